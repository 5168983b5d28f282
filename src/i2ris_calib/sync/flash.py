"""LED flash edges seen by a camera, with sub-frame times.

The flash brightens the whole frame, so the mean grey level of a view jumps. Dark and
bright levels come from two-means clustering; a frame whose exposure straddles the LED
edge is partly lit, and its lit fraction places the edge inside the exposure
(sub-frame timing, exact likelihood in :mod:`i2ris_calib.sync.edgetime`). An edge that
falls between two exposures (short exposure, or a dropped frame) is only known to lie
in that gap. When the exposure is not configured it is marginalised over
:data:`EXPOSURE_FRACTIONS` of the frame interval, weighted by each one's evidence.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.stats import theilslopes

from i2ris_calib.sync.config import SyncConfig
from i2ris_calib.sync.edgetime import TIME_FLOOR_S, edge_moments, sse_pieces

LEVEL_FRAMES = 8  # steady frames each side of an edge used for the dark/bright levels
#: exposures tried when ``sync.exposure_s = 0`` (unknown), as fractions of the frame interval
EXPOSURE_FRACTIONS = np.array([0.03, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0])


@dataclass(frozen=True)
class CameraEdge:
    """One LED edge seen by one camera (camera clock).

    Attributes
    ----------
    t_s : float
        Edge time (posterior mean given the frames), camera clock, s.
    sd_s : float
        Standard deviation of ``t_s``, s.
    rising : bool
        True for LED on, False for LED off.
    camera : str
        Camera name.
    frames_t_s : ndarray, shape (k,)
        Timestamps of the frames around the edge, s.
    frac : ndarray, shape (k,)
        Observed lit fraction of each of those frames.
    frac_sd : float
        Standard deviation of ``frac``.
    exposures_s : tuple of float
        Candidate exposure times (one when configured, :data:`EXPOSURE_FRACTIONS` of the
        frame interval when not), s.
    ref : str
        Where a timestamp lies in its exposure: ``start``, ``middle``, ``end``.
    """

    t_s: float
    sd_s: float
    rising: bool
    camera: str
    frames_t_s: np.ndarray
    frac: np.ndarray
    frac_sd: float
    exposures_s: tuple[float, ...]
    ref: str = "middle"


def two_level_split(g: np.ndarray, iters: int = 20) -> tuple[float, float]:
    """Dark and bright grey levels of ``g`` by 1-D two-means clustering (medians)."""
    lo, hi = float(np.min(g)), float(np.max(g))
    for _ in range(iters):
        thr = 0.5 * (lo + hi)
        dark, bright = g[g <= thr], g[g > thr]
        if dark.size == 0 or bright.size == 0:
            break
        new = float(np.median(dark)), float(np.median(bright))
        if new == (lo, hi):
            break
        lo, hi = new
    return lo, hi


def lit_fraction(
    t_edge: np.ndarray, start: np.ndarray, end: np.ndarray, rising: bool
) -> np.ndarray:
    """Fraction of each exposure ``[start, end]`` with the LED on, for edge times ``t_edge``.

    Parameters
    ----------
    t_edge : ndarray, shape (m,)
        Candidate edge times, s.
    start, end : ndarray, shape (k,)
        Exposure windows, s.
    rising : bool
        LED goes on at the edge (True) or off (False).

    Returns
    -------
    ndarray, shape (m, k)
    """
    e = end - start
    te = np.asarray(t_edge, dtype=float)[:, None]
    frac = (end - te) / e if rising else (te - start) / e
    return np.clip(frac, 0.0, 1.0)


def exposure_candidates(exposure_s: float, interval_s: float) -> tuple[float, ...]:
    """Exposure times to consider: the configured one, or (0 = unknown) a grid of
    :data:`EXPOSURE_FRACTIONS` of the frame interval ``interval_s``."""
    if exposure_s > 0:
        return (float(exposure_s),)
    return tuple(float(x) for x in EXPOSURE_FRACTIONS * interval_s)


def subframe_edge_time(
    t_s: np.ndarray,
    frac: np.ndarray,
    frac_sd: float,
    exposure_s: float | tuple[float, ...],
    ref: str,
    rising: bool,
    level_frames: int = 0,
) -> tuple[float, float]:
    """Edge time (s) and its standard deviation from frames around one edge.

    Posterior mean and standard deviation of the edge time ``u`` under a flat prior
    and the exact likelihood ``exp(-sse(u)/2)`` of the observed lit fractions
    (:mod:`i2ris_calib.sync.edgetime`). A partly lit frame places the edge inside its
    exposure to the noise level; when no frame is partly lit (an edge between two
    exposures, or inside a dropped frame) the likelihood is flat over the gap and the
    standard deviation is that of a uniform distribution over it (gap / sqrt(12)).
    Several candidate exposures are averaged with weights given by their evidence.

    Parameters
    ----------
    t_s : ndarray, shape (k,)
        Timestamps of the frames around the edge (camera clock), s.
    frac : ndarray, shape (k,)
        Observed lit fraction of each frame: (grey - dark) / (bright - dark).
    frac_sd : float
        Standard deviation of ``frac`` (grey-level noise / contrast).
    exposure_s : float or tuple of float
        Exposure time, s, or candidate exposure times (equal prior weight).
    ref, rising
        See :func:`i2ris_calib.sync.edgetime.exposure_windows` and :func:`lit_fraction`.
    level_frames : int
        Frames behind each of the dark/bright levels (medians); their error is added
        to ``frac_sd`` (0 = levels known exactly).
    """
    sd = frac_sd * np.sqrt(1.0 + (np.pi / 2 / level_frames if level_frames else 0.0))
    exposures = np.atleast_1d(np.asarray(exposure_s, dtype=float))
    moments = np.array([edge_moments(sse_pieces(t_s, frac, sd, e, ref, rising)) for e in exposures])
    w = np.exp(moments[:, 0] - moments[:, 0].max())
    return mixture_time(moments, w / w.sum())


def mixture_time(moments: np.ndarray, weights: np.ndarray) -> tuple[float, float]:
    """Mean and sd (floored at TIME_FLOOR_S) of an edge time averaged over exposures.

    ``moments`` (E, 3): log evidence, mean, variance per exposure; ``weights`` (E,).
    """
    mean = float(weights @ moments[:, 1])
    var = float(weights @ (moments[:, 2] + (moments[:, 1] - mean) ** 2))
    return mean, float(np.sqrt(var + TIME_FLOOR_S**2))


def edge_given_exposure(edge: CameraEdge, weights: np.ndarray) -> CameraEdge:
    """``edge`` with its time and sd recomputed for exposure probabilities ``weights``
    (the clock posterior's, which pools every edge) instead of its own evidence."""
    if len(edge.exposures_s) < 2:
        return edge
    moments = np.array(
        [
            edge_moments(
                sse_pieces(edge.frames_t_s, edge.frac, edge.frac_sd, e, edge.ref, edge.rising)
            )
            for e in edge.exposures_s
        ]
    )
    t, sd = mixture_time(moments, weights)
    return replace(edge, t_s=t, sd_s=sd)


def camera_edges(
    t_s: np.ndarray, gray: np.ndarray, camera: str, cfg: SyncConfig
) -> list[CameraEdge]:
    """LED edges seen by one camera, with sub-frame times.

    Parameters
    ----------
    t_s : ndarray, shape (n,)
        Frame timestamps, camera clock, s.
    gray : ndarray, shape (n,)
        Mean grey level of each frame (0-255); NaN rows are ignored.
    camera : str
        Camera name (recorded in the edges).
    cfg : SyncConfig
        ``flash_min_contrast_gray``, ``exposure_s`` (0 = unknown), ``frame_time_ref``,
        ``use_falling_edges``.

    Returns
    -------
    list of CameraEdge
        Empty when the grey level never jumps by ``flash_min_contrast_gray``.
    """
    t, g = _finite_sorted(t_s, gray)
    if t.size < 4:
        return []
    dark, bright = two_level_split(g)
    if bright - dark < cfg.flash_min_contrast_gray:
        return []
    on = g > 0.5 * (dark + bright)
    interval = float(np.median(np.diff(t)))
    exposures = exposure_candidates(cfg.exposure_s, interval)
    change = np.flatnonzero(on[1:] != on[:-1]) + 1  # first frame of each new run
    bounds = np.concatenate([[0], change, [t.size]])
    found = [
        _edge_levels(t, g, bounds, i, bool(on[k]), (dark, bright))
        for i, k in enumerate(change)
        if on[k] or cfg.use_falling_edges
    ]
    noise = level_noise_sd(t, g, bounds, change)
    edges = [_timed_edge(t, g, levels, noise, exposures, camera, cfg) for levels in found]
    return [e for e in edges if e is not None]


def _finite_sorted(t_s: np.ndarray, gray: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Frames with finite time and grey level, in time order.

    Returns
    -------
    t, g : ndarray, shape (m,)
        Camera-clock times (s) and mean grey levels (0-255), ``m <= n``.
    """
    ok = np.isfinite(t_s) & np.isfinite(gray)
    t, g = np.asarray(t_s, float)[ok], np.asarray(gray, float)[ok]
    order = np.argsort(t)
    return t[order], g[order]


def _edge_levels(
    t: np.ndarray,
    g: np.ndarray,
    bounds: np.ndarray,
    i: int,
    rising: bool,
    dark_bright: tuple[float, float],
) -> tuple[bool, np.ndarray, np.ndarray, np.ndarray, float]:
    """Frames near edge ``i`` and the grey levels before and after it at those frames.

    Parameters
    ----------
    t, g : ndarray, shape (m,)
        Frame times (camera clock, s) and grey levels, time-ordered.
    bounds : ndarray, shape (n_edges + 2,)
        First frame of each lit/dark run, then ``m``; edge ``i`` starts run ``i + 1``.
    i : int
        Edge index.
    rising : bool
        LED switched on at this edge.
    dark_bright : tuple of float
        Recording-wide dark and bright levels, used when a run has no steady frame.

    Returns
    -------
    rising : bool
        As given.
    idx : ndarray of int, shape (k,)
        Frames near the edge (up to 3 each side), not straddling a neighbouring edge.
    lvl_before, lvl_after : ndarray, shape (k,)
        Level of the run before and after the edge at each of those frames (grey).
    var : float
        Larger variance of the two levels, in units of the per-frame noise variance.
    """
    dark, bright = dark_bright
    k = bounds[i + 1]
    before = np.arange(bounds[i], k)  # run before the edge
    after = np.arange(k, bounds[i + 2])  # run after the edge
    # steady frames: drop run ends that may straddle an edge
    win_before = before[(1 if i > 0 else 0) : -1][-LEVEL_FRAMES:]
    win_after = after[1 : (-1 if i + 2 < bounds.size - 1 else None)][:LEVEL_FRAMES]
    # frames near the edge, excluding frames that may straddle the neighbouring edges
    lo_b = bounds[i] + (1 if i > 0 else 0)
    hi_b = bounds[i + 2] - (1 if i + 2 < bounds.size - 1 else 0)
    idx = np.arange(max(k - 3, lo_b), min(k + 3, hi_b))
    # levels at each of those frames: the scene's grey level drifts while the tip moves
    lvl_before, var_b = _level(t, g, win_before, t[idx], dark if rising else bright)
    lvl_after, var_a = _level(t, g, win_after, t[idx], bright if rising else dark)
    return rising, idx, lvl_before, lvl_after, max(var_b, var_a)


def _timed_edge(
    t: np.ndarray,
    g: np.ndarray,
    levels: tuple[bool, np.ndarray, np.ndarray, np.ndarray, float],
    noise: float,
    exposures: tuple[float, ...],
    camera: str,
    cfg: SyncConfig,
) -> CameraEdge | None:
    """The edge with its sub-frame time from the lit fractions of the frames near it.

    ``levels`` is what :func:`_edge_levels` returns; ``noise`` the per-frame grey
    noise sd; ``exposures`` the exposure candidates (s). None when the contrast at
    some frame is below ``cfg.flash_min_contrast_gray``.
    """
    rising, idx, lvl_before, lvl_after, var = levels
    lo_lvl, hi_lvl = (lvl_before, lvl_after) if rising else (lvl_after, lvl_before)
    contrast = float(np.min(hi_lvl - lo_lvl))
    if contrast < cfg.flash_min_contrast_gray:
        return None
    frac = (g[idx] - lo_lvl) / (hi_lvl - lo_lvl)
    frac_sd = noise / contrast * np.sqrt(1.0 + var)
    te, sd = subframe_edge_time(t[idx], frac, frac_sd, exposures, cfg.frame_time_ref, rising)
    return CameraEdge(
        te,
        sd,
        rising,
        camera,
        frames_t_s=t[idx],
        frac=frac,
        frac_sd=float(frac_sd),
        exposures_s=exposures,
        ref=cfg.frame_time_ref,
    )


def level_noise_sd(t: np.ndarray, g: np.ndarray, bounds: np.ndarray, change: np.ndarray) -> float:
    """Grey-level noise sd of single frames about the local level, from the steady runs.

    Each run between LED edges (its end frames, which may straddle an edge, left out)
    is cut into pieces of :data:`LEVEL_FRAMES` frames and a straight line fitted to
    each; the pooled residual sd (degrees of freedom: frames less 2 per piece) is the
    scatter the lit fractions see about the level lines of :func:`_level`. The
    recording-wide :func:`gray_noise_sd` (second differences) is used when fewer than
    10 degrees of freedom remain. Second differences overstate this scatter when the
    frames alternate (a video codec's alternating frame types: +-0.03 grey about the
    trend gives second differences of 0.12, measured on rendered mp4 sessions) and
    would overstate every partly lit frame's timing sd by the same factor.
    """
    ss, dof = 0.0, 0
    for i in range(change.size + 1):
        run = np.arange(
            bounds[i] + (1 if i > 0 else 0), bounds[i + 1] - (1 if i < change.size else 0)
        )
        for j in range(0, run.size - LEVEL_FRAMES + 1, LEVEL_FRAMES):
            piece = run[j : j + LEVEL_FRAMES]
            x = t[piece] - t[piece].mean()
            y = g[piece] - g[piece].mean()
            r = y - x * (x @ y) / (x @ x)
            ss, dof = ss + float(r @ r), dof + piece.size - 2
    if dof < 10:
        return gray_noise_sd(g)
    return float(max(np.sqrt(ss / dof), 0.005))


def _level(
    t: np.ndarray, g: np.ndarray, idx: np.ndarray, t_eval: np.ndarray, fallback: float
) -> tuple[np.ndarray, float]:
    """Grey level of the steady frames ``idx`` at times ``t_eval``, and its variance in
    units of the per-frame noise variance (largest over ``t_eval``).

    Four or more frames: a robust straight line (Theil-Sen), extrapolated to the
    frames at the edge, because the mean grey level drifts while the tip moves and a
    plain median lags it (measured: 0.5 ms edge bias during a pitch ramp). Fewer: the
    median (``fallback`` with none, variance 1).
    """
    if idx.size >= 4:
        slope, icpt, _, _ = theilslopes(g[idx], t[idx])
        dt = t_eval - float(np.mean(t[idx]))
        sxx = float(np.sum((t[idx] - np.mean(t[idx])) ** 2))
        var = np.pi / 2 * (1.0 / idx.size + float(np.max(dt**2)) / sxx)
        return icpt + slope * t_eval, var
    if idx.size:
        return np.full(t_eval.shape, float(np.median(g[idx]))), np.pi / 2 / idx.size
    return np.full(t_eval.shape, fallback), 1.0


def gray_noise_sd(g: np.ndarray) -> float:
    """Robust grey-level noise sd of a whole recording from second differences.

    ``1.4826 * median|d2 g| / sqrt(6)``: slow illumination changes cancel in the
    second difference and the few frames at LED edges are outliers the median ignores.
    """
    if g.size < 5:
        return 1.0
    d2 = np.diff(g, 2)
    return float(max(1.4826 * np.median(np.abs(d2)) / np.sqrt(6.0), 0.05))
