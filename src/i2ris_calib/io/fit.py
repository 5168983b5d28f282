"""``i2ris-calib fit``: synced CSV(s) -> per-direction GPI/EGPI fits -> fit.json, predictions.csv.

File formats are documented in docs/fit.md (schema ``i2ris-calib.fit/1``).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import astuple, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from rich.console import Console
from rich.progress import Progress
from rich.table import Table

from i2ris_calib.compensation.safety import max_input_rate
from i2ris_calib.data.coupling import MotorsTogether, motors_together
from i2ris_calib.data.dataset import Dataset, other_axis
from i2ris_calib.data.excursions import Excursions, excursions
from i2ris_calib.diagnosis.effects import base_of
from i2ris_calib.diagnosis.serialize import model_from_dict
from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.fit import fit_model
from i2ris_calib.fitting.pipeline import (
    MODEL_KINDS,
    ModelChoice,
    choose_model,
    fit_dataset,
    fit_warnings,
    pick_after_fit,
)
from i2ris_calib.hysteresis.registry import BUILT_KINDS, fit_order, kind_info, table_order
from i2ris_calib.io.atomic import write_json
from i2ris_calib.io.fit_schema import FIT_SCHEMA, check_fit_doc, check_model_doc
from i2ris_calib.io.outputs import claim_output_dir, output_dir
from i2ris_calib.io.provenance import provenance
from i2ris_calib.io.synced import load_datasets

SCHEMA = FIT_SCHEMA
#: predictions.csv's fixed columns (the direction kinds' outputs always; the outputs of
#: other kinds follow "split" when fitted)
PRED_COLUMNS = ("dataset", "time_s", "v", "theta_deg", *(f"{k}_deg" for k in MODEL_KINDS), "split")

#: The files ``fit`` writes in its output folder.
OUTPUTS = ("fit.json", "predictions.csv")


def model_record(res, kind: str, model, v: np.ndarray | None = None) -> dict[str, Any]:
    """The fit.json record M of one fitted model (docs/fit.md); ``v``: the dataset's
    input, for the warnings (:func:`i2ris_calib.fitting.pipeline.fit_warnings`)."""
    rec = {
        "params": res.params,
        "stderr": res.stderr,
        "units": {p.name: p.unit for p in model.parameters},
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
        "n_operators": int(getattr(base_of(model), "n", 0)),
        "v_f": res.params.get("v_f"),
        "warnings": list(fit_warnings(res, np.zeros(0) if v is None else v)),
        "stderr_reasons": dict(res.stderr_reasons),
        "initial_state": None if res.initial_state is None else res.initial_state.as_dict(),
    }
    if hasattr(base_of(model), "deadband_counts"):
        rec["deadband_counts"] = float(base_of(model).deadband_counts)
    return rec


def fit_saved(model, data: Dataset, fit_config):
    """Refit a saved (diagnosed) model to one dataset, starting from its saved values."""
    return fit_model(
        model,
        data.signals,
        data.theta_deg,
        holdout_mask=data.holdout,
        max_nfev=fit_config.max_nfev,
    )


def fit_datasets(
    datasets: Sequence[Dataset], kinds: Sequence[str], fit_config, progress=None, saved=None
):
    """Fit every model kind to every dataset: list of (dataset, {kind: FitResult}).

    ``saved`` is an optional model from ``final_model.json`` (diagnose), fitted as kind
    ``"diagnosed"`` when that kind is listed.
    """
    out = []
    for d in datasets:
        if np.ptp(d.v) == 0:
            raise CalibError(
                f"{d.source} [{d.name}]: the input is constant; nothing to fit (check --axis)"
            )
        results = {}
        for kind in fit_order(kinds):
            if progress is not None:
                progress(f"{d.name}: {kind}")
            try:
                if kind == "diagnosed":
                    results[kind] = fit_saved(saved, d, fit_config)
                else:
                    results[kind] = fit_dataset(kind, d, fit_config, results)
            except CalibError as exc:
                raise CalibError(f"{d.source} [{d.name}] {kind}: {exc}") from None
        out.append((d, {k: results[k] for k in kinds}))
    return out


def fit_document(
    fitted, axis: str, kinds: Sequence[str], provenance: dict, choice: ModelChoice | None = None
) -> dict[str, Any]:
    """The fit.json document (schema i2ris-calib.fit/1); ``choice``: which models on
    which input and why (``model_choice``)."""
    datasets = []
    for d, results in fitted:
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
                "models": {k: model_record(results[k], k, results[k].model, d.v) for k in kinds},
            }
        )
    doc: dict[str, Any] = {"schema": SCHEMA, "axis": axis, "datasets": datasets}
    if len(datasets) == 1:
        doc["direction"] = datasets[0]["direction"]
        doc["abs_fitted"] = datasets[0]["abs_fitted"]
        doc["models"] = datasets[0]["models"]
    if choice is not None:
        doc["model_choice"] = choice.as_dict()
    doc["provenance"] = provenance
    return doc


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
    (:meth:`~i2ris_calib.fitting.fit.FitResult.eval_uncertainty`); NaN where the
    covariance is not available (a parameter not identified)."""
    try:
        sd = res.eval_uncertainty(d.signals, sigma=1.0)
    except (CalibError, ValueError, np.linalg.LinAlgError):
        return np.full(d.n_samples, np.nan)
    return np.where(np.isfinite(sd), sd, np.nan)


def source_labels(sources: Sequence[str]) -> dict[str, str]:
    """The shortest trailing part of each file path that tells it from the others
    (``A/synced.csv`` and ``B/synced.csv``; ``synced.csv`` alone), by source."""
    parts = {s: Path(s).resolve().parts for s in dict.fromkeys(sources)}
    labels = {}
    for src, mine in parts.items():
        others = [p for s, p in parts.items() if p != mine]
        k = 1
        while k < len(mine) and any(p[-k:] == mine[-k:] for p in others):
            k += 1
        labels[src] = "/".join(mine[-k:])
    return labels


def results_tables(fitted, kinds: Sequence[str], axis: str) -> list:
    """:func:`results_table` of every dataset, or one per input file when the datasets
    come from several (titled with the part of its path that tells it from the others,
    :func:`source_labels`): same-named datasets of different files are never side by
    side, and a table never gets wider than one file's directions."""
    labels = source_labels([d.source for d, _ in fitted])
    if len(set(labels.values())) < 2:
        return [results_table(fitted, kinds, axis)]
    groups: dict[str, list] = {}
    for d, results in fitted:
        groups.setdefault(labels[d.source], []).append((d, results))
    return [results_table(group, kinds, axis, source=src) for src, group in groups.items()]


def results_table(fitted, kinds: Sequence[str], axis: str, source: str | None = None):
    """A rich Table shaped like the paper's Tables 1-2: one row per model (fitted
    cycles and held-out cycles), RMSE / NRMSE / MAE (= max |error|) per dataset. A
    ``*`` marks each cell group whose fit did not converge (per model and dataset).
    ``source``: the one input file of these datasets, in the title (the columns are
    then labelled by direction: one dataset per direction in a file)."""

    def label(d: Dataset) -> str:
        return f"{d.axis}{d.direction}" if source else d.name

    absd = [label(d) for d, _ in fitted if d.abs_fitted]
    table = Table(
        title=f"GPI and EGPI, {axis} motor: RMSE, MAE (max |error|) in deg, NRMSE in %"
        + (f"\n{source}" if source else ""),
        caption="; ".join(
            [f"{', '.join(absd)}: fitted on |counts| -> |deg|"] * bool(absd)
            + ["* = not converged"]
            * any(not r.converged for _, res in fitted for r in res.values())
        )
        or None,
    )
    table.add_column("model", no_wrap=True)
    for d, _ in fitted:
        for m in ("RMSE", "NRMSE", "MAE"):
            table.add_column(f"{label(d)}\n{m}", justify="right", no_wrap=True)
    for kind in table_order(kinds):
        for label, attr in (("fit", "metrics"), ("hold", "holdout_metrics")):
            row = [f"{kind_info(kind).label} {label}"]
            for _, results in fitted:
                mt = getattr(results[kind], attr)
                star = "" if results[kind].converged else "*"
                row += [
                    f"{mt.rmse_deg:.2f}{star}",
                    f"{mt.nrmse_pct:.2f}{star}",
                    f"{mt.max_abs_err_deg:.2f}{star}",
                ]
            table.add_row(*[r.replace("nan", "-") for r in row])
    return table


def fit_files(
    paths: Sequence[str | Path],
    axis: str,
    model: str,
    out: str | Path,
    config,
    model_file: str | Path | None = None,
) -> dict[str, Any]:
    """Command body of ``i2ris-calib fit``: read, split, fit, write, print the table.

    ``model_file`` is a ``final_model.json`` written by ``diagnose``: that model is
    refitted too, as model ``"diagnosed"`` in fit.json. Returns the fit.json document.
    """
    if model not in (*BUILT_KINDS, "all"):
        raise CalibError(f"--model must be {', '.join(BUILT_KINDS)} or all, got '{model}'")
    if not paths:
        raise CalibError("give at least one synced CSV to fit")
    saved = read_model_file(model_file) if model_file is not None else None
    fit_config = config.fit
    inputs = [*paths, *([model_file] if model_file is not None else [])]
    out = claim_output_dir(out, "fit", inputs, OUTPUTS)
    datasets, choice = datasets_for_fit(paths, axis, fit_config, model, config.columns)
    kinds = (*choice.kinds, *(["diagnosed"] if saved is not None else []))
    console = Console(stderr=True)
    with Progress(console=console, transient=True, disable=not console.is_terminal) as bar:
        task = bar.add_task("fitting", total=len(datasets) * len(kinds))

        def step(label: str) -> None:
            bar.update(task, description=f"fitting {label}", advance=1)

        fitted = fit_datasets(datasets, kinds, fit_config, progress=step, saved=saved)
    choice = pick_after_fit(choice, fitted)  # the default model: from the held-out errors
    doc = fit_document(fitted, axis, kinds, provenance(inputs, config), choice)
    with output_dir(out, "fit", inputs, OUTPUTS) as tmp:
        write_json(tmp / "fit.json", doc)
        predictions_frame(fitted).to_csv(tmp / "predictions.csv", index=False, float_format="%.10g")
    for table in results_tables(fitted, kinds, axis):
        Console().print(table)
    labels = source_labels([d["source"] for d in doc["datasets"]])
    several = len(set(labels.values())) > 1
    console.print(choice.line)
    for d in doc["datasets"]:
        r = d["rows"]
        name = f"{d['name']} [{labels[d['source']]}]" if several else d["name"]
        console.print(
            f"{name}: {r['total']} samples drive the models; {r['in_direction']} are its own "
            f"({r['fitted']} fitted, {r['holdout']} held out, {r['angle_missing']} not measured)"
        )
        for kind, rec in d["models"].items():
            for w in rec["warnings"]:
                if not w.startswith("not converged"):
                    console.print(f"warning: {name} {kind}: {w}")
    if any(not r.converged for _, res in fitted for r in res.values()):
        console.print(
            "* not converged: see 'message' in fit.json (try more starts or --config [fit] max_nfev)"
        )
    return doc


def recording_summary(whole: Sequence[Dataset]) -> tuple[Excursions, MotorsTogether | None]:
    """How the recording drives the axis, over all its files: the excursions of its
    signed input (:func:`~i2ris_calib.data.excursions.excursions`) and how the other
    motor moves with it (:func:`~i2ris_calib.data.coupling.motors_together`; None
    without the other motor's input). ``whole``: the signed datasets of the axis."""
    counts = [astuple(excursions(d.enc, d.bands.zero_band, d.time_s)) for d in whole]
    recording = Excursions(*(int(sum(c)) for c in zip(*counts, strict=True)))
    if any(d.signals.v_other is None for d in whole):
        return recording, None
    other = other_axis(whole[0].axis)
    enc = np.concatenate([d.enc for d in whole])
    enc_other = np.concatenate([np.asarray(d.signals.v_other, float) for d in whole])
    return recording, motors_together(enc, enc_other, other)


def datasets_for_fit(
    paths: Sequence[str | Path], axis: str, fit_config, model: str = "all", columns=None
) -> tuple[list[Dataset], ModelChoice]:
    """The datasets of a fit and the model choice (:func:`~i2ris_calib.fitting.pipeline.
    choose_model`): unless ``[fit] signed`` forces it, the recording's excursions
    (:func:`~i2ris_calib.data.excursions.excursions`, over all files) decide between
    the signed dataset of the axis and the paper's per-direction split; whether the
    other motor moves with this one decides the coupled model (:func:`recording_summary`).
    ``columns``: the files' column mapping (``[columns]``, default the standard names)."""
    whole = load_datasets(
        paths, axis, replace(fit_config, signed=True, split=False), columns=columns
    )
    recording, together = recording_summary(whole)
    choice = choose_model(None if fit_config.signed else recording, fit_config, model, together)
    if choice.signed:
        return whole, choice
    split_config = replace(fit_config, signed=False, split=False)
    return load_datasets(paths, axis, split_config, columns=columns), choice


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


def read_fit_json(path: str | Path) -> dict[str, Any]:
    """Load a fit.json written by :func:`fit_files` and check it completely
    (:func:`~i2ris_calib.io.fit_schema.check_fit_doc`: keys, types, every parameter a
    finite number, ordered input range); CalibError naming the file and the key."""
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
