"""Report tables (as :class:`~i2ris_calib.report.document.Table`) from parsed run outputs.

Metric names follow the paper (Eq25-27): RMSE (deg), NRMSE (% of the angle range),
max |error| = the MAXIMUM absolute error (deg), the paper's "MAE" in its Tables 1-2.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np
import pandas as pd

from i2ris_calib.hysteresis.kinds import PAPER_BASELINE, PAPER_KINDS, PAPER_MODEL
from i2ris_calib.hysteresis.registry import ALL_KINDS, kind_info, table_order
from i2ris_calib.report.document import Table

DASH = "—"
NOT_CONVERGED = "*"
# the paper's two, in its row order, and every model a fit.json may hold, in table
# order (a model saved by `diagnose` first, the paper's two last): from the registry
MODELS = tuple((k, kind_info(k).report_name) for k in PAPER_KINDS)
FIT_MODELS = tuple((k, kind_info(k).report_name) for k in table_order(ALL_KINDS))
METRIC_COLUMNS = (
    ("rmse_deg", "RMSE (deg)", 3),
    ("nrmse_pct", "NRMSE (%)", 2),
    ("max_abs_err_deg", "max |error| (deg)", 3),
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


def _finite(x: Any) -> float | None:
    """``x`` as a finite float, else None (None, NaN, inf, text)."""
    try:
        f = float(x)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


def _positional(x: float, decimals: int) -> str:
    """``x`` rounded to ``decimals`` places (negative: to tens, hundreds ...), no exponent."""
    if decimals >= 0:
        text = f"{x:.{decimals}f}"
    else:
        text = f"{round(x, decimals):.0f}"
    return "0" + text[2:] if text.startswith("-0") and float(text) == 0 else text


def fmt_sig(value: Any, digits: int = 4, pad: bool = False) -> str:
    """``value`` to ``digits`` significant digits, positional between 1e-4 and 1e6
    (``4225``, ``0.0364``), else ``1.23e-07``; an em dash when missing. ``pad`` keeps
    trailing zeros (``0.010``) for a number whose digits state its precision."""
    v = _finite(value)
    if v is None:
        return DASH
    if v == 0 or 1e-4 <= abs(v) < 1e6:
        if pad:  # keep trailing zeros: 0.010 says "two significant digits"
            text = np.format_float_positional(
                v, precision=digits, unique=False, fractional=False, trim="k"
            )
            return text.rstrip(".")
        return np.format_float_positional(v, precision=digits, fractional=False, trim="-")
    return f"{v:.{digits - 1}e}"


def fmt_pm(
    value: Any,
    stderr: Any,
    *,
    fixed: bool = False,
    no_stderr: str = "not identified",
    digits: int = 2,
) -> str:
    """``value ± stderr`` with the digits the uncertainty supports.

    The standard error is rounded to ``digits`` significant digits and the value to
    the same decimal place (``0.00590 ± 0.00008``, ``4225 ± 31``); a value that
    rounds to zero there keeps one significant digit (``0.00003 ± 0.16``). Very small
    or very large numbers share one power of ten: ``(3.00 ± 0.10)e-9``.

    Parameters
    ----------
    value, stderr : float or None
        Estimate and its standard error (same unit).
    fixed : bool
        The parameter was held fixed: ``"0.0364 (fixed)"``, no stderr.
    no_stderr : str
        Words for a missing (None/NaN) standard error, e.g. ``"not identified"`` or
        ``"profiled"``: ``"4225 (profiled)"``.
    digits : int
        Significant digits of the standard error.

    Returns
    -------
    str
        An em dash for a missing value. ``" (not identified)"`` is appended when the
        standard error exceeds ``|value|`` (the data do not pin the sign).
    """
    v = _finite(value)
    if v is None:
        return DASH
    if fixed:
        return f"{fmt_sig(v)} (fixed)"
    s = _finite(stderr)
    if s is None or s < 0:
        return f"{fmt_sig(v)} ({no_stderr})" if no_stderr else fmt_sig(v)
    if s == 0:
        return f"{fmt_sig(v)} ± 0"
    exp = math.floor(math.log10(s))
    decimals = digits - 1 - exp
    s_r = round(s, decimals)
    if s_r >= 10.0 ** (exp + 1):  # 0.0996 -> 0.10: one place fewer
        decimals -= 1
        s_r = round(s, decimals)
    tail = " (not identified)" if s > abs(v) else ""
    top = max(abs(v), s_r)
    if decimals > 6 or top >= 1e6:
        # one shared power of ten, mantissa to the same relative place
        e10 = math.floor(math.log10(top))
        md = max(decimals + e10, 0)
        mv, ms = v / 10.0**e10, s_r / 10.0**e10
        body = f"({_positional(mv, md)} ± {_positional(ms, md)})e{e10}"
        return body + tail
    v_text = _positional(v, decimals)
    if v != 0 and float(v_text) == 0:
        v_text = np.format_float_positional(v, precision=1, fractional=False, trim="-")
    return f"{v_text} ± {_positional(s_r, decimals)}{tail}"


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
    with RMSE (deg), NRMSE (%), max |error| (deg). A cell of model M and dataset D ends in
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
        caption=f"{axis}: model accuracy per motion direction. max |error| is the maximum "
        "absolute error (the paper's MAE, Eq27); NRMSE is RMSE over the measured angle range; "
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


# The paper's Tables 1-2 (Yue et al., real I2RIS data): (RMSE deg, NRMSE %, MAE deg)
# of its EGPI (PAPER_MODEL) and its GPI (PAPER_BASELINE).
PAPER_RESULTS = {
    "yaw": {
        "yaw+": {PAPER_MODEL: (0.36, 0.98, 1.07), PAPER_BASELINE: (2.23, 6.07, 4.88)},
        "yaw-": {PAPER_MODEL: (0.35, 1.12, 1.15), PAPER_BASELINE: (2.38, 7.50, 5.37)},
    },
    "pitch": {
        "pitch+": {PAPER_MODEL: (0.58, 1.65, 1.62), PAPER_BASELINE: (2.51, 7.16, 6.73)},
        "pitch-": {PAPER_MODEL: (0.49, 1.12, 1.62), PAPER_BASELINE: (2.64, 8.38, 5.53)},
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
        g = float(models[PAPER_BASELINE][split_key]["rmse_deg"])
        e = float(models[PAPER_MODEL][split_key]["rmse_deg"])
    except (KeyError, TypeError, ValueError):
        return None
    return g / e if e > 0 and math.isfinite(g) and math.isfinite(e) else None


MEANING_MAX_CHARS = 40
"""Longer parameter meanings are cut at their first ``:``/``;`` (or a word) and the
whole text goes to a footnote under the table."""


def short_meaning(text: str, limit: int = MEANING_MAX_CHARS) -> tuple[str, str]:
    """(cell text, footnote text) of a parameter meaning; footnote ``""`` when it fits.

    The cell keeps the part before the first ``": "`` or ``"; "`` when that fits in
    ``limit`` characters, else the words that fit followed by an ellipsis.
    """
    text = " ".join(str(text).split())
    if len(text) <= limit:
        return text, ""
    cuts = [i for i in (text.find(": "), text.find("; ")) if 0 < i <= limit]
    if cuts:
        return text[: min(cuts)], text
    head = text[: limit - 1].rsplit(" ", 1)[0]
    return head + "…", text


def param_cell(rec: Mapping[str, Any], name: str) -> str:
    """One parameter of one fitted model: :func:`fmt_pm` of its value and stderr.

    A parameter not in the record's ``free`` list (or, without that list, with stderr
    exactly 0) is "fixed"; the profiled flag point ``v_f`` has no stderr ("profiled");
    any other missing stderr means the Jacobian did not identify it.
    """
    params = rec.get("params") or {}
    if name not in params:
        return DASH
    se = (rec.get("stderr") or {}).get(name)
    free = rec.get("free")
    fixed = name not in free if isinstance(free, list) else _finite(se) == 0.0
    how = "profiled" if name in PROFILED_PARAMS else "not identified"
    return fmt_pm(params[name], se, fixed=fixed, no_stderr=how)


PROFILED_PARAMS = ("v_f",)
"""Parameters fitted by a profile search (no standard error), as in ``fitting.fit``."""


def params_table(
    dataset: Mapping[str, Any],
    info: Mapping[str, tuple[str, str]] | None = None,
    models: Iterable[str] | None = None,
) -> Table:
    """Fitted parameters as ``value ± stderr``, one column per model.

    Parameters
    ----------
    dataset : mapping
        One fit.json dataset record.
    info : mapping, optional
        Parameter name -> (unit, meaning), shown when given; a meaning longer than
        :data:`MEANING_MAX_CHARS` is shortened and given in full in a footnote.

    Each cell is :func:`param_cell`: digits set by the standard error, "not
    identified" when the standard error exceeds the value or is missing, "fixed" for
    a parameter held fixed, "profiled" for the flag point. ``models``: the fit.json
    model keys to show (default: every model of the dataset).
    """
    info = info or {}
    keep = None if models is None else set(models)
    models = [
        (k, lab)
        for k, lab in FIT_MODELS
        if isinstance(dataset.get("models", {}).get(k), dict) and (keep is None or k in keep)
    ]
    names: list[str] = []
    for k, _ in models:
        for n in dataset["models"][k].get("params", {}) or {}:
            if n not in names:
                names.append(n)
    rows, notes = [], []
    for n in names:
        unit, doc = info.get(n, ("", ""))
        cell, note = short_meaning(doc)
        if note:
            notes.append(f"{n}: {note}")
            cell = f"{cell} [{len(notes)}]"
        rows.append((n, unit, *(param_cell(dataset["models"][k], n) for k, _ in models), cell))
    return Table(
        header=("parameter", "unit", *(f"{lab} (value ± stderr)" for _, lab in models), "meaning"),
        rows=tuple(rows),
        align=("l", "l", *("r" * len(models)), "l"),
        caption=f"{_dataset_label(dataset)}: fitted parameters, ± one standard error from "
        "the Jacobian at the optimum, rounded to 2 significant digits with the value to the "
        "same decimal place. not identified = the standard error exceeds the value or the "
        "data do not determine it; fixed = held at its value; profiled = fitted by a grid "
        "search (no standard error); — = not a parameter of that model.",
        footnotes=tuple(f"[{i + 1}] {t}" for i, t in enumerate(notes)),
    )


PARAM_GROUPS = (
    ("_cp", "coupling: other motor +"),
    ("_cn", "coupling: other motor −"),
    ("_p", "tendon + (positive input)"),
    ("_n", "tendon − (|negative input|)"),
)
"""Name suffix -> column of a many-parameter model's table (the two-tendon GPI: one
GPI per tendon; with coupling, one per side of the other motor), longest suffix first."""
GROUP_ORDER = ("_p", "_n", "_cp", "_cn")
"""Column order of :func:`grouped_params_table`."""
SHARED_COLUMN = "whole axis"


def param_group(name: str) -> tuple[str, str | None]:
    """(base name, group suffix or None): ``"a1_cp"`` -> ``("a1", "_cp")``,
    ``"theta0"`` -> ``("theta0", None)``."""
    for suffix, _ in PARAM_GROUPS:
        if name.endswith(suffix) and len(name) > len(suffix):
            return name[: -len(suffix)], suffix
    return name, None


def is_grouped(rec: Mapping[str, Any]) -> bool:
    """True for a model record whose parameters come per tendon / coupling side
    (:data:`PARAM_GROUPS`), shown by :func:`grouped_params_table`."""
    return any(param_group(n)[1] for n in (rec.get("params") or {}))


def _base_meaning(doc: str) -> str:
    """A grouped parameter's meaning without its group prefix (``"positive-input
    tendon: loading envelope slope"`` -> ``"loading envelope slope"``)."""
    head, sep, rest = str(doc).partition(": ")
    return rest if sep and ("tendon" in head or "coupling" in head) else str(doc)


def grouped_params_table(
    dataset: Mapping[str, Any], key: str, info: Mapping[str, tuple[str, str]] | None = None
) -> Table:
    """One many-parameter model (the two-tendon GPI, 17 parameters; with coupling, 35)
    as a compact table: one row per GPI parameter (``a1`` ... ``rn``, ``sign``), one
    column per tendon and coupling side (:data:`PARAM_GROUPS`), a ``whole axis``
    column for the parameters shared by all (``theta0``). Cells as :func:`param_cell`.
    """
    rec = dataset["models"][key]
    names = list(rec.get("params") or {})
    labels = dict(PARAM_GROUPS)
    groups = [g for g in GROUP_ORDER if any(param_group(n)[1] == g for n in names)]
    shared = [n for n in names if param_group(n)[1] is None]
    rows, notes = _grouped_rows(rec, names, groups, info or {})
    value_cols = ([SHARED_COLUMN] if shared else []) + [labels[g] for g in groups]
    label = kind_info(key).report_name if key in ALL_KINDS else key
    return Table(
        header=("parameter", "unit", *value_cols, "meaning"),
        rows=tuple(rows),
        group_header=(("", 2), (f"{label} (value ± stderr)", len(value_cols)), ("", 1)),
        align=("l", "l", *("r" * len(value_cols)), "l"),
        caption=_grouped_caption(dataset, label, len(names), groups),
        footnotes=tuple(f"[{i + 1}] {t}" for i, t in enumerate(notes)),
    )


def _grouped_members(names: list[str]) -> dict[str, list[str]]:
    """GPI parameter base name -> its per-part names (``a1`` -> ``a1_p``, ``a1_n``, ...),
    bases in order of first appearance; shared parameters left out."""
    members: dict[str, list[str]] = {}
    for n in names:
        base, g = param_group(n)
        if g is not None:
            members.setdefault(base, []).append(n)
    return members


def _grouped_rows(
    rec: Mapping[str, Any],
    names: list[str],
    groups: list[str],
    info: Mapping[str, tuple[str, str]],
) -> tuple[list[tuple[str, ...]], list[str]]:
    """Rows of :func:`grouped_params_table` (parameter, unit, shared cell if any, one
    cell per part in ``groups``, meaning) and the footnotes the meanings refer to."""
    units = rec.get("units") if isinstance(rec.get("units"), Mapping) else {}
    shared = [n for n in names if param_group(n)[1] is None]
    rows, notes = [], []

    def meaning(name: str, grouped: bool) -> str:
        doc = info.get(name, ("", ""))[1]
        cell, note = short_meaning(_base_meaning(doc) if grouped else doc)
        if note:
            notes.append(f"{param_group(name)[0]}: {note}")
            cell = f"{cell} [{len(notes)}]"
        return cell

    def unit(name: str) -> str:
        return str(units.get(name) or info.get(name, ("", ""))[0])

    for n in shared:
        cells = [param_cell(rec, n)] + [DASH] * len(groups)
        rows.append((n, unit(n), *cells, meaning(n, False)))
    for b, parts in _grouped_members(names).items():
        cells = [DASH] if shared else []
        cells += [param_cell(rec, b + g) if b + g in names else DASH for g in groups]
        rows.append((b, unit(parts[0]), *cells, meaning(parts[0], True)))
    return rows, notes


def _grouped_caption(dataset: Mapping[str, Any], label: str, n_params: int, groups) -> str:
    """Caption of :func:`grouped_params_table`: what rows, columns and cells mean."""
    return (
        f"{_dataset_label(dataset)}: {label}, {n_params} parameters: one GPI "
        "per tendon"
        + (
            " and per side of the other motor (coupling)"
            if any(g in groups for g in ("_cp", "_cn"))
            else ""
        )
        + ": a row per GPI parameter, a column per part (fit.json names them <row>_p, "
        f"<row>_n, <row>_cp, <row>_cn); {SHARED_COLUMN} = shared by every part. Value ± "
        "one standard error from the Jacobian; not identified = the standard error "
        "exceeds the value or the data do not determine it; fixed = held at its value; "
        "— = not in that part."
    )


def at_bound(dataset: Mapping[str, Any], key: str) -> list[str]:
    """Free parameters of model ``key`` that the fit left on a bound (the search found
    no lower cost inside it: a constrained optimum)."""
    rec = dataset.get("models", {}).get(key)
    if not isinstance(rec, Mapping):
        return []
    reasons = rec.get("stderr_reasons") or {}
    return [n for n, r in reasons.items() if str(r).startswith("at its bound")]


def unidentified(dataset: Mapping[str, Any], key: str) -> list[str]:
    """Free parameters of model ``key`` whose stderr is missing or exceeds |value|
    (the profiled flag point excluded: it has no stderr by construction)."""
    rec = dataset.get("models", {}).get(key)
    if not isinstance(rec, Mapping):
        return []
    out = []
    free = rec.get("free")
    reasons = rec.get("stderr_reasons") or {}
    for n, v in (rec.get("params") or {}).items():
        se = _finite((rec.get("stderr") or {}).get(n))
        if n in PROFILED_PARAMS or (isinstance(free, list) and n not in free) or se == 0.0:
            continue
        if str(reasons.get(n, "")).startswith("at its bound"):
            continue  # a constrained optimum (at_bound lists it), not a lack of data
        val = _finite(v)
        if se is None or val is None or se > abs(val):
            out.append(n)
    return out


FIT_INFO_KEYS = (
    ("converged", "converged"),
    ("nfev", "function evals"),
    ("n_samples", "samples"),
    ("v_f", "flag point v_f (counts)"),
    ("aic", "AIC"),
    ("bic", "BIC"),
    ("message", "optimizer message"),
)


def certificate_cell(cert: Any) -> str:
    """The fit's search certificate (fit.json ``certificate``) in a few words: how many
    starts reached the best cost, the next minimum found, and a warning mark when only
    one start reached it; an em dash when the record has none (an older fit.json)."""
    if not isinstance(cert, Mapping) or _finite(cert.get("at_best")) is None:
        return "\u2014"
    n_all = int(_finite(cert.get("starts")) or 0) + int(_finite(cert.get("hops")) or 0)
    txt = f"{int(cert['at_best'])} of {n_all} starts at the best cost"
    nxt, best = _finite(cert.get("next_cost")), _finite(cert.get("best_cost"))
    if nxt is not None and best:
        txt += f"; next minimum {nxt / best:.4g}x"
    if cert.get("certified") is False:
        txt = "**only one start reached it**: " + txt
    return txt


def fit_info_table(dataset: Mapping[str, Any]) -> Table:
    """Convergence and information criteria per model for one dataset."""
    models = [
        (k, lab) for k, lab in FIT_MODELS if isinstance(dataset.get("models", {}).get(k), dict)
    ]
    rows = tuple(
        (
            lab,
            *(fmt(dataset["models"][k].get(key)) for key, _ in FIT_INFO_KEYS),
            certificate_cell(dataset["models"][k].get("certificate")),
        )
        for k, lab in models
    )
    return Table(
        header=("model", *(label for _, label in FIT_INFO_KEYS), "global search"),
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
        **_roll_stat(angles, status == "measured"),
    }


def _roll_stat(angles: pd.DataFrame, measured: pd.Series) -> dict[str, float]:
    """``roll_p95_abs_deg``: 95th percentile of |roll_deg| over measured frames, when present."""
    if "roll_deg" not in angles:
        return {}
    roll = pd.to_numeric(angles.loc[measured, "roll_deg"], errors="coerce").to_numpy(dtype=float)
    roll = roll[np.isfinite(roll)]
    return {"roll_p95_abs_deg": float(np.percentile(np.abs(roll), 95))} if roll.size else {}


def tracking_table(
    summary: Mapping[str, Any],
    track: Mapping[str, Any] | None = None,
    noise_deg: Mapping[str, float] | None = None,
) -> Table:
    """Tracking quality in at most 12 rows: frames, status counts, reprojection error,
    angle noise per axis, roll per frame and the reference roll.

    Parameters
    ----------
    summary : mapping
        :func:`tracking_summary` of angles.csv.
    track : mapping, optional
        Parsed track.json (reference roll).
    noise_deg : mapping, optional
        Angle column -> frame-to-frame noise (deg), e.g. ``{"yaw": 0.004}``.
    """
    n = summary["n_frames"]
    rows = [
        ("frames", fmt(n)),
        ("duration (s, camera clock)", fmt(summary["duration_s"], 2)),
        ("detection rate (%)", fmt(100 * summary["detection_rate"], 1)),
    ]
    for st, c in summary["counts"].items():
        if st != "measured":
            rows.append((f"frames {st}", f"{c} ({fmt(100 * c / n if n else None, 1)} %)"))
    rows.append(
        (
            "reprojection error median / 95 % / max (px)",
            " / ".join(
                fmt_sig(summary[k], 2)
                for k in ("reproj_median_px", "reproj_p95_px", "reproj_max_px")
            ),
        )
    )
    for axis, sd in (noise_deg or {}).items():
        rows.append((f"{axis} noise, frame to frame (deg, 1 sd)", fmt_sig(sd, 2, pad=True)))
    if "roll_p95_abs_deg" in summary:
        rows.append(
            ("roll per frame, 95 % of |roll| below (deg)", fmt_sig(summary["roll_p95_abs_deg"], 2))
        )
    ref = (track or {}).get("reference")
    if isinstance(ref, Mapping) and ref.get("roll_correction_deg") is not None:
        rows.append(
            (
                f"reference roll correction (deg, {ref.get('roll_method', '?')})",
                fmt_pm(ref.get("roll_correction_deg"), ref.get("roll_sd_deg")),
            )
        )
    return Table(
        header=("quantity", "value"),
        rows=tuple(rows),
        caption="Tracking quality from track/angles.csv (reprojection error over measured "
        "frames) and track/track.json. Angle noise: robust sd of second differences over "
        "three consecutive measured frames / sqrt(6). Roll is the twist about the tool "
        "axis (poorly conditioned; a diagnostic, not used downstream).",
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


def clock_table(view: Any, sync: Mapping[str, Any]) -> Table:
    """The clock in at most 14 rows: method, offset and drift with standard errors, the
    stated error in the middle and at worst, each method's clock alone, flash edges,
    rows synced, glitches, the (biased) cross-correlation for comparison.

    Parameters
    ----------
    view : ClockView
        :func:`i2ris_calib.report.clock.clock_view` of ``sync``.
    sync : mapping
        Parsed sync.json.
    """
    return Table(
        header=("quantity", "value"),
        rows=tuple(_clock_rows(view) + _synced_rows(sync, view.clock)),
        align=("l", "l"),
        caption="t_ctrl = offset + (1 + drift 1e-6) t_cam (controller clock from camera "
        "clock); ± one standard error. The stated error of the clock at any time follows "
        "from the offset's and the drift's (it grows away from t_ref). The raw sync.json "
        "is in the appendix.",
    )


def _drift_text(line: Any) -> str:
    """Drift ± stderr (ppm) of a clock line, or its held value when not fitted."""
    if math.isfinite(line.drift_sd_ppm):
        return fmt_pm(line.drift_ppm, line.drift_sd_ppm) + " ppm"
    return f"{fmt_sig(line.drift_ppm, 3)} ppm (held, not fitted)"


def _clock_rows(view: Any) -> list[tuple[str, str]]:
    """(quantity, value) rows of the clock itself: method, offset at ``t_ref`` (s),
    drift (ppm), stated error (ms), each method's clock alone, event - model, edges."""
    c = view.clock
    worst, t_worst = view.worst_sd()
    ms = lambda x: fmt_sig(1e3 * x, 2)  # noqa: E731
    rows = [
        ("method used (asked)", f"{view.method} ({view.requested})"),
        (
            f"offset at t_cam = {fmt_sig(c.t_ref_s, 4)} s",
            fmt_pm(c.offset_ref_s, c.offset_ref_sd_s) + " s",
        ),
        ("drift", _drift_text(c)),
        (
            "stated clock error, 1 sd: middle / worst",
            f"{ms(c.offset_ref_sd_s)} ms / {ms(worst)} ms (at t_cam = {fmt_sig(t_worst, 3)} s)",
        ),
    ]
    for line in view.others:
        rows.append(
            (
                f"{line.label}: offset at t_cam = {fmt_sig(line.t_ref_s, 4)} s; drift",
                f"{fmt_pm(line.offset_ref_s, line.offset_ref_sd_s)} s; {_drift_text(line)}",
            )
        )
    if math.isfinite(view.z):
        rows.append(("event − model (combined sd)", fmt_sig(view.z, 2)))
    if view.edges or view.n_camera_edges is not None:
        rows.append(
            (
                "flash edges matched (camera / log edges)",
                f"{len(view.edges)} ({fmt(view.n_camera_edges)} / {fmt(view.n_log_edges)})",
            )
        )
    return rows


def _synced_rows(sync: Mapping[str, Any], c: Any) -> list[tuple[str, str]]:
    """(quantity, value) rows of what sync.json reports besides the clock ``c``: frames
    synced, glitches, plain cross-correlation (ms from the clock), time ranges (s)."""
    rows = [
        (
            "frames synced / outside the encoder log",
            f"{fmt(sync.get('n_rows'))} / {fmt(sync.get('n_dropped_outside_log'))}",
        )
    ]
    glitches = sync.get("encoder_glitches")
    if isinstance(glitches, Mapping):
        rows.append(("encoder glitches replaced", fmt(glitches.get("n_samples"))))
    xc = sync.get("xcorr_comparison")
    if isinstance(xc, Mapping) and _finite(xc.get("offset_s")) is not None:
        off = float(xc["offset_s"]) + (_finite(xc.get("drift_ppm")) or 0.0) * 1e-6 * c.t_ref_s
        rows.append(
            (
                "plain cross-correlation (biased, comparison only)",
                f"{fmt_sig(1e3 * (off - c.offset_ref_s), 3)} ms from the clock at t_ref",
            )
        )
    for key, label in (("camera_time_range_s", "camera"), ("log_time_range_s", "encoder log")):
        rng = sync.get(key)
        if isinstance(rng, list) and len(rng) == 2:
            rows.append((f"{label} time range (s)", f"{fmt_sig(rng[0], 4)} – {fmt_sig(rng[1], 4)}"))
    return rows


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
