"""Report figures as PNG bytes, from in-memory frames.

matplotlib is imported inside the functions (Agg canvas, no pyplot state), so
importing this module is cheap. Figure sizes (inches) and DPI are fixed, and no
timestamp is written into the PNG, so the same data give the same bytes.
"""

from __future__ import annotations

import io

import numpy as np
import pandas as pd

MEASURED_COLOR = "0.45"
GPI_COLOR = "#D55E00"  # vermillion (Okabe-Ito, colour-blind safe)
EGPI_COLOR = "#0072B2"  # blue
DIAGNOSED_COLOR = "#009E73"  # bluish green
HOLDOUT_COLOR = "#F0E442"
STATUS_COLORS = {"not_found": "#E69F00", "ambiguous": "#CC79A7", "rejected": "#D55E00"}


def _new_figure(width_in: float, height_in: float):
    """A matplotlib Figure on an Agg canvas (no global pyplot state)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

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


def _shade_holdout(ax, spans: list[tuple[float, float]]) -> None:
    for i, (a, b) in enumerate(spans):
        ax.axvspan(a, b, color=HOLDOUT_COLOR, alpha=0.3, lw=0, label="held out" if i == 0 else None)


def _model_columns(pred: pd.DataFrame) -> list[tuple[str, str, str]]:
    """(column, label, colour) for each model column present with finite values."""
    out = []
    for col, label, color in (
        ("gpi_deg", "GPI", GPI_COLOR),
        ("egpi_deg", "EGPI", EGPI_COLOR),
        ("diagnosed_deg", "EGPI + effects", DIAGNOSED_COLOR),
    ):
        if col in pred and np.isfinite(pred[col].to_numpy(dtype=float)).any():
            out.append((col, label, color))
    return out


def fit_figure_png(
    pred: pd.DataFrame,
    title: str,
    axis: str,
    abs_fitted: bool,
    dpi: int = 100,
    max_points: int = 20000,
) -> bytes:
    """Fig-6-like panel row for one dataset: angle vs input, angle vs time, error vs time.

    Parameters
    ----------
    pred : DataFrame
        This dataset's rows of predictions.csv: ``time_s`` (s), ``v`` (counts),
        ``theta_deg`` (measured, deg), ``gpi_deg`` / ``egpi_deg`` (model, deg; either
        may be absent or NaN), ``split`` (fit|holdout).
    title : str
        Figure title (dataset name).
    axis : str
        ``"yaw"`` or ``"pitch"``, used in axis labels.
    abs_fitted : bool
        True when the dataset was fitted as |input| -> |angle| (paper's negative sets).
    dpi, max_points : int
        PNG resolution; longest series drawn (thinned by a fixed step).

    Returns
    -------
    bytes
        PNG image, 12 x 3.6 in.
    """
    pred = pred.sort_values("time_s", kind="stable")
    step = thinning_step(len(pred), max_points)
    p = pred.iloc[::step]
    t = p["time_s"].to_numpy(dtype=float)
    v = p["v"].to_numpy(dtype=float)
    theta = p["theta_deg"].to_numpy(dtype=float)
    spans = holdout_spans(
        pred["time_s"].to_numpy(dtype=float), (pred["split"] == "holdout").to_numpy()
    )
    bars = "|" if abs_fitted else ""
    angle_label = f"{bars}{axis} angle{bars} (deg)"
    fig = _new_figure(12, 3.6)
    ax_v, ax_t, ax_e = fig.subplots(1, 3)
    ax_v.plot(v, theta, ".", ms=3, color=MEASURED_COLOR, label="measured")
    ax_t.plot(t, theta, ".", ms=3, color=MEASURED_COLOR, label="measured")
    models = _model_columns(p)
    for col, label, color in models:
        y = p[col].to_numpy(dtype=float)
        ax_v.plot(v, y, "-", lw=1, color=color, label=label)
        ax_t.plot(t, y, "-", lw=1, color=color, label=label)
        ax_e.plot(t, y - theta, "-", lw=0.8, color=color, label=f"{label} - measured")
    _shade_holdout(ax_t, spans)
    _shade_holdout(ax_e, spans)
    ax_e.axhline(0.0, color="0.2", lw=0.6)
    ax_v.set(
        xlabel=f"{bars}encoder input{bars} (counts)", ylabel=angle_label, title="angle vs input"
    )
    ax_t.set(xlabel="time (s, controller clock)", ylabel=angle_label, title="angle vs time")
    ax_e.set(xlabel="time (s, controller clock)", ylabel="model error (deg)", title="error vs time")
    if not models:
        ax_e.text(
            0.5, 0.5, "no model predictions", ha="center", va="center", transform=ax_e.transAxes
        )
    for ax in (ax_v, ax_t, ax_e):
        ax.grid(True, lw=0.4, alpha=0.5)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8, loc="best", markerscale=3)
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


def tracking_figure_png(
    angles: pd.DataFrame, window_s: float = 1.0, dpi: int = 100, max_points: int = 20000
) -> bytes:
    """Tracking quality over time: angles, detection rate, reprojection error, flagged frames.

    Parameters
    ----------
    angles : DataFrame
        track/angles.csv: ``time_s`` (camera clock, s), ``yaw_deg``, ``pitch_deg``,
        ``status``, ``reproj_err_px`` (px).
    window_s : float
        Moving-window width for the detection rate (s).

    Returns
    -------
    bytes
        PNG image, 10 x 8 in, four stacked panels sharing the time axis.
    """
    a = angles.sort_values("time_s", kind="stable")
    t_all = a["time_s"].to_numpy(dtype=float)
    status = a["status"].astype(str).to_numpy()
    measured = status == "measured"
    rate = detection_rate(t_all, measured, window_s)
    step = thinning_step(len(a), max_points)
    sl = slice(None, None, step)
    fig = _new_figure(10, 8)
    ax_a, ax_d, ax_r, ax_f = fig.subplots(4, 1, sharex=True)
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
    ax_d.plot(t_all[sl], 100 * rate[sl], lw=0.8, color="0.2")
    ax_d.set(
        ylabel="detected (%)", ylim=(-5, 105), title=f"detection rate, {window_s:g} s moving window"
    )
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
    _flagged_raster(ax_f, t_all, status)
    ax_f.set(xlabel="time (s, camera clock)", title="flagged frames by status")
    for ax in (ax_a, ax_d, ax_r, ax_f):
        ax.grid(True, lw=0.4, alpha=0.5)
    if ax_a.get_legend_handles_labels()[0]:
        ax_a.legend(fontsize=8, loc="upper right")
    return figure_png(fig, dpi)


def _flagged_raster(ax, t: np.ndarray, status: np.ndarray) -> None:
    """One row of tick marks per non-measured status."""
    kinds = [s for s in ("not_found", "ambiguous", "rejected") if (status == s).any()]
    kinds += sorted({s for s in status if s != "measured"} - set(kinds))
    if not kinds:
        ax.text(0.5, 0.5, "no flagged frames", ha="center", va="center", transform=ax.transAxes)
        ax.set_yticks([])
        return
    for row, kind in enumerate(kinds):
        ax.eventplot(
            t[status == kind],
            lineoffsets=row,
            linelengths=0.8,
            linewidths=0.8,
            colors=STATUS_COLORS.get(kind, "0.3"),
        )
    ax.set_yticks(range(len(kinds)), kinds)
    ax.set_ylim(-0.6, len(kinds) - 0.4)


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
