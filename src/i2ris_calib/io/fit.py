"""``i2ris-calib fit``: synced CSV(s) -> per-direction GPI/EGPI fits -> fit.json, predictions.csv.

File formats are documented in docs/fit.md (schema ``i2ris-calib.fit/1``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from i2ris_calib.errors import CalibError

SCHEMA = "i2ris-calib.fit/1"
AXES = ("yaw", "pitch")
PRED_COLUMNS = ("dataset", "time_s", "v", "theta_deg", "gpi_deg", "egpi_deg", "split")


@dataclass(frozen=True)
class Dataset:
    """One motion direction of one axis, ready to fit.

    ``v`` and ``theta_deg`` are in the fitted convention: |counts| -> |deg| when
    ``abs_fitted`` (negative-input datasets, as the paper).
    """

    name: str
    direction: str
    abs_fitted: bool
    source: str
    time_s: np.ndarray
    v: np.ndarray
    theta_deg: np.ndarray
    v_other: np.ndarray


def read_synced(path: str | Path, axis: str) -> pd.DataFrame:
    """Read and validate a synced CSV for ``axis``; one-line CalibError on bad input.

    Checks: file readable, columns ``time_s, enc_yaw, enc_pitch, <axis>_deg`` present,
    time and encoders finite, time strictly increasing. Angles of rows whose
    ``status`` (if present) is not ``measured`` are set to NaN.
    """
    p = Path(path)
    if axis not in AXES:
        raise CalibError(f"--axis must be yaw or pitch, got '{axis}'")
    if not p.is_file():
        raise CalibError(f"{p}: file not found (give a synced CSV, see docs/formats.md)")
    try:
        df = pd.read_csv(p)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise CalibError(f"{p}: not a readable CSV ({str(exc).splitlines()[0]})") from None
    need = ["time_s", "enc_yaw", "enc_pitch", f"{axis}_deg"]
    missing = [c for c in need if c not in df.columns]
    if missing:
        raise CalibError(
            f"{p}: missing column(s) {', '.join(missing)}; a synced CSV needs {', '.join(need)} (docs/formats.md)"
        )
    for col in need:
        try:
            df[col] = pd.to_numeric(df[col], errors="raise").astype(float)
        except (ValueError, TypeError):
            raise CalibError(f"{p}: column '{col}' is not numeric") from None
    for col in ("time_s", "enc_yaw", "enc_pitch"):
        bad = np.flatnonzero(~np.isfinite(df[col].to_numpy()))
        if bad.size:
            raise CalibError(
                f"{p}: {bad.size} row(s) with NaN/empty '{col}' (first at data row {bad[0] + 1}); "
                "drop or interpolate them (only angles may be NaN)"
            )
    t = df["time_s"].to_numpy()
    step = np.diff(t)
    if step.size and (step <= 0).any():
        k = int(np.flatnonzero(step <= 0)[0])
        kind = "duplicate" if step[k] == 0 else "decreasing"
        raise CalibError(
            f"{p}: {kind} time_s at data row {k + 2} ({t[k]:.6g} -> {t[k + 1]:.6g} s); "
            "time must be strictly increasing (sort the rows and drop duplicates)"
        )
    if "status" in df.columns:
        df.loc[df["status"].astype(str) != "measured", f"{axis}_deg"] = np.nan
    return df


def datasets_from_frame(df: pd.DataFrame, axis: str, source: str, fit_config) -> list[Dataset]:
    """Motion-direction datasets of ``axis`` in one synced frame (see direction_blocks)."""
    from i2ris_calib.fitting.pipeline import direction_blocks

    other = "pitch" if axis == "yaw" else "yaw"
    enc = df[f"enc_{axis}"].to_numpy()
    out = []
    for block in direction_blocks(enc, fit_config):
        i = block.index
        neg = block.direction == "-"
        sgn = -1.0 if neg else 1.0
        out.append(
            Dataset(
                name=f"{axis}{block.direction}",
                direction=block.direction,
                abs_fitted=neg,
                source=source,
                time_s=df["time_s"].to_numpy()[i],
                v=sgn * enc[i],
                theta_deg=sgn * df[f"{axis}_deg"].to_numpy()[i],
                v_other=df[f"enc_{other}"].to_numpy()[i],
            )
        )
    return out


def load_datasets(paths: Sequence[str | Path], axis: str, fit_config) -> list[Dataset]:
    """All motion-direction datasets of ``axis`` in the given synced CSVs, uniquely named."""
    found: list[Dataset] = []
    for path in paths:
        found += datasets_from_frame(read_synced(path, axis), axis, str(path), fit_config)
    if not found:
        raise CalibError(
            f"no {axis} motion in {', '.join(map(str, paths))}: every enc_{axis} is within "
            f"+-{fit_config.zero_band_counts:g} counts or the blocks are shorter than "
            f"{fit_config.min_block_samples} samples (check --axis)"
        )
    names: dict[str, int] = {}
    unique = []
    for d in found:
        names[d.name] = names.get(d.name, 0) + 1
        if names[d.name] > 1:
            d = Dataset(**{**d.__dict__, "name": f"{d.name} ({Path(d.source).stem})"})
        unique.append(d)
    return unique


def model_record(res, kind: str, model) -> dict[str, Any]:
    """The fit.json record M of one fitted model (docs/fit.md)."""
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
        "n_operators": int(getattr(base_model(model), "n", 0)),
        "v_f": res.params.get("v_f"),
    }
    if hasattr(base_model(model), "deadband_counts"):
        rec["deadband_counts"] = float(base_model(model).deadband_counts)
    return rec


def base_model(model):
    """The GPI/EGPI model inside a model extended by diagnosed effects (itself otherwise)."""
    from i2ris_calib.diagnosis.effects import base_of

    return base_of(model)


def fit_saved(model, sig, theta_deg: np.ndarray, holdout: np.ndarray, fit_config):
    """Refit a saved (diagnosed) model to one dataset, starting from its saved values."""
    from i2ris_calib.fitting.fit import fit_model

    return fit_model(
        model,
        sig,
        theta_deg,
        fit_mask=np.isfinite(theta_deg) & ~holdout,
        holdout_mask=holdout,
        max_nfev=fit_config.max_nfev,
    )


def fit_datasets(
    datasets: Sequence[Dataset], kinds: Sequence[str], fit_config, progress=None, saved=None
):
    """Fit every model kind to every dataset: list of (dataset, holdout mask, {kind: FitResult}).

    ``saved`` is an optional model from ``final_model.json`` (diagnose), fitted as kind
    ``"diagnosed"`` when that kind is listed.
    """
    from i2ris_calib.fitting.pipeline import fit_kind, split_masks
    from i2ris_calib.hysteresis.model import Signals

    out = []
    for d in datasets:
        if np.ptp(d.v) == 0:
            raise CalibError(
                f"{d.source} [{d.name}]: the input is constant; nothing to fit (check --axis)"
            )
        holdout = split_masks(d.v, fit_config)[1]
        sig = Signals(v=d.v, t_s=d.time_s, v_other=d.v_other)
        results = {}
        for kind in kinds:
            if progress is not None:
                progress(f"{d.name}: {kind}")
            try:
                if kind == "diagnosed":
                    results[kind] = fit_saved(saved, sig, d.theta_deg, holdout, fit_config)
                else:
                    results[kind] = fit_kind(
                        kind, sig, d.theta_deg, fit_config, holdout, gpi_fit=results.get("gpi")
                    )
            except CalibError as exc:
                raise CalibError(f"{d.source} [{d.name}] {kind}: {exc}") from None
        out.append((d, holdout, results))
    return out


def fit_document(fitted, axis: str, kinds: Sequence[str], provenance: dict) -> dict[str, Any]:
    """The fit.json document (schema i2ris-calib.fit/1)."""
    datasets = []
    for d, _, results in fitted:
        datasets.append(
            {
                "name": d.name,
                "direction": d.direction,
                "abs_fitted": d.abs_fitted,
                "source": d.source,
                "n_samples": int(d.v.size),
                "n_angles": int(np.isfinite(d.theta_deg).sum()),
                "input_range_counts": [float(d.v.min()), float(d.v.max())],
                "models": {k: model_record(results[k], k, results[k].model) for k in kinds},
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
    """predictions.csv rows: one per sample of every dataset (fitted convention)."""
    from i2ris_calib.hysteresis.model import Signals

    parts = []
    for d, holdout, results in fitted:
        cols = {
            "dataset": d.name,
            "time_s": d.time_s,
            "v": d.v,
            "theta_deg": d.theta_deg,
        }
        for kind in ("gpi", "egpi"):
            cols[f"{kind}_deg"] = results[kind].predict(d.v) if kind in results else np.nan
        if "diagnosed" in results:
            cols["diagnosed_deg"] = results["diagnosed"].predict(
                Signals(v=d.v, t_s=d.time_s, v_other=d.v_other)
            )
        cols["split"] = np.where(holdout, "holdout", "fit")
        parts.append(pd.DataFrame(cols))
    frame = pd.concat(parts, ignore_index=True)
    extra = ["diagnosed_deg"] if "diagnosed_deg" in frame else []
    return frame[[*PRED_COLUMNS, *extra]]


def results_table(fitted, kinds: Sequence[str], axis: str):
    """A rich Table shaped like the paper's Tables 1-2: one row per model (fitted
    cycles and held-out cycles), RMSE / NRMSE / MAE (= max |error|) per dataset."""
    from rich.table import Table

    absd = [d.name for d, _, _ in fitted if d.abs_fitted]
    table = Table(
        title=f"EGPI and GPI, {axis} motor: RMSE, MAE (max |error|) in deg, NRMSE in %",
        caption=f"{', '.join(absd)}: fitted on |counts| -> |deg|" if absd else None,
    )
    table.add_column("model", no_wrap=True)
    for d, _, _ in fitted:
        for m in ("RMSE", "NRMSE", "MAE"):
            table.add_column(f"{d.name}\n{m}", justify="right", no_wrap=True)
    for kind in [k for k in ("diagnosed", "egpi", "gpi") if k in kinds]:
        for label, attr in (("fit", "metrics"), ("hold", "holdout_metrics")):
            row = [f"{kind.upper()} {label}"]
            for _, _, results in fitted:
                mt = getattr(results[kind], attr)
                row += [f"{mt.rmse_deg:.2f}", f"{mt.nrmse_pct:.2f}", f"{mt.max_abs_err_deg:.2f}"]
            if not results[kind].converged:
                row[0] += " *"
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
    from rich.console import Console
    from rich.progress import Progress

    from i2ris_calib.io.atomic import write_csv, write_json
    from i2ris_calib.io.provenance import provenance

    if model not in ("gpi", "egpi", "all"):
        raise CalibError(f"--model must be gpi, egpi or all, got '{model}'")
    if not paths:
        raise CalibError("give at least one synced CSV to fit")
    kinds = ("gpi", "egpi") if model == "all" else (model,)
    saved = read_model_file(model_file) if model_file is not None else None
    if saved is not None:
        kinds = (*kinds, "diagnosed")
    fit_config = config.fit
    datasets = load_datasets(paths, axis, fit_config)
    console = Console(stderr=True)
    with Progress(console=console, transient=True, disable=not console.is_terminal) as bar:
        task = bar.add_task("fitting", total=len(datasets) * len(kinds))

        def step(label: str) -> None:
            bar.update(task, description=f"fitting {label}", advance=1)

        fitted = fit_datasets(datasets, kinds, fit_config, progress=step, saved=saved)
    inputs = [*paths, *([model_file] if model_file is not None else [])]
    doc = fit_document(fitted, axis, kinds, provenance(inputs, config))
    out = Path(out)
    write_csv(out / "predictions.csv", predictions_frame(fitted))
    write_json(out / "fit.json", doc)
    Console().print(results_table(fitted, kinds, axis))
    if any(not r.converged for _, _, res in fitted for r in res.values()):
        console.print(
            "* not converged: see 'message' in fit.json (try more starts or --config [fit] max_nfev)"
        )
    return doc


def read_model_file(path: str | Path):
    """The model saved in a ``final_model.json`` (docs/diagnosis.md); CalibError if unreadable."""
    import json

    from i2ris_calib.diagnosis.serialize import model_from_dict

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
    import json

    p = Path(path)
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise CalibError(f"{p}: cannot read fit.json ({exc})") from None
    if doc.get("schema") != SCHEMA:
        raise CalibError(f"{p}: schema is {doc.get('schema')!r}, expected {SCHEMA!r}; re-run 'fit'")
    return doc
