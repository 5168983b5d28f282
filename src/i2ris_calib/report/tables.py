"""Report tables (as :class:`~i2ris_calib.report.document.Table`) from parsed run outputs.

Metric names follow the paper (Eq25-27): RMSE (deg), NRMSE (% of the angle range),
MAE = MAXIMUM absolute error (deg), as in the paper's Tables 1-2.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np
import pandas as pd

from i2ris_calib.report.document import Table

DASH = "—"
NOT_CONVERGED = "*"
MODELS = (("egpi", "EGPI"), ("gpi", "GPI"))  # the paper's two, in its row order
# fitted models a fit.json may hold, in table order: a model saved by `diagnose`, the
# continuous EGPI, then the paper's two
FIT_MODELS = (("diagnosed", "EGPI + diagnosed effects"), ("egpi_c", "EGPI_C"), *MODELS)
METRIC_COLUMNS = (
    ("rmse_deg", "RMSE (deg)", 3),
    ("nrmse_pct", "NRMSE (%)", 2),
    ("max_abs_err_deg", "MAE (deg)", 3),
)
TRACK_STATUSES = ("measured", "not_found", "ambiguous", "rejected")


def fmt(value: Any, digits: int | None = None) -> str:
    """Text for a table cell: fixed ``digits`` decimals, or 6 significant digits.

    None, NaN and missing values become an em dash; booleans and strings pass through.
    """
    if value is None:
        return DASH
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        if not math.isfinite(float(value)):
            return DASH
        return f"{float(value):.{digits}f}" if digits is not None else f"{float(value):.6g}"
    if isinstance(value, (list, tuple)):
        return ", ".join(fmt(v, digits) for v in value) if value else DASH
    if isinstance(value, Mapping):
        return ", ".join(f"{k}={fmt(v, digits)}" for k, v in value.items()) if value else DASH
    return str(value)


def fit_datasets(fit: Mapping[str, Any]) -> list[dict[str, Any]]:
    """The dataset records of a fit.json (the single-dataset top-level form included)."""
    datasets = fit.get("datasets")
    if isinstance(datasets, list) and datasets:
        return [d for d in datasets if isinstance(d, dict)]
    if isinstance(fit.get("models"), dict):
        name = f"{fit.get('axis', '')}{fit.get('direction', '')}" or "dataset"
        return [{"name": name, "direction": fit.get("direction", ""), "models": fit["models"]}]
    return []


def not_converged(dataset: Mapping[str, Any], key: str) -> bool:
    """True when model ``key`` of this dataset is recorded as not converged.

    A missing record or a missing ``converged`` field is not a failure.
    """
    rec = dataset.get("models", {}).get(key)
    return isinstance(rec, Mapping) and rec.get("converged") is False


def metric_cell(value: Any, digits: int, star: bool) -> str:
    """A metric cell: :func:`fmt` with ``digits`` decimals, ``*`` appended when ``star``."""
    text = fmt(value, digits)
    return text + NOT_CONVERGED if star else text


def metrics_table(axis: str, datasets: list[dict[str, Any]]) -> Table:
    """Paper-shaped accuracy table for one axis (like Tables 1-2).

    Rows: model (EGPI + diagnosed effects, EGPI_C, EGPI, GPI; those present) x data
    split (fitted, held-out). Column groups: one per dataset (motion direction), each
    with RMSE (deg), NRMSE (%), MAE (deg). A cell of model M and dataset D ends in
    ``*`` when M's fit of D did not converge (``converged`` false in fit.json), and
    only that cell group.
    """
    header = ["model", "data"]
    groups: list[tuple[str, int]] = [("", 2)]
    for d in datasets:
        header += [label for _, label, _ in METRIC_COLUMNS]
        groups.append((str(d.get("name", "dataset")), len(METRIC_COLUMNS)))
    rows = []
    starred = False
    for key, label in FIT_MODELS:
        if not any(key in d.get("models", {}) for d in datasets):
            continue
        for split_key, split_label in (("metrics", "fitted"), ("holdout_metrics", "held-out")):
            row = [label, split_label]
            for d in datasets:
                m = (d.get("models", {}).get(key) or {}).get(split_key) or {}
                star = not_converged(d, key)
                starred |= star
                row += [metric_cell(m.get(k), digits, star) for k, _, digits in METRIC_COLUMNS]
            rows.append(tuple(row))
    star_note = (
        f" {NOT_CONVERGED} = that model's fit of that dataset did not converge (see its "
        "optimizer message under Fitted parameters)."
        if starred
        else ""
    )
    return Table(
        header=tuple(header),
        rows=tuple(rows),
        group_header=tuple(groups),
        caption=f"{axis}: model accuracy per motion direction. MAE is the MAXIMUM absolute "
        "error, as in the paper (Eq27); NRMSE is RMSE over the measured angle range; "
        "fitted = the dataset's own samples in the loss, held-out = its held-out loading "
        "cycles (not used for fitting); EGPI_C = continuous EGPI (no output step at the "
        "flag point)." + _abs_note(datasets) + star_note,
    )


ROW_COLUMNS = (
    ("total", "samples in recording"),
    ("in_direction", "own samples"),
    ("fitted", "fitted"),
    ("holdout", "held out"),
    ("angle_missing", "not measured"),
    ("other", "other direction"),
)


def rows_from_predictions(pred: pd.DataFrame) -> dict[str, int]:
    """Row accounting of one dataset recomputed from its predictions.csv rows.

    Same keys as fit.json ``rows`` plus ``other``: ``fitted`` / ``holdout`` count own
    samples with a measured angle, ``angle_missing`` own samples without one.
    """
    split = pred["split"].astype(str).to_numpy()
    measured = np.isfinite(pred["theta_deg"].to_numpy(dtype=float))
    own = split != "other"
    return {
        "total": int(split.size),
        "in_direction": int(own.sum()),
        "fitted": int((measured & (split == "fit")).sum()),
        "holdout": int((measured & (split == "holdout")).sum()),
        "angle_missing": int((own & ~measured).sum()),
        "other": int((~own).sum()),
    }


def dataset_rows(
    dataset: Mapping[str, Any], pred: pd.DataFrame | None = None
) -> dict[str, Any] | None:
    """Row accounting of a dataset: fit.json ``rows`` (plus ``other`` = total - own), or
    recomputed from its predictions.csv rows when fit.json has none; None without either."""
    rows = dataset.get("rows")
    if isinstance(rows, Mapping) and rows:
        out = dict(rows)
        try:
            out.setdefault("other", int(rows["total"]) - int(rows["in_direction"]))
        except (KeyError, TypeError, ValueError):
            out.setdefault("other", None)
        return out
    if pred is not None and not pred.empty:
        return rows_from_predictions(pred)
    return None


def _band(bands: Mapping[str, Any], key: str, name: str) -> str:
    text = fmt(bands.get(key), 3)
    derived = bands.get("derived") or ()
    return f"{text} (derived)" if text != DASH and name in derived else text


def samples_table(
    axis: str,
    datasets: list[dict[str, Any]],
    predictions: Mapping[str, pd.DataFrame] | None = None,
) -> Table | None:
    """How many samples of each dataset were fitted, held out, not measured, other.

    Parameters
    ----------
    axis : str
        Axis name (caption).
    datasets : list of mapping
        fit.json dataset records (``rows``, ``bands`` used when present).
    predictions : mapping, optional
        Dataset name -> its predictions.csv rows, used when fit.json has no ``rows``.

    Returns
    -------
    Table or None
        None when no dataset has an accounting.
    """
    predictions = predictions or {}
    body = []
    for d in datasets:
        name = str(d.get("name", "dataset"))
        rows = dataset_rows(d, predictions.get(name))
        if rows is None:
            continue
        bands = d.get("bands") if isinstance(d.get("bands"), Mapping) else {}
        body.append(
            (
                name,
                *(fmt(rows.get(k)) for k, _ in ROW_COLUMNS),
                _band(bands, "zero_band", "zero_band"),
                _band(bands, "deadband", "deadband"),
            )
        )
    if not body:
        return None
    return Table(
        header=(
            "dataset",
            *(label for _, label in ROW_COLUMNS),
            "zero band (input unit)",
            "v' dead band (input unit)",
        ),
        rows=tuple(body),
        caption=f"{axis}: samples per dataset. Every sample of the recording drives each "
        "model (its operators need the whole input history); only the dataset's own "
        "samples (its motion direction) with a measured angle enter the loss (fitted) or "
        "the held-out metrics (held out). not measured = own samples without an angle; "
        "other direction = samples of the opposite direction (the model's input rests "
        "at 0 there; not in loss or metrics). A sample inside the zero band belongs to "
        "the excursion before it. Bands are in the input's unit (counts for encoders).",
    )


# The paper's Tables 1-2 (Yue et al., real I2RIS data): (RMSE deg, NRMSE %, MAE deg).
PAPER_RESULTS = {
    "yaw": {
        "yaw+": {"egpi": (0.36, 0.98, 1.07), "gpi": (2.23, 6.07, 4.88)},
        "yaw-": {"egpi": (0.35, 1.12, 1.15), "gpi": (2.38, 7.50, 5.37)},
    },
    "pitch": {
        "pitch+": {"egpi": (0.58, 1.65, 1.62), "gpi": (2.51, 7.16, 6.73)},
        "pitch-": {"egpi": (0.49, 1.12, 1.62), "gpi": (2.64, 8.38, 5.53)},
    },
}


def paper_table(axis: str) -> Table:
    """The paper's published accuracy for ``axis``, in the layout of :func:`metrics_table`."""
    results = PAPER_RESULTS[axis]
    header = ["model", "data"]
    groups: list[tuple[str, int]] = [("", 2)]
    for name in results:
        header += [label for _, label, _ in METRIC_COLUMNS]
        groups.append((f"{name} (paper)", len(METRIC_COLUMNS)))
    rows = []
    for key, label in MODELS:
        row = [label, "paper"]
        for name in results:
            rmse, nrmse, mae = results[name][key]
            row += [f"{rmse:.2f}", f"{nrmse:.2f}", f"{mae:.2f}"]
        rows.append(tuple(row))
    return Table(
        header=tuple(header),
        rows=tuple(rows),
        group_header=tuple(groups),
        caption=f"{axis}: the paper's published values on real I2RIS data (Yue et al., Tables "
        "1-2), for comparison; negative sets fitted as |input| -> |angle|.",
    )


def _abs_note(datasets: list[dict[str, Any]]) -> str:
    names = [str(d.get("name")) for d in datasets if d.get("abs_fitted")]
    return (
        f" {', '.join(names)}: input max(-enc, 0), angle -theta (= |input| -> |angle| on "
        "its own samples, as in the paper)."
        if names
        else ""
    )


def _dataset_label(d: Mapping[str, Any]) -> str:
    label = str(d.get("name", "dataset"))
    if d.get("abs_fitted"):
        label += " (input max(-enc, 0), angle -theta)"
    return label


def gpi_egpi_ratio(dataset: Mapping[str, Any], split_key: str = "holdout_metrics") -> float | None:
    """GPI RMSE / EGPI RMSE for one dataset on ``split_key`` (None when not available)."""
    models = dataset.get("models", {})
    try:
        g = float(models["gpi"][split_key]["rmse_deg"])
        e = float(models["egpi"][split_key]["rmse_deg"])
    except (KeyError, TypeError, ValueError):
        return None
    return g / e if e > 0 and math.isfinite(g) and math.isfinite(e) else None


def params_table(
    dataset: Mapping[str, Any], info: Mapping[str, tuple[str, str]] | None = None
) -> Table:
    """Fitted parameters with standard errors, one column group per model.

    Parameters
    ----------
    dataset : mapping
        One fit.json dataset record.
    info : mapping, optional
        Parameter name -> (unit, one-line meaning), shown when given.

    The relative standard error (stderr / |value|, %) flags poorly determined
    parameters.
    """
    info = info or {}
    models = [
        (k, lab) for k, lab in FIT_MODELS if isinstance(dataset.get("models", {}).get(k), dict)
    ]
    names: list[str] = []
    for k, _ in models:
        for n in dataset["models"][k].get("params", {}) or {}:
            if n not in names:
                names.append(n)
    header = ["parameter", "unit"]
    for _, lab in models:
        header += [f"{lab} value", f"{lab} stderr", f"{lab} rel. stderr (%)"]
    header.append("meaning")
    rows = []
    for n in names:
        unit, doc = info.get(n, ("", ""))
        row = [n, unit]
        for k, _ in models:
            rec = dataset["models"][k]
            val = (rec.get("params") or {}).get(n)
            se = (rec.get("stderr") or {}).get(n)
            row += [fmt(val), fmt(se), fmt(_relative_pct(val, se), 1)]
        rows.append((*row, doc))
    return Table(
        header=tuple(header),
        rows=tuple(rows),
        align=("l", "l", *("r" * (3 * len(models))), "l"),
        caption=f"{_dataset_label(dataset)}: fitted parameters (stderr from the LM Jacobian; "
        "— = not a parameter of that model, held fixed, or not estimable).",
    )


def _relative_pct(value: Any, stderr: Any) -> float | None:
    try:
        v, s = float(value), float(stderr)
    except (TypeError, ValueError):
        return None
    return 100.0 * s / abs(v) if v != 0 else None


FIT_INFO_KEYS = (
    ("converged", "converged"),
    ("nfev", "function evals"),
    ("n_samples", "samples"),
    ("v_f", "flag point v_f (counts)"),
    ("aic", "AIC"),
    ("bic", "BIC"),
    ("message", "optimizer message"),
)


def fit_info_table(dataset: Mapping[str, Any]) -> Table:
    """Convergence and information criteria per model for one dataset."""
    models = [
        (k, lab) for k, lab in FIT_MODELS if isinstance(dataset.get("models", {}).get(k), dict)
    ]
    rows = tuple(
        (lab, *(fmt(dataset["models"][k].get(key)) for key, _ in FIT_INFO_KEYS))
        for k, lab in models
    )
    return Table(
        header=("model", *(label for _, label in FIT_INFO_KEYS)),
        rows=rows,
        caption=f"{_dataset_label(dataset)}: fit diagnostics.",
    )


def tracking_summary(angles: pd.DataFrame) -> dict[str, Any]:
    """Frame counts per status, detection rate and reprojection-error statistics.

    Parameters
    ----------
    angles : DataFrame
        track/angles.csv with ``status`` and (optionally) ``reproj_err_px``.

    Returns
    -------
    dict
        ``n_frames``, ``counts`` (status -> int), ``detection_rate`` (measured /
        frames, 0-1), ``reproj_median_px``, ``reproj_p95_px``, ``reproj_max_px``
        (over measured frames with a finite error; NaN when none), ``duration_s``.
    """
    status = angles["status"].astype(str)
    counts = {s: int((status == s).sum()) for s in TRACK_STATUSES}
    for s in sorted(set(status) - set(TRACK_STATUSES)):
        counts[s] = int((status == s).sum())
    n = len(angles)
    err = (
        angles.loc[status == "measured", "reproj_err_px"].to_numpy(dtype=float)
        if "reproj_err_px" in angles
        else np.array([])
    )
    err = err[np.isfinite(err)]
    t = angles["time_s"].to_numpy(dtype=float)
    stat = lambda f: float(f(err)) if err.size else float("nan")  # noqa: E731
    return {
        "n_frames": n,
        "counts": counts,
        "detection_rate": counts["measured"] / n if n else float("nan"),
        "reproj_median_px": stat(np.median),
        "reproj_p95_px": stat(lambda e: np.percentile(e, 95)),
        "reproj_max_px": stat(np.max),
        "duration_s": float(np.nanmax(t) - np.nanmin(t)) if n else float("nan"),
    }


def tracking_table(summary: Mapping[str, Any]) -> Table:
    """Key/value table of :func:`tracking_summary`."""
    n = summary["n_frames"]
    rows = [
        ("frames", fmt(n)),
        ("duration (s, camera clock)", fmt(summary["duration_s"], 2)),
        ("detection rate (%)", fmt(100 * summary["detection_rate"], 1)),
    ]
    for s, c in summary["counts"].items():
        rows.append((f"frames {s}", f"{c} ({fmt(100 * c / n if n else None, 1)} %)"))
    rows += [
        ("reprojection error median (px)", fmt(summary["reproj_median_px"], 3)),
        ("reprojection error 95th percentile (px)", fmt(summary["reproj_p95_px"], 3)),
        ("reprojection error max (px)", fmt(summary["reproj_max_px"], 3)),
    ]
    return Table(
        header=("quantity", "value"),
        rows=tuple(rows),
        caption="Tracking quality computed from track/angles.csv (reprojection error over "
        "measured frames only).",
    )


def flatten(
    obj: Mapping[str, Any], prefix: str = "", skip: Iterable[str] = ("provenance",)
) -> list[tuple[str, Any]]:
    """(dotted key, scalar) pairs of a nested JSON mapping, ``skip`` keys left out.

    Lists of scalars stay one value; lists of mappings are indexed (``steps.0.effect``).
    """
    out: list[tuple[str, Any]] = []
    skip = tuple(skip)
    for k, v in obj.items():
        if k in skip:
            continue
        key = f"{prefix}{k}"
        if isinstance(v, Mapping):
            out += flatten(v, f"{key}.", skip)
        elif isinstance(v, list) and v and all(isinstance(x, Mapping) for x in v):
            for i, x in enumerate(v):
                out += flatten(x, f"{key}.{i}.", skip)
        else:
            out.append((key, v))
    return out


def key_value_table(
    obj: Mapping[str, Any], caption: str, skip: Iterable[str] = ("provenance",)
) -> Table:
    """Every scalar of a JSON mapping as a (key, value) row."""
    return Table(
        header=("key", "value"),
        rows=tuple((k, fmt(v)) for k, v in flatten(obj, skip=skip)),
        caption=caption,
    )


def find_stderr(obj: Mapping[str, Any], name: str) -> Any:
    """Standard error recorded beside ``name`` in a JSON mapping, or None.

    Accepts ``<name>_stderr``, ``<stem>_stderr_<unit>`` (e.g. ``offset_stderr_s``
    for ``offset_s``), ``<name>_std``/``_se``/``_sigma`` and a ``stderr`` sub-mapping.
    """
    stem, _, unit = name.rpartition("_")
    cands = [f"{name}_{tag}" for tag in ("stderr", "std", "se", "sigma", "err")]
    cands += [f"{stem}_{tag}_{unit}" for tag in ("stderr", "std", "se", "sigma", "err")]
    for c in cands:
        if c in obj:
            return obj[c]
    for sub in ("stderr", "standard_errors", "std"):
        if isinstance(obj.get(sub), Mapping) and name in obj[sub]:
            return obj[sub][name]
    return None


def sync_table(sync: Mapping[str, Any]) -> Table:
    """Clock offset and drift with standard errors, then the method; the offset in the
    middle of the data, encoder glitches replaced and sync warnings when recorded."""
    rows = []
    for name, label, digits in (("offset_s", "offset (s)", 6), ("drift_ppm", "drift (ppm)", 3)):
        val, se = sync.get(name), find_stderr(sync, name)
        rows.append((label, fmt(val, digits), fmt(se, digits)))
    rows.append(("method", fmt(sync.get("method")), ""))
    if "offset_at_t_ref_s" in sync and "t_ref_cam_s" in sync:
        rows.append(
            (
                f"offset at t_cam = {fmt(sync['t_ref_cam_s'], 3)} s (s)",
                fmt(sync["offset_at_t_ref_s"], 6),
                fmt(sync.get("offset_at_t_ref_stderr_s"), 6),
            )
        )
    glitches = sync.get("encoder_glitches")
    if isinstance(glitches, Mapping):
        rows.append(("encoder glitches replaced", fmt(glitches.get("n_samples")), ""))
    for w in sync.get("warnings") or ():
        rows.append(("warning", str(w), ""))
    return Table(
        header=("quantity", "estimate", "standard error"),
        rows=tuple(rows),
        caption="t_ctrl = offset_s + (1 + drift_ppm * 1e-6) * t_cam (controller clock from "
        "camera clock).",
    )


def provenance_table(label: str, prov: Mapping[str, Any]) -> Table:
    """Package version, Python and SHA-256 of every input file of one output."""
    rows = [
        ("package version", fmt(prov.get("version"))),
        ("python", fmt(prov.get("python"))),
    ]
    for path, digest in (prov.get("inputs") or {}).items():
        rows.append((f"input {path}", f"sha256 {digest}"))
    for k, v in prov.items():
        if k not in ("package", "version", "python", "config", "inputs"):
            rows.append((k, fmt(v)))
    return Table(header=("item", "value"), rows=tuple(rows), caption=f"Provenance of {label}.")
