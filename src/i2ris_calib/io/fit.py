"""fit.json and predictions.csv: the files of ``i2ris-calib fit`` (docs/fit.md, schema
``i2ris-calib.fit/1``): their documents built from fitted results, and read back
(:func:`read_fit_json`, and :func:`read_model_file` for a diagnose ``final_model.json``).

The ``fit`` command itself (pick the datasets, fit, write, print) is
:mod:`i2ris_calib.commands.fit`.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from i2ris_calib.compensation.rate import max_input_rate
from i2ris_calib.data.dataset import Dataset
from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.decision import Decision
from i2ris_calib.fitting.limits import RecordingLimits
from i2ris_calib.fitting.pipeline import (
    MIN_EXPLAINED_VARIANCE,
    MODEL_KINDS,
    ModelChoice,
    fit_warnings,
)
from i2ris_calib.hysteresis.codec import fit_json_fields, model_from_dict
from i2ris_calib.hysteresis.registry import fit_order
from i2ris_calib.io.fit_schema import FIT_SCHEMA, check_fit_doc, check_model_doc

SCHEMA = FIT_SCHEMA
#: predictions.csv's fixed columns (the direction kinds' outputs always; the outputs of
#: other kinds follow "split" when fitted)
PRED_COLUMNS = ("dataset", "time_s", "v", "theta_deg", *(f"{k}_deg" for k in MODEL_KINDS), "split")


def model_record(res, kind: str, model, v: np.ndarray | None = None) -> dict[str, Any]:
    """The fit.json record M of one fitted model (docs/fit.md); ``v``: the dataset's
    input, for the warnings (:func:`i2ris_calib.fitting.pipeline.fit_warnings`)."""
    own = fit_json_fields(model)  # the model codec's: units, operators, dead band
    rec = {
        "params": res.params,
        "stderr": res.stderr,
        "units": own["units"],
        "free": list(res.free),
        "metrics": res.metrics.as_dict(),
        "holdout_metrics": res.holdout_metrics.as_dict(),
        "aic": res.aic,
        "bic": res.bic,
        "converged": res.converged,
        "within_bounds": not res.extra.get("outside_bounds"),
        "message": res.message,
        "nfev": res.nfev,
        "n_samples": res.n_samples,
        "n_holdout": res.holdout_metrics.n_samples,
        "n_operators": own["n_operators"],
        "v_f": res.params.get("v_f"),
        "warnings": list(fit_warnings(res, np.zeros(0) if v is None else v)),
        "stderr_reasons": dict(res.stderr_reasons),
        "initial_state": None if res.initial_state is None else res.initial_state.as_dict(),
        "certificate": None if res.certificate is None else res.certificate.as_dict(),
    }
    if "deadband_counts" in own:
        rec["deadband_counts"] = own["deadband_counts"]
    return rec


#: The advice of the low-explained-variance warning (:func:`~i2ris_calib.fitting.
#: pipeline.fit_warnings`), replaced when another model of the dataset explains the angle
LOW_VARIANCE_ADVICE = (
    ": the angle may not follow this input (check the axis, the columns and the tracking)"
)


def _explained_elsewhere(models: dict[str, dict]) -> dict[str, dict]:
    """``models`` (kind -> fit.json record) with the low-explained-variance warning of a
    model told that another model of the same dataset explains the angle (at least
    :data:`~i2ris_calib.fitting.pipeline.MIN_EXPLAINED_VARIANCE`): then the data are
    fine and the model lacks what the other adds (the other motor, a second tendon);
    "check the columns" would send the user looking for a mistake that is not there."""
    ev = {k: r["metrics"].get("explained_variance") for k, r in models.items()}
    good = {k: e for k, e in ev.items() if e is not None and e >= MIN_EXPLAINED_VARIANCE}
    for kind, rec in models.items():
        best = max((k for k in good if k != kind), key=good.get, default=None)
        if best is None:
            continue
        rec["warnings"] = [
            w.replace(
                LOW_VARIANCE_ADVICE,
                f"; {best} explains {100 * good[best]:.0f} % of it: this model lacks what "
                f"{best} models (the data are not at fault)",
            )
            for w in rec["warnings"]
        ]
    return models


def fit_document(
    fitted,
    axis: str,
    kinds: Sequence[str],
    provenance: dict,
    choice: ModelChoice | None = None,
    decisions: Sequence[Decision] | None = None,
    limits: Sequence[RecordingLimits] | None = None,
    replaced: dict[tuple[str, str], dict] | None = None,
) -> dict[str, Any]:
    """The fit.json document (schema i2ris-calib.fit/1); ``choice``: which models on
    which input and why (``model_choice``); ``decisions``: the recommended model of
    each dataset (``decision``, :mod:`i2ris_calib.fitting.decision`), in ``fitted``'s
    order; ``limits``: each dataset's noise, repeatability, baselines and
    cross-validation (``limits``, :mod:`i2ris_calib.fitting.limits`); ``replaced``:
    (dataset name, kind) -> the model's :func:`replacement_record` (a fit rerun from a
    lower cost a later stage found)."""
    replaced = replaced or {}
    datasets = []
    decisions = list(decisions) if decisions is not None else [None] * len(fitted)
    limits = list(limits) if limits is not None else [None] * len(fitted)
    for (d, results), dec, lim in zip(fitted, decisions, limits, strict=True):
        datasets.append(
            {
                "name": d.name,
                "direction": d.direction,
                "abs_fitted": d.abs_fitted,
                "source": d.source,
                "n_samples": int(d.v.size),
                "n_angles": int(np.isfinite(d.theta_deg).sum()),
                "rows": dict(d.rows),
                "bands": {
                    "zero_band": d.bands.zero_band,
                    "deadband": d.bands.deadband,
                    "input_noise": d.bands.noise,
                    "derived": list(d.bands.derived),
                },
                "input_range_counts": [float(d.v.min()), float(d.v.max())],
                # the fastest input move: compensate's default rate limit
                "max_input_rate_counts_per_s": max_input_rate(d.v, d.time_s),
                "models": _explained_elsewhere(
                    {k: model_record(results[k], k, results[k].model, d.v) for k in kinds}
                ),
            }
        )
        for kind, rec in datasets[-1]["models"].items():
            if (d.name, kind) in replaced:
                rec["replaced"] = replaced[d.name, kind]
        if dec is not None:
            datasets[-1]["decision"] = dec.as_dict()
        if lim is not None:
            datasets[-1]["limits"] = lim.as_dict()
    doc: dict[str, Any] = {"schema": SCHEMA, "axis": axis, "datasets": datasets}
    if len(datasets) == 1:
        doc["direction"] = datasets[0]["direction"]
        doc["abs_fitted"] = datasets[0]["abs_fitted"]
        doc["models"] = datasets[0]["models"]
        if "decision" in datasets[0]:
            doc["decision"] = datasets[0]["decision"]
    if choice is not None:
        doc["model_choice"] = choice.as_dict()
    doc["provenance"] = provenance
    return doc


def replacement_record(
    dataset: str,
    kind: str,
    previous_cost: float,
    cost: float,
    found_by: str,
    stage: str,
    previous_params: dict[str, float],
    previous_sha256: str,
) -> dict[str, Any]:
    """A fit.json model's ``replaced`` record (docs/formats.md): a later stage found a
    lower cost of this model on the same data and the fit was rerun from it. The
    costs are the fit's own (its loss over the fitted samples, deg^2); ``found_by``
    says where the lower cost came from; ``previous_sha256`` names the fit.json it
    replaced (its values are ``previous_params``); ``text`` is the one sentence
    (:func:`replacement_text`) the report and ``compensate`` repeat."""
    return {
        "previous_cost": float(previous_cost),
        "cost": float(cost),
        "stage": stage,
        "found_by": found_by,
        "previous_params": {k: float(v) for k, v in previous_params.items()},
        "previous_sha256": previous_sha256,
        "text": replacement_text(dataset, kind, previous_cost, cost, found_by),
    }


def replacement_text(
    dataset: str, kind: str, previous_cost: float, cost: float, found_by: str
) -> str:
    """The one sentence on a replaced fit, e.g. ``fit.json's pitch+ egpi replaced: cost
    6.43 -> 0.545 (found by diagnose's refit from creep_log's values)``."""
    return (
        f"fit.json's {dataset} {kind} replaced: cost {previous_cost:.4g} -> {cost:.4g} "
        f"(found by {found_by})"
    )


def predictions_frame(fitted) -> pd.DataFrame:
    """predictions.csv rows: every sample of every dataset, in the dataset's convention.

    ``split``: ``fit`` / ``holdout`` for the dataset's own samples, ``other`` for the
    samples of the other direction (they drive the model; not in loss or metrics).
    ``theta_deg`` is the measured angle in the dataset's convention (``-angle`` for a
    ``"-"`` dataset) on every measured sample.
    """
    parts = []
    for d, results in fitted:
        cols = {
            "dataset": d.name,
            "time_s": d.time_s,
            "v": d.v,
            "theta_deg": d.theta_measured_deg,
        }
        for kind in fit_order({*MODEL_KINDS, *results}):
            if kind in results:
                cols[f"{kind}_deg"] = results[kind].predict(d.signals)
            else:  # the direction kinds' columns are always there
                cols[f"{kind}_deg"] = np.nan
        for kind in fit_order(results):  # 1-sd prediction band (the report's Fig-6 bands)
            cols[f"{kind}_sd_deg"] = prediction_sd(results[kind], d)
        cols["split"] = np.where(~d.in_direction, "other", np.where(d.holdout, "holdout", "fit"))
        parts.append(pd.DataFrame(cols))
    frame = pd.concat(parts, ignore_index=True)
    extra = [c for c in frame if c not in PRED_COLUMNS]
    return frame[[*PRED_COLUMNS, *extra]]


def prediction_sd(res, d: Dataset) -> np.ndarray:
    """1-sd band of a fit's model curve from its parameter covariance (deg), per sample
    (:meth:`~i2ris_calib.fitting.result.FitResult.eval_uncertainty`); NaN where the
    covariance is not available (a parameter not identified)."""
    try:
        sd = res.eval_uncertainty(d.signals, sigma=1.0)
    except (CalibError, ValueError, np.linalg.LinAlgError):
        return np.full(d.n_samples, np.nan)
    return np.where(np.isfinite(sd), sd, np.nan)


def read_model_file(path: str | Path):
    """The model saved in a ``final_model.json`` (docs/diagnosis.md); CalibError if unreadable."""
    p = Path(path)
    try:
        obj = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise CalibError(
            f"{p}: cannot read the model file ({exc}); give a final_model.json from 'diagnose'"
        ) from None
    check_model_doc(obj, p)  # every value, naming the file and key (io/fit_schema.py)
    try:
        return model_from_dict(obj)
    except CalibError as exc:
        raise CalibError(f"{p}: {exc}") from None


def model_file_origin(path: str | Path) -> dict[str, str]:
    """What a final_model.json records of the data it was diagnosed on: ``axis``,
    ``dataset``, ``direction`` (those present as text; read after
    :func:`read_model_file` accepted the file)."""
    try:
        obj = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError, UnicodeDecodeError):
        return {}
    if not isinstance(obj, dict):
        return {}
    return {k: obj[k] for k in ("axis", "dataset", "direction") if isinstance(obj.get(k), str)}


def read_fit_json(path: str | Path) -> dict[str, Any]:
    """Load a fit.json written by ``fit`` (:func:`~i2ris_calib.commands.fit.fit_files`)
    and check it completely (:func:`~i2ris_calib.io.fit_schema.check_fit_doc`: keys,
    types, every parameter a finite number, ordered input range); CalibError naming the
    file and the key."""
    p = Path(path)
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise CalibError(
            f"{p}: not a JSON file ({exc}); re-run 'fit' or restore the file"
        ) from None
    except OSError as exc:
        raise CalibError(
            f"{p}: cannot read fit.json ({exc.strerror or exc}); give the fit.json written by 'fit'"
        ) from None
    return check_fit_doc(doc, p)
