"""Report figures as PNG bytes, from in-memory frames.

matplotlib is imported inside the functions (Agg canvas, no pyplot state), so
importing this module is cheap. Figure sizes (inches) and DPI are fixed, and no
timestamp is written into the PNG, so the same data give the same bytes.
"""

from __future__ import annotations

import io
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

MEASURED_COLOR = "0.45"
GPI_COLOR = "#D55E00"  # vermillion (Okabe-Ito, colour-blind safe)
EGPI_COLOR = "#0072B2"  # blue
EGPI_C_COLOR = "#CC79A7"  # reddish purple
DIAGNOSED_COLOR = "#009E73"  # bluish green
AGPI_COLOR = "#56B4E9"  # sky blue
AGPI_COUPLED_COLOR = "#E69F00"  # orange
SLIP_COLOR = "#000000"  # black
BOUC_WEN_COLOR = "0.35"  # dark grey
HOLDOUT_COLOR = "#F0E442"
OTHER_COLOR = "0.6"
GAP_FACTOR = 1.5
BAND_SIGMA = 2.0
"""Bands are drawn at +-2 standard errors (about 95 %): the confidence band of the
model curve (parameter covariance) and, wider, the prediction band of a new
measurement (that plus the model's residual sd)."""
"""A time step longer than this times the median step is a gap (no line across it)."""
STATUS_COLORS = {"not_found": "#E69F00", "ambiguous": "#CC79A7", "rejected": "#D55E00"}


def _new_figure(width_in: float, height_in: float):
    """A matplotlib Figure on an Agg canvas (no global pyplot state)."""
    fig = Figure(figsize=(width_in, height_in), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def figure_png(fig, dpi: int) -> bytes:
    """Encode ``fig`` as PNG bytes at ``dpi`` with no software/date metadata."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, metadata={"Software": None})
    return buf.getvalue()


def thinning_step(n: int, max_points: int) -> int:
    """Step k so that every k-th of ``n`` samples gives at most ``max_points``."""
    return max(1, int(np.ceil(n / max(1, max_points))))


def holdout_spans(time_s: np.ndarray, is_holdout: np.ndarray) -> list[tuple[float, float]]:
    """Time intervals (s) of contiguous held-out samples, in time order.

    Parameters
    ----------
    time_s : ndarray, shape (n,)
        Sample times, sorted ascending (s).
    is_holdout : ndarray of bool, shape (n,)
        True for held-out samples.
    """
    spans = []
    flags = np.asarray(is_holdout, dtype=bool)
    if flags.size == 0:
        return spans
    edges = np.flatnonzero(np.diff(flags.astype(np.int8))) + 1
    starts = np.r_[0, edges]
    ends = np.r_[edges, flags.size]
    for a, b in zip(starts, ends, strict=True):
        if flags[a]:
            spans.append((float(time_s[a]), float(time_s[b - 1])))
    return spans


def _shade(
    ax, spans: list[tuple[float, float]], color: str, alpha: float, label: str,
    hatch: str | None = None,
) -> None:  # fmt: skip
    for i, (a, b) in enumerate(spans):
        ax.axvspan(a, b, color=color, alpha=alpha, lw=0, label=label if i == 0 else None,
                   hatch=hatch)  # fmt: skip


MODEL_CURVES = (
    ("gpi_deg", "GPI", GPI_COLOR),
    ("egpi_deg", "EGPI", EGPI_COLOR),
    ("egpi_c_deg", "EGPI_C", EGPI_C_COLOR),
    ("agpi_deg", "two-tendon GPI", AGPI_COLOR),
    ("agpi_coupled_deg", "two-tendon GPI + coupling", AGPI_COUPLED_COLOR),
    ("maxwell_slip_deg", "PI / Maxwell slip", SLIP_COLOR),
    ("bouc_wen_deg", "Bouc-Wen", BOUC_WEN_COLOR),
    ("diagnosed_deg", "EGPI + effects", DIAGNOSED_COLOR),
)
"""(predictions.csv column, legend label, colour) of every model curve, drawing order:
every fitted kind, so the recommended model is always drawn."""


def _model_columns(pred: pd.DataFrame) -> list[tuple[str, str, str]]:
    """(column, label, colour) for each model column present with finite values."""
    return drawn_models(pred)


def drawn_models(pred: pd.DataFrame) -> list[tuple[str, str, str]]:
    """(column, label, colour) of the model curves a Fig-6 panel draws for these rows:
    every :data:`MODEL_CURVES` column present with a finite value (a signed fit's
    predictions.csv has empty ``egpi_deg`` columns: not drawn, not named)."""
    return [
        (col, label, color)
        for col, label, color in MODEL_CURVES
        if col in pred and np.isfinite(pred[col].to_numpy(dtype=float)).any()
    ]


def continuation(
    time_s: np.ndarray, keep: np.ndarray, gap_factor: float = GAP_FACTOR
) -> np.ndarray:
    """True where sample i may be joined by a line to sample i-1, shape (n,).

    A line may join two consecutive samples of the recording only when both are kept
    and no sample is missing between them: the time step is at most ``gap_factor``
    times the recording's median step (dropped frames, pauses, a spliced file), so a
    line never bridges a stretch that is not drawn.

    Parameters
    ----------
    time_s : ndarray, shape (n,)
        Sample times of the whole recording, sorted ascending (s).
    keep : ndarray of bool, shape (n,)
        Samples that are drawn.
    gap_factor : float
        A step longer than ``gap_factor x median step`` is a gap.

    Returns
    -------
    ndarray of bool, shape (n,)
        ``False`` at index 0, at every dropped sample and after every gap or dropped sample.
    """
    t = np.asarray(time_s, dtype=float)
    k = np.asarray(keep, dtype=bool)
    out = np.zeros(t.size, dtype=bool)
    if t.size < 2:
        return out
    dt = np.diff(t)
    pos = dt[np.isfinite(dt) & (dt > 0)]
    limit = gap_factor * float(np.median(pos)) if pos.size else np.inf
    out[1:] = k[1:] & k[:-1] & (dt <= limit)
    return out


def broken_series(
    index: np.ndarray, cont: np.ndarray, *columns: np.ndarray
) -> tuple[np.ndarray, ...]:
    """The rows ``index`` of ``columns`` with a NaN row inserted at every break.

    Parameters
    ----------
    index : ndarray of int, shape (m,)
        Rows to draw (ascending; e.g. every k-th kept sample).
    cont : ndarray of bool, shape (n,)
        :func:`continuation` of the whole recording.
    *columns : ndarray, shape (n,)
        Values per sample (float).

    Returns
    -------
    tuple of ndarray, each shape (m + number of breaks,)
        Consecutive drawn rows ``a < b`` stay joined only when every sample in
        ``a+1 .. b`` continues its predecessor (nothing missing in between);
        otherwise a NaN separates them, so matplotlib does not draw a line there.
    """
    idx = np.asarray(index, dtype=int)
    seg = np.cumsum(~np.asarray(cont, dtype=bool))  # segment id of every sample
    breaks = np.flatnonzero(seg[idx[1:]] != seg[idx[:-1]]) + 1
    return tuple(np.insert(np.asarray(c, dtype=float)[idx], breaks, np.nan) for c in columns)


@dataclass(frozen=True)
class Fig6Data:
    """What a Fig-6 panel row draws, lines already broken (NaN) at every gap.

    Attributes
    ----------
    time_s, v : ndarray, shape (m,)
        Time (s) and model input (input unit) of the model curves; NaN at breaks.
    models : dict
        predictions.csv column (``gpi_deg`` ...) -> model output (deg), shape (m,).
    meas_time_s, meas_v, theta_deg : ndarray, shape (k,)
        The measured samples (deg, dataset convention); NaN at breaks.
    errors : dict
        Column -> model minus measured (deg), shape (k,), on the measured samples.
    holdout_spans, other_spans : list of (float, float)
        Time intervals (s) of held-out samples and of the other direction's samples.
    counts : dict
        ``fit``, ``holdout`` (own samples with a measured angle), ``not_measured``
        (own samples without one), ``other`` (samples of the other direction).
    bands : dict
        Model column -> its 1-sigma confidence band (deg, parameter covariance), shape (m,), for every model
        whose ``<model>_sd_deg`` column (:func:`band_column`) predictions.csv carries.
    """

    time_s: np.ndarray
    v: np.ndarray
    models: dict[str, np.ndarray]
    meas_time_s: np.ndarray
    meas_v: np.ndarray
    theta_deg: np.ndarray
    errors: dict[str, np.ndarray]
    holdout_spans: list[tuple[float, float]]
    other_spans: list[tuple[float, float]]
    counts: dict[str, int]
    bands: dict[str, np.ndarray] = field(default_factory=dict)


def fig6_data(
    pred: pd.DataFrame, max_points: int = 20000, gap_factor: float = GAP_FACTOR
) -> Fig6Data:
    """The curves of a Fig-6 panel row from one dataset's predictions.csv rows.

    Only the dataset's own samples (``split`` != ``other``) are drawn. Model curves are
    broken wherever the recording has no own sample (the other direction's stretches,
    time gaps longer than ``gap_factor`` x the median step); the measured samples and
    the errors are broken also at own samples without a measured angle. Series longer
    than ``max_points`` are thinned by a fixed step, keeping the breaks.

    Parameters
    ----------
    pred : DataFrame
        Rows of one dataset: ``time_s`` (s), ``v`` (input unit), ``theta_deg`` (deg,
        NaN when not measured), model columns (deg), ``split`` (fit|holdout|other).
    max_points : int
        Longest series drawn.
    gap_factor : float
        See :func:`continuation`.
    """
    p = pred.sort_values("time_s", kind="stable")
    t = p["time_s"].to_numpy(dtype=float)
    v = p["v"].to_numpy(dtype=float)
    theta = p["theta_deg"].to_numpy(dtype=float)
    split = p["split"].astype(str).to_numpy()
    own = split != "other"
    measured = own & np.isfinite(theta)
    cont = continuation(t, own, gap_factor)
    cont_m = continuation(t, measured, gap_factor)
    models = _model_columns(p[own])
    step = thinning_step(int(own.sum()), max_points)
    cols = [p[c].to_numpy(dtype=float) for c, _, _ in models]
    banded = [c for c, _, _ in models if band_column(c) in p]
    sds = [p[band_column(c)].to_numpy(dtype=float) for c in banded]
    time_s, vv, *ys = broken_series(np.flatnonzero(own)[::step], cont, t, v, *cols, *sds)
    ys, band_ys = ys[: len(cols)], ys[len(cols) :]
    mt, mv, mth, *ms = broken_series(np.flatnonzero(measured)[::step], cont_m, t, v, theta, *cols)
    return Fig6Data(
        time_s=time_s,
        v=vv,
        models={c: y for (c, _, _), y in zip(models, ys, strict=True)},
        meas_time_s=mt,
        meas_v=mv,
        theta_deg=mth,
        errors={c: y - mth for (c, _, _), y in zip(models, ms, strict=True)},
        holdout_spans=holdout_spans(t, split == "holdout"),
        other_spans=holdout_spans(t, ~own),
        counts={
            "fit": int((measured & (split == "fit")).sum()),
            "holdout": int((measured & (split == "holdout")).sum()),
            "not_measured": int((own & ~measured).sum()),
            "other": int((~own).sum()),
        },
        bands=dict(zip(banded, band_ys, strict=True)),
    )


def band_column(model_column: str) -> str:
    """predictions.csv column of a model's 1-sigma confidence band: ``egpi_deg`` ->
    ``egpi_sd_deg`` (deg; :meth:`i2ris_calib.fitting.result.FitResult.eval_uncertainty`)."""
    return model_column.removesuffix("_deg") + "_sd_deg"


def fig6_labels(axis: str, direction: str) -> tuple[str, str]:
    """(input label, angle label) of a dataset's panels in its sign convention."""
    if direction == "-":
        return "input max(−enc, 0) (counts)", f"−{axis} angle (deg) = |angle|"
    if direction == "+":
        return "input max(enc, 0) (counts)", f"{axis} angle (deg)"
    return "encoder input (counts)", f"{axis} angle (deg)"


def fit_figure_png(
    pred: pd.DataFrame,
    title: str,
    axis: str,
    direction: str,
    dpi: int = 100,
    max_points: int = 20000,
) -> bytes:
    """Fig-6-like panel row for one dataset: angle vs input, angle vs time, error vs time.

    Parameters
    ----------
    pred : DataFrame
        This dataset's rows of predictions.csv (see :func:`fig6_data`).
    title : str
        Figure title (dataset name).
    axis : str
        ``"yaw"`` or ``"pitch"``, used in axis labels.
    direction : str
        ``"+"``, ``"-"`` (input ``max(-enc, 0)``, angle ``-theta``) or ``"±"``.
    dpi, max_points : int
        PNG resolution; longest series drawn (thinned by a fixed step).

    Returns
    -------
    bytes
        PNG image, 12 x 3.6 in. Only the dataset's own samples are drawn and no line
        crosses a gap (:func:`fig6_data`); held-out cycles are shaded yellow, the other
        direction's stretches grey.
    """
    data = fig6_data(pred, max_points)
    input_label, angle_label = fig6_labels(axis, direction)
    fig = _new_figure(12, 3.6)
    ax_v, ax_t, ax_e = fig.subplots(1, 3)
    ax_v.plot(data.meas_v, data.theta_deg, ".", ms=3, color=MEASURED_COLOR, label="measured")
    ax_t.plot(data.meas_time_s, data.theta_deg, ".", ms=3, color=MEASURED_COLOR, label="measured")
    labels = {c: (lab, color) for c, lab, color in MODEL_CURVES}
    for col, y in data.models.items():
        label, color = labels[col]
        ax_v.plot(data.v, y, "-", lw=1, color=color, label=label)
        ax_t.plot(data.time_s, y, "-", lw=1, color=color, label=label)
        if col in data.bands:
            conf = data.bands[col]
            err = np.asarray(data.errors[col], dtype=float)
            noise = float(np.sqrt(np.nanmean(err**2))) if np.isfinite(err).any() else 0.0
            wide = BAND_SIGMA * np.sqrt(conf**2 + noise**2)  # noise plus parameters
            ax_t.fill_between(data.time_s, y - wide, y + wide, color=color, alpha=0.1, lw=0,
                              label=f"{label} ±{BAND_SIGMA:g} sd prediction")  # fmt: skip
            sd = BAND_SIGMA * conf
            ax_t.fill_between(data.time_s, y - sd, y + sd, color=color, alpha=0.3, lw=0,
                              label=f"{label} ±{BAND_SIGMA:g} sd confidence")  # fmt: skip
        ax_e.plot(
            data.meas_time_s,
            data.errors[col],
            "-",
            lw=0.8,
            color=color,
            label=f"{label} - measured",
        )
    for ax in (ax_t, ax_e):
        _shade(ax, data.holdout_spans, HOLDOUT_COLOR, 0.3, "held out")
        _shade(ax, data.other_spans, OTHER_COLOR, 0.25, "other direction")
    ax_e.axhline(0.0, color="0.2", lw=0.6)
    ax_v.set(xlabel=input_label, ylabel=angle_label, title="angle vs input")
    ax_t.set(xlabel="time (s, controller clock)", ylabel=angle_label, title="angle vs time")
    ax_e.set(xlabel="time (s, controller clock)", ylabel="model error (deg)", title="error vs time")
    if not data.models:
        ax_e.text(
            0.5, 0.5, "no model predictions", ha="center", va="center", transform=ax_e.transAxes
        )
    for ax in (ax_v, ax_t, ax_e):
        ax.grid(True, lw=0.4, alpha=0.5)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7, loc="best", markerscale=3)
    fig.suptitle(title)
    return figure_png(fig, dpi)


def detection_rate(time_s: np.ndarray, measured: np.ndarray, window_s: float) -> np.ndarray:
    """Fraction of measured frames in a centred window around each frame time.

    Parameters
    ----------
    time_s : ndarray, shape (n,)
        Frame times, sorted ascending (s).
    measured : ndarray of bool, shape (n,)
        True where the frame was measured.
    window_s : float
        Window width (s); frames in [t - w/2, t + w/2] count.

    Returns
    -------
    ndarray, shape (n,)
        Detection rate in [0, 1] per frame.
    """
    t = np.asarray(time_s, dtype=float)
    csum = np.r_[0, np.cumsum(np.asarray(measured, dtype=np.int64))]
    lo = np.searchsorted(t, t - window_s / 2, side="left")
    hi = np.searchsorted(t, t + window_s / 2, side="right")
    return (csum[hi] - csum[lo]) / np.maximum(hi - lo, 1)


STATUS_ORDER = ("measured", "not_found", "ambiguous", "rejected")
MEASURED_STATUS_COLOR = "#009E73"


def status_runs(time_s: np.ndarray, status: np.ndarray, kind: str) -> list[tuple[float, float]]:
    """(start, width) in s of each run of consecutive frames with ``status == kind``;
    a run covers its frames' times plus one median frame interval (so a single frame
    is visible)."""
    t = np.asarray(time_s, dtype=float)
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    spans = holdout_spans(t, np.asarray(status) == kind)
    return [(a - dt / 2, b - a + dt) for a, b in spans]


def tracking_figure_png(
    angles: pd.DataFrame, window_s: float = 1.0, dpi: int = 100, max_points: int = 20000
) -> bytes:
    """Tracking over time: per-frame status timeline, angles, reprojection error, roll.

    Parameters
    ----------
    angles : DataFrame
        track/angles.csv: ``time_s`` (camera clock, s), ``yaw_deg``, ``pitch_deg``,
        ``status``, optionally ``reproj_err_px`` (px) and ``roll_deg`` (deg).
    window_s : float
        Moving-window width for the measured share drawn over the timeline (s).

    Returns
    -------
    bytes
        PNG image, 10 x 6 in (7 in with roll), stacked panels sharing the time axis: one
        timeline row per status present (measured, not_found, ambiguous, rejected,
        others) with the measured share in a ``window_s`` window; yaw and pitch;
        reprojection error of measured frames; roll (twist) when present.
    """
    a = angles.sort_values("time_s", kind="stable")
    t_all = a["time_s"].to_numpy(dtype=float)
    status = a["status"].astype(str).to_numpy()
    measured = status == "measured"
    step = thinning_step(len(a), max_points)
    sl = slice(None, None, step)
    has_roll = "roll_deg" in a and np.isfinite(a["roll_deg"].to_numpy(dtype=float)).any()
    ratios = [1.0, 2.0, 1.0] + ([1.0] if has_roll else [])
    fig = _new_figure(10, 7 if has_roll else 6)
    axes = fig.subplots(len(ratios), 1, sharex=True, gridspec_kw={"height_ratios": ratios})
    ax_s, ax_a, ax_r = axes[:3]
    _plot_status_timeline(ax_s, t_all, status, window_s, sl)
    _plot_tracked_angles(ax_a, a, t_all, sl)
    _plot_reprojection_error(ax_r, a, t_all, measured, step)
    if has_roll:
        _plot_roll(axes[3], a, t_all, measured, sl)
    axes[-1].set_xlabel("time (s, camera clock)")
    for ax in axes[1:]:
        ax.grid(True, lw=0.4, alpha=0.5)
    ax_s.grid(True, axis="x", lw=0.4, alpha=0.5)
    if ax_a.get_legend_handles_labels()[0]:
        ax_a.legend(fontsize=8, loc="upper right")
    return figure_png(fig, dpi)


def _plot_status_timeline(
    ax_s, t_all: np.ndarray, status: np.ndarray, window_s: float, sl: slice
) -> None:
    """One timeline row per status present (frame counts at right) and, on a twin axis,
    the measured share (%) in a ``window_s`` (s) window at frames ``sl``.

    ``t_all`` (s) and ``status`` are per frame, shape (n,), sorted by time.
    """
    kinds = [k for k in STATUS_ORDER if (status == k).any()]
    kinds += sorted(set(status) - set(STATUS_ORDER))
    for row, kind in enumerate(kinds):
        n = int((status == kind).sum())
        color = MEASURED_STATUS_COLOR if kind == "measured" else STATUS_COLORS.get(kind, "0.3")
        ax_s.broken_barh(status_runs(t_all, status, kind), (row - 0.4, 0.8), color=color)
        ax_s.text(0.995, row, f"{n} ", transform=ax_s.get_yaxis_transform(), va="center",
                  ha="right", fontsize=7, color="0.1")  # fmt: skip
    ax_s.set_yticks(range(len(kinds)), kinds)
    ax_s.set_ylim(len(kinds) - 0.4, -0.6)
    rate = detection_rate(t_all, status == "measured", window_s)
    ax_share = ax_s.twinx()
    ax_share.plot(t_all[sl], 100 * rate[sl], lw=0.7, color="0.15")
    ax_share.set_ylim(-5, 105)
    ax_share.set_ylabel("measured (%)", fontsize=7)
    ax_share.tick_params(labelsize=7)
    ax_s.set_title(
        f"status of every frame (frame counts at right; line: measured share in a "
        f"{window_s:g} s window)"
    )


def _plot_tracked_angles(ax_a, a: pd.DataFrame, t_all: np.ndarray, sl: slice) -> None:
    """Yaw and pitch (deg) of the frames ``sl``; unmeasured frames leave gaps."""
    for col, color in (("yaw_deg", EGPI_COLOR), ("pitch_deg", GPI_COLOR)):
        if col in a:
            ax_a.plot(
                t_all[sl],
                a[col].to_numpy(dtype=float)[sl],
                lw=0.8,
                color=color,
                label=col.replace("_deg", ""),
            )
    ax_a.set(ylabel="angle (deg)", title="tracked angles (gaps = unmeasured frames)")


def _plot_roll(ax_o, a: pd.DataFrame, t_all: np.ndarray, measured: np.ndarray, sl: slice) -> None:
    """Roll (twist about the tool axis, deg) of the measured frames among ``sl``."""
    roll = a["roll_deg"].to_numpy(dtype=float)
    ax_o.plot(t_all[sl], np.where(measured, roll, np.nan)[sl], lw=0.7, color="0.3")
    ax_o.axhline(0.0, color="0.2", lw=0.5)
    ax_o.set(ylabel="roll (deg)", title="roll (twist about the tool axis, diagnostic)")


def _plot_reprojection_error(
    ax_r, a: pd.DataFrame, t_all: np.ndarray, measured: np.ndarray, step: int
) -> None:
    """Reprojection error (px) of every ``step``-th measured frame and its median."""
    err = (
        a["reproj_err_px"].to_numpy(dtype=float)
        if "reproj_err_px" in a
        else np.full(len(a), np.nan)
    )
    ok = measured & np.isfinite(err)
    idx = np.flatnonzero(ok)[::step]
    ax_r.plot(t_all[idx], err[idx], ".", ms=2, color="0.3")
    if ok.any():
        ax_r.axhline(float(np.median(err[ok])), color=EGPI_COLOR, lw=0.8, label="median")
        ax_r.legend(fontsize=8, loc="upper right")
    ax_r.set(ylabel="reprojection\nerror (px)", title="reprojection error of measured frames")


def synced_figure_png(synced: pd.DataFrame, dpi: int = 100, max_points: int = 20000) -> bytes:
    """Synced samples as raw hysteresis loops: angle vs encoder, one panel per axis.

    Parameters
    ----------
    synced : DataFrame
        sync/synced.csv: ``enc_yaw``, ``enc_pitch`` (counts), ``yaw_deg``, ``pitch_deg``.

    Returns
    -------
    bytes
        PNG image, 10 x 3.6 in. A wrong clock offset shows as a fattened loop.
    """
    step = thinning_step(len(synced), max_points)
    s = synced.iloc[::step]
    fig = _new_figure(10, 3.6)
    for ax, axis in zip(fig.subplots(1, 2), ("yaw", "pitch"), strict=True):
        ax.plot(
            s[f"enc_{axis}"].to_numpy(dtype=float),
            s[f"{axis}_deg"].to_numpy(dtype=float),
            ".",
            ms=2,
            color=MEASURED_COLOR,
        )
        ax.set(
            xlabel=f"enc_{axis} (counts)",
            ylabel=f"{axis} angle (deg)",
            title=f"{axis}: tracked angle vs encoder",
        )
        enc = synced[f"enc_{axis}"].to_numpy(dtype=float)
        if enc.size and np.nanmax(enc) - np.nanmin(enc) < 1:
            ax.text(0.5, 0.8, f"{axis} encoder did not move", ha="center", transform=ax.transAxes)
        ax.grid(True, lw=0.4, alpha=0.5)
    return figure_png(fig, dpi)


FLAG_STYLES = {
    "above_range": ("^", "#D55E00"),
    "below_range": ("v", "#D55E00"),
    "rate_limited": ("|", "#E69F00"),
    "output_step": ("D", "#CC79A7"),
    "spike_removed": ("s", "#009E73"),
    "within_delay": ("o", "0.5"),
}
"""Marker and colour of each compensation flag (COMMANDS.csv ``flags``; ``entry`` is shaded)."""


def axis_flags(flags: pd.Series, axis: str, two_axes: bool) -> list[set[str]]:
    """The flags of ``axis`` per row of COMMANDS.csv's ``flags`` column (``;``-joined;
    ``axis:flag`` when both axes were compensated; empty or NaN: none)."""
    out = []
    for cell in flags.astype(object).where(flags.notna(), "").astype(str):
        names = set()
        for f in filter(None, cell.split(";")):
            a, sep, name = f.partition(":")
            if not sep:
                names.add(f)
            elif a == axis or not two_axes:
                names.add(name)
        out.append(names)
    return out


def aligned_target(commands: pd.DataFrame, target: pd.DataFrame | None, axis: str) -> np.ndarray:
    """The target angle of ``axis`` on COMMANDS.csv's rows (NaN on the entry rows
    before the target's first sample): the target's rows are the commands' last rows."""
    out = np.full(len(commands), np.nan)
    col = f"{axis}_deg"
    if target is None or col not in target or len(target) > len(commands):
        return out
    out[len(commands) - len(target) :] = target[col].to_numpy(dtype=float)
    return out


def compensation_figure_png(
    commands: pd.DataFrame,
    target: pd.DataFrame | None,
    axes: list[str],
    axes_doc: dict | None = None,
    dpi: int = 100,
    max_points: int = 20000,
) -> bytes:
    """Feedforward compensation, one column per axis: target and predicted angle,
    their difference with every flagged sample marked, the motor command within the
    fitted input range, and the command's rate against the rate limit.

    Parameters
    ----------
    commands : DataFrame
        compensate/commands.csv: ``time_s`` (s), ``enc_<axis>`` (counts),
        ``predicted_<axis>_deg`` (deg), ``reachable`` (0/1), ``flags`` (optional).
        The entry ramp's rows (flag ``entry``) come before the target's first time.
    target : DataFrame or None
        The target (``time_s``, ``<axis>_deg``): the commands' last rows.
    axes : list of str
        Axes to draw (``"yaw"``, ``"pitch"``).
    axes_doc : mapping, optional
        compensate.json ``axes``: ``max_counts_per_s`` (the rate limit drawn; None: no
        limit), ``input_range_counts``, ``dataset`` (a ``-`` dataset's range is negated).

    Returns
    -------
    bytes
        PNG image, 6.5 in wide per axis x 8 in.
    """
    axes_doc = axes_doc or {}
    fig = _new_figure(max(6.5 * len(axes), 8.0), 8.0)
    grid = fig.subplots(4, len(axes), sharex=True, squeeze=False)
    step = thinning_step(len(commands), max_points)
    flags_col = commands["flags"] if "flags" in commands else pd.Series([""] * len(commands))
    for j, axis in enumerate(axes):
        doc = axes_doc.get(axis, {}) if isinstance(axes_doc.get(axis), dict) else {}
        flags = axis_flags(flags_col, axis, len(axes) > 1)
        _plot_compensation_column(grid[:, j], commands, target, axis, flags, step)
        _plot_command_limits(grid[2, j], grid[3, j], doc)
        _label_compensation_column(grid[:, j], axis, doc, commands["time_s"], flags)
    return figure_png(fig, dpi)


def _plot_compensation_column(
    col, commands: pd.DataFrame, target, axis: str, flags: list[set[str]], step: int
) -> None:
    """One axis of :func:`compensation_figure_png` (axes ``col``: angle, difference,
    command, rate): target and predicted angle (deg), their difference (deg), the command
    (counts) and its rate (counts/s), every ``step``-th sample; flagged samples marked."""
    ax_a, ax_e, ax_c, ax_r = col
    t_all = commands["time_s"].to_numpy(dtype=float)
    t = t_all[::step]
    pred_all = commands[f"predicted_{axis}_deg"].to_numpy(dtype=float)
    tgt_all = aligned_target(commands, target, axis)
    ax_a.plot(t, tgt_all[::step], "-", lw=2.0, color=MEASURED_COLOR, alpha=0.7, label="target")
    ax_a.plot(t, pred_all[::step], "-", lw=0.9, color=EGPI_COLOR, label="predicted (model)")
    err = pred_all - tgt_all
    ax_e.plot(t, err[::step], "-", lw=0.8, color="0.2")
    enc = commands[f"enc_{axis}"].to_numpy(dtype=float)
    ax_c.plot(t, enc[::step], "-", lw=0.9, color="0.1", label="command")
    dt = np.diff(t_all)
    step_rate = np.r_[0.0, np.abs(np.diff(enc)) / np.where(dt > 0, dt, np.nan)][: enc.size]
    ax_r.plot(t, step_rate[::step], "-", lw=0.8, color="0.2", label="|Δcommand| / Δt")
    for name, (marker, color) in FLAG_STYLES.items():
        on = np.flatnonzero([name in f for f in flags])[::step]
        if not on.size:
            continue
        label = f"{name} ({int(sum(name in f for f in flags))})"
        y = err if np.isfinite(err[on]).any() else pred_all
        ax_e.plot(t_all[on], y[on], marker, ms=4, color=color, label=label, ls="none")
        if name == "rate_limited":
            ax_r.plot(t_all[on], step_rate[on], marker, ms=4, color=color, label=label,
                      ls="none")  # fmt: skip


def _plot_command_limits(ax_c, ax_r, doc: dict) -> None:
    """The rate limit (counts/s) on ``ax_r`` (or "no rate limit") and the fitted input
    range (counts; negated for a ``-`` dataset) on ``ax_c``, from compensate.json."""
    limit = doc.get("max_counts_per_s")
    if limit is not None and np.isfinite(float(limit)):
        ax_r.axhline(float(limit), color="#D55E00", ls="--", lw=1.2,
                     label=f"rate limit {float(limit):.5g} counts/s")  # fmt: skip
    else:
        ax_r.text(0.5, 0.85, "no rate limit", ha="center", transform=ax_r.transAxes)
    rng = doc.get("input_range_counts")
    if isinstance(rng, list) and len(rng) == 2:
        sign = -1.0 if str(doc.get("dataset", "")).endswith("-") else 1.0
        for k, v in enumerate(sorted(sign * float(x) for x in rng)):
            ax_c.axhline(v, color="0.5", ls=":", lw=1.0,
                         label="fitted input range" if k == 0 else None)  # fmt: skip


def _label_compensation_column(col, axis: str, doc: dict, time_s, flags: list[set[str]]) -> None:
    """Entry-ramp and conditioning-sweep shading (over ``time_s``, s), grids, titles,
    labels and legends of one axis column of :func:`compensation_figure_png`."""
    ax_a, ax_e, ax_c, ax_r = col
    t_all = time_s.to_numpy(dtype=float)
    spans = holdout_spans(t_all, np.array(["entry" in f for f in flags]))
    sweep = holdout_spans(t_all, np.array(["conditioning" in f for f in flags]))
    for ax in col:
        _shade(ax, spans, OTHER_COLOR, 0.25, "entry ramp")
        _shade(ax, sweep, "0.6", 0.25, "conditioning sweep", hatch="//")
        ax.grid(True, lw=0.4, alpha=0.5)
    ax_e.axhline(0.0, color="0.2", lw=0.5)
    label = doc.get("dataset", axis)
    model = doc.get("model")
    ax_a.set_title(f"{label}: target and predicted" + (f" ({model})" if model else ""))
    ax_a.set_ylabel(f"{axis} angle (deg)")
    ax_e.set_ylabel("predicted − target (deg)")
    ax_e.set_title("difference; flagged samples marked")
    ax_c.set_ylabel(f"enc_{axis} (counts)")
    ax_c.set_title("motor command")
    ax_r.set_ylabel("command rate (counts/s)")
    ax_r.set_title("command rate and the rate limit")
    ax_r.set_xlabel("time (s)")
    for ax in col:
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="upper right", fontsize=7, ncol=2)


def before_after_png(
    before: bytes, after: bytes | None, titles: tuple[str, str], dpi: int = 100
) -> bytes:
    """Two residual figures of ``diagnose`` side by side (before: the starting model,
    after: the final one), or the one when nothing was added (``after`` None).

    Returns
    -------
    bytes
        PNG image, 13 x 4.8 in (7 x 5 in for one).
    """
    import matplotlib.image as mpimg

    pngs = [before] if after is None else [before, after]
    fig = _new_figure(7.0, 5.0) if after is None else _new_figure(13.0, 4.8)
    axs = fig.subplots(1, len(pngs), squeeze=False)[0]
    for ax, png, title in zip(axs, pngs, titles, strict=False):
        ax.imshow(mpimg.imread(io.BytesIO(png), format="png"), interpolation="antialiased")
        ax.set_title(title, fontsize=10)
        ax.set_axis_off()
    return figure_png(fig, dpi)


CAMERA_MARKERS = {"top": ("o", EGPI_COLOR), "side": ("s", GPI_COLOR)}
OTHER_CLOCK_STYLES = {"event alone": ("--", "#E69F00"), "model alone": (":", DIAGNOSED_COLOR)}


def clock_figure_png(view, dpi: int = 100) -> bytes:
    """The clock and its evidence: offset line with its stated band, residuals of the
    flash edges and of the clocks each method gave alone, the model's offset profile.

    Parameters
    ----------
    view : ClockView
        :func:`i2ris_calib.report.clock.clock_view` of sync.json.

    Returns
    -------
    bytes
        PNG image, 11 x 5.6 in. Left top: offset ``t_ctrl - t_cam`` minus its value at
        ``t_ref`` (ms) vs camera time, with +-1 and +-2 sd bands. Left bottom: the same
        relative to the stated clock (residual, ms): flash edges with +-1 sd error bars,
        the event's and the model's clocks alone. Right (model methods): residual sum of
        squares of the offset profile vs offset at ``t_ref`` (ms from the stated clock).
    """
    t0, t1 = view.t_range_s
    pad = 0.02 * (t1 - t0) if t1 > t0 else 1.0
    t = np.linspace(t0 - pad, t1 + pad, 200)
    fig = _new_figure(11, 5.6)
    ax_l, ax_r, ax_p = _clock_axes(fig, view.profile is not None)
    _plot_clock_lines(ax_l, ax_r, view, t)
    _plot_flash_edges(ax_l, ax_r, view)
    _label_clock_axes(ax_l, ax_r, view.clock, (t0 - pad, t1 + pad))
    if ax_p is not None:
        _plot_offset_profile(ax_p, view)
    return figure_png(fig, dpi)


def _clock_axes(fig, with_profile: bool) -> tuple:
    """Axes of :func:`clock_figure_png`: (offset line, residuals, offset profile or None);
    the profile takes a right-hand column when ``with_profile``."""
    if with_profile:
        grid = fig.add_gridspec(2, 2, width_ratios=(3, 1))
        ax_l, ax_r = fig.add_subplot(grid[0, 0]), fig.add_subplot(grid[1, 0])
        return ax_l, ax_r, fig.add_subplot(grid[:, 1])
    ax_l, ax_r = fig.subplots(2, 1, sharex=True)
    return ax_l, ax_r, None


def _plot_clock_lines(ax_l, ax_r, view, t: np.ndarray) -> None:
    """The stated clock with its +-1/+-2 sd bands and the other methods' clocks at camera
    times ``t`` (s): offset relative to ``t_ref`` on ``ax_l``, residual on ``ax_r`` (ms)."""
    c = view.clock
    ms = 1e3
    sd = c.sd(t) * ms
    line = (c.offset(t) - c.offset_ref_s) * ms
    for ax, centre in ((ax_l, line), (ax_r, np.zeros_like(t))):
        if np.isfinite(sd).any():
            ax.fill_between(t, centre - 2 * sd, centre + 2 * sd, color=EGPI_COLOR, alpha=0.12,
                            lw=0, label="stated ±2 sd")  # fmt: skip
            ax.fill_between(t, centre - sd, centre + sd, color=EGPI_COLOR, alpha=0.25, lw=0,
                            label="stated ±1 sd")  # fmt: skip
        ax.plot(t, centre, "-", color=EGPI_COLOR, lw=1.2, label=f"clock ({view.method})")
    for other in view.others:
        style, color = OTHER_CLOCK_STYLES.get(other.label, ("-.", "0.3"))
        o = other.offset(t) * ms
        ax_l.plot(t, o - c.offset_ref_s * ms, style, color=color, lw=1.1, label=other.label)
        ax_r.plot(t, o - c.offset(t) * ms, style, color=color, lw=1.1, label=other.label)


def _plot_flash_edges(ax_l, ax_r, view) -> None:
    """Flash edges of each camera with +-1 sd error bars (ms): on the offset line
    (``ax_l``) and as residuals from the stated clock (``ax_r``)."""
    c = view.clock
    ms = 1e3
    for cam in sorted({e.camera for e in view.edges}):
        marker, color = CAMERA_MARKERS.get(cam, ("^", "0.3"))
        es = [e for e in view.edges if e.camera == cam]
        te = np.array([e.t_cam_s for e in es])
        r = np.array([e.residual_s for e in es]) * ms
        s = np.array([e.sd_s for e in es]) * ms
        base = (c.offset(te) - c.offset_ref_s) * ms
        kw = dict(fmt=marker, ms=4, color=color, ecolor=color, elinewidth=0.8, capsize=2)
        ax_l.errorbar(te, base + r, yerr=s, label=f"flash edges ({cam})", **kw)
        ax_r.errorbar(te, r, yerr=s, label=f"flash edges ({cam})", **kw)


def _label_clock_axes(ax_l, ax_r, c, xlim: tuple[float, float]) -> None:
    """Titles, labels, grid, camera-time limits ``xlim`` (s) and legend of the offset
    line and residual axes of clock ``c``."""
    ax_l.set(
        ylabel="offset − offset at t_ref (ms)",
        title=f"clock line: t_ctrl − t_cam relative to {c.offset_ref_s:.6f} s at "
        f"t_cam = {c.t_ref_s:.3g} s (slope = drift)",
    )
    ax_r.set(
        xlabel="camera time (s)",
        ylabel="residual from the clock (ms)",
        title="residuals: flash edges and the clocks each method gave alone",
    )
    ax_r.axhline(0.0, color="0.2", lw=0.5)
    for ax in (ax_l, ax_r):
        ax.grid(True, lw=0.4, alpha=0.5)
        ax.set_xlim(*xlim)
    ax_l.legend(fontsize=7, loc="best", ncol=2)


def _plot_offset_profile(ax_p, view) -> None:
    """The model method's residual sum of squares (deg^2) vs offset at ``t_ref`` less
    the stated one (ms), with the stated +-1 sd."""
    c = view.clock
    ms = 1e3
    x, y = view.profile
    order = np.argsort(x)
    dx = (x[order] - c.offset_ref_s) * ms
    ax_p.plot(dx, y[order], "o-", ms=3, lw=0.9, color=DIAGNOSED_COLOR)
    if np.isfinite(c.offset_ref_sd_s):
        s_ref = c.offset_ref_sd_s * ms
        ax_p.axvspan(-s_ref, s_ref, color=EGPI_COLOR, alpha=0.25, lw=0, label="stated ±1 sd")
    ax_p.axvline(0.0, color=EGPI_COLOR, lw=1.0)
    ax_p.set(
        xlabel="offset at t_ref − stated (ms)",
        ylabel="model residual sum of squares (deg²)",
        title="model method: offset profile",
    )
    ax_p.grid(True, lw=0.4, alpha=0.5)
    ax_p.legend(fontsize=7, loc="upper center")
