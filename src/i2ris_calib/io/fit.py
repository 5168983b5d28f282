"""``i2ris-calib fit``: synced CSV(s) -> per-direction GPI/EGPI fits -> fit.json, predictions.csv.

File formats are documented in docs/fit.md (schema ``i2ris-calib.fit/1``).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from rich.console import Console
from rich.progress import Progress
from rich.table import Table

from i2ris_calib.data.dataset import Dataset
from i2ris_calib.diagnosis.effects import base_of
from i2ris_calib.diagnosis.serialize import model_from_dict
from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.fit import fit_model
from i2ris_calib.fitting.pipeline import MODEL_KINDS, fit_dataset, fit_warnings
from i2ris_calib.io.atomic import atomic_path, check_output_dir, write_json
from i2ris_calib.io.provenance import provenance
from i2ris_calib.io.synced import load_datasets

SCHEMA = "i2ris-calib.fit/1"
PRED_COLUMNS = ("dataset", "time_s", "v", "theta_deg", "gpi_deg", "egpi_deg", "egpi_c_deg", "split")


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
        order = [k for k in MODEL_KINDS if k in kinds] + [k for k in kinds if k not in MODEL_KINDS]
        for kind in order:
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


def fit_document(fitted, axis: str, kinds: Sequence[str], provenance: dict) -> dict[str, Any]:
    """The fit.json document (schema i2ris-calib.fit/1)."""
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
                "models": {k: model_record(results[k], k, results[k].model, d.v) for k in kinds},
            }
        )
    doc: dict[str, Any] = {"schema": SCHEMA, "axis": axis, "datasets": datasets}
    if len(datasets) == 1:
        doc["direction"] = datasets[0]["direction"]
        doc["abs_fitted"] = datasets[0]["abs_fitted"]
        doc["models"] = datasets[0]["models"]
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
        for kind in ("gpi", "egpi", "egpi_c", "diagnosed"):
            if kind in results:
                cols[f"{kind}_deg"] = results[kind].predict(d.signals)
            elif kind != "diagnosed":
                cols[f"{kind}_deg"] = np.nan
        cols["split"] = np.where(~d.in_direction, "other", np.where(d.holdout, "holdout", "fit"))
        parts.append(pd.DataFrame(cols))
    frame = pd.concat(parts, ignore_index=True)
    extra = ["diagnosed_deg"] if "diagnosed_deg" in frame else []
    return frame[[*PRED_COLUMNS, *extra]]


def results_table(fitted, kinds: Sequence[str], axis: str):
    """A rich Table shaped like the paper's Tables 1-2: one row per model (fitted
    cycles and held-out cycles), RMSE / NRMSE / MAE (= max |error|) per dataset. A
    ``*`` marks each cell group whose fit did not converge (per model and dataset)."""
    absd = [d.name for d, _ in fitted if d.abs_fitted]
    table = Table(
        title=f"GPI and EGPI, {axis} motor: RMSE, MAE (max |error|) in deg, NRMSE in %",
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
            table.add_column(f"{d.name}\n{m}", justify="right", no_wrap=True)
    for kind in [k for k in ("diagnosed", "egpi_c", "egpi", "gpi") if k in kinds]:
        for label, attr in (("fit", "metrics"), ("hold", "holdout_metrics")):
            row = [f"{kind.upper()} {label}"]
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
    if model not in (*MODEL_KINDS, "all"):
        raise CalibError(f"--model must be {', '.join(MODEL_KINDS)} or all, got '{model}'")
    if not paths:
        raise CalibError("give at least one synced CSV to fit")
    kinds = MODEL_KINDS if model == "all" else (model,)
    saved = read_model_file(model_file) if model_file is not None else None
    if saved is not None:
        kinds = (*kinds, "diagnosed")
    fit_config = config.fit
    created = not Path(out).exists()
    out = check_output_dir(out, ("predictions.csv", "fit.json"))
    try:
        datasets = load_datasets(paths, axis, fit_config)
    except CalibError:
        if created:  # a folder made only to check it can be written: leave nothing behind
            out.rmdir()
        raise
    console = Console(stderr=True)
    with Progress(console=console, transient=True, disable=not console.is_terminal) as bar:
        task = bar.add_task("fitting", total=len(datasets) * len(kinds))

        def step(label: str) -> None:
            bar.update(task, description=f"fitting {label}", advance=1)

        fitted = fit_datasets(datasets, kinds, fit_config, progress=step, saved=saved)
    inputs = [*paths, *([model_file] if model_file is not None else [])]
    doc = fit_document(fitted, axis, kinds, provenance(inputs, config))
    # both files or neither: fit.json is renamed into place only after predictions.csv
    with atomic_path(out / "fit.json") as tmp_json:
        write_json(tmp_json, doc)
        with atomic_path(out / "predictions.csv") as tmp_csv:
            predictions_frame(fitted).to_csv(tmp_csv, index=False, float_format="%.10g")
    Console().print(results_table(fitted, kinds, axis))
    for d in doc["datasets"]:
        r = d["rows"]
        console.print(
            f"{d['name']}: {r['total']} samples drive the models; {r['in_direction']} are its own "
            f"({r['fitted']} fitted, {r['holdout']} held out, {r['angle_missing']} not measured)"
        )
        for kind, rec in d["models"].items():
            for w in rec["warnings"]:
                if not w.startswith("not converged"):
                    console.print(f"warning: {d['name']} {kind}: {w}")
    if any(not r.converged for _, res in fitted for r in res.values()):
        console.print(
            "* not converged: see 'message' in fit.json (try more starts or --config [fit] max_nfev)"
        )
    return doc


def read_model_file(path: str | Path):
    """The model saved in a ``final_model.json`` (docs/diagnosis.md); CalibError if unreadable."""
    p = Path(path)
    try:
        obj = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise CalibError(
            f"{p}: cannot read the model file ({exc}); give a final_model.json from 'diagnose'"
        ) from None
    try:
        return model_from_dict(obj)
    except CalibError as exc:
        raise CalibError(f"{p}: {exc}") from None


def read_fit_json(path: str | Path) -> dict[str, Any]:
    """Load a fit.json written by :func:`fit_files`; CalibError when unreadable."""
    p = Path(path)
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise CalibError(f"{p}: cannot read fit.json ({exc})") from None
    if doc.get("schema") != SCHEMA:
        raise CalibError(f"{p}: schema is {doc.get('schema')!r}, expected {SCHEMA!r}; re-run 'fit'")
    return doc
