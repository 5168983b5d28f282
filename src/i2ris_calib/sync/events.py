"""Clock sync from a sync event: LED flash edges in the video matched to the log.

The controller switches an LED that both microscopes see and logs it as
``sync_flash``. In the video the flash is a jump of the mean grey level. A frame
whose exposure straddles the LED edge is partially bright; its brightness fraction
gives the edge time inside the exposure (sub-frame timing). An edge that falls
between two exposures (short exposure, or a dropped frame) is only known to lie in
that gap. The exact likelihood of the edge time is in :mod:`i2ris_calib.sync.edgetime`.
When the exposure time is not configured it is marginalised over
:data:`EXPOSURE_FRACTIONS` of the frame interval, weighted by how well each explains
the frames. Matching camera edges to logged edges gives the clock posterior.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.special import logsumexp

from i2ris_calib.errors import CalibError
from i2ris_calib.sync.clock import ClockModel, clock_from_offsets, clock_model
from i2ris_calib.sync.config import SyncConfig
from i2ris_calib.sync.edgetime import (
    SsePieces,
    edge_moments,
    exposure_windows,  # noqa: F401  (re-exported: part of this module's API)
    sse_pieces,
    window_min_sse,
)
from i2ris_calib.sync.log import Channel

TIME_FLOOR_S = 1e-5  # smallest standard deviation given to any edge time
LEVEL_FRAMES = 8  # steady frames each side of an edge used for the dark/bright levels
#: exposures tried when ``sync.exposure_s = 0`` (unknown), as fractions of the frame interval
EXPOSURE_FRACTIONS = np.array([0.03, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0])
#: exposures whose evidence is this many nats below the best are dropped from the clock posterior
EXPOSURE_PRUNE_NATS = 40.0
#: evidence differences between exposures smaller than this (nats) are not trusted: the
#: evidence assumes flash times random relative to the frames, but round flash times
#: (e.g. 0.5 s at 30 fps) sit at frame centres and are partly lit whatever the exposure
EXPOSURE_TRUST_NATS = 6.0


@dataclass(frozen=True)
class Edge:
    """One LED edge.

    Attributes
    ----------
    t_s : float
        Edge time on the clock of its source, s.
    sd_s : float
        Standard deviation of ``t_s``, s.
    rising : bool
        True for LED on, False for LED off.
    source : str
        Camera name, or ``"log"``.
    frames_t_s, frac, frac_sd, exposures_s, ref
        Camera edges only: timestamps and observed lit fractions of the frames
        around the edge, the fraction's sd, the candidate exposure times (one when
        configured, :data:`EXPOSURE_FRACTIONS` of the frame interval when not) and
        where a timestamp lies in its exposure.
    t_lo_s, t_hi_s
        Log edges only: the interval the edge is known to lie in.
    """

    t_s: float
    sd_s: float
    rising: bool
    source: str
    # camera edges: the frames around the edge, for the joint clock likelihood
    frames_t_s: np.ndarray | None = None
    frac: np.ndarray | None = None
    frac_sd: float = 0.0
    exposures_s: tuple[float, ...] = ()
    ref: str = "middle"
    # log edges: the edge lies in [t_lo_s, t_hi_s] (uniform)
    t_lo_s: float = 0.0
    t_hi_s: float = 0.0


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
        See :func:`exposure_windows` and :func:`lit_fraction`.
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


def edge_given_exposure(edge: Edge, weights: np.ndarray) -> Edge:
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


def camera_edges(t_s: np.ndarray, gray: np.ndarray, camera: str, cfg: SyncConfig) -> list[Edge]:
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
    list of Edge
        Empty when the grey level never jumps by ``flash_min_contrast_gray``.
    """
    ok = np.isfinite(t_s) & np.isfinite(gray)
    t, g = np.asarray(t_s, float)[ok], np.asarray(gray, float)[ok]
    order = np.argsort(t)
    t, g = t[order], g[order]
    if t.size < 4:
        return []
    dark, bright = two_level_split(g)
    if bright - dark < cfg.flash_min_contrast_gray:
        return []
    on = g > 0.5 * (dark + bright)
    interval = float(np.median(np.diff(t)))
    exposures = exposure_candidates(cfg.exposure_s, interval)
    change = np.flatnonzero(on[1:] != on[:-1]) + 1  # first frame of each new run
    noise = gray_noise_sd(g)
    bounds = np.concatenate([[0], change, [t.size]])
    edges = []
    for i, k in enumerate(change):
        rising = bool(on[k])
        if not rising and not cfg.use_falling_edges:
            continue
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
        lo_lvl, hi_lvl = (lvl_before, lvl_after) if rising else (lvl_after, lvl_before)
        contrast = float(np.min(hi_lvl - lo_lvl))
        if contrast < cfg.flash_min_contrast_gray:
            continue
        frac = (g[idx] - lo_lvl) / (hi_lvl - lo_lvl)
        frac_sd = noise / contrast * np.sqrt(1.0 + max(var_b, var_a))
        te, sd = subframe_edge_time(t[idx], frac, frac_sd, exposures, cfg.frame_time_ref, rising)
        edges.append(
            Edge(
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
        )
    return edges


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
        from scipy.stats import theilslopes

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


def log_edges(flash: Channel, at: str) -> list[Edge]:
    """LED edges of the logged ``sync_flash`` channel (controller clock).

    ``at="first_on"``: the edge is at the first sample with the new state (the
    controller logs the tick at which it switched the LED); ``"midpoint"``: half
    way between the two samples, with a uniform uncertainty over the interval.
    """
    v = flash.values > 0
    k = np.flatnonzero(v[1:] != v[:-1]) + 1
    edges = []
    for i in k:
        t0, t1 = float(flash.t_s[i - 1]), float(flash.t_s[i])
        lo = t0 if at == "midpoint" else t1
        sd = (t1 - lo) / np.sqrt(12.0)
        edges.append(
            Edge(0.5 * (lo + t1), max(sd, TIME_FLOOR_S), bool(v[i]), "log", t_lo_s=lo, t_hi_s=t1)
        )
    return edges


def match_edges(cam: list[Edge], log: list[Edge], cfg: SyncConfig) -> list[tuple[Edge, Edge]]:
    """Pair camera edges with logged edges of the same kind.

    Every (camera edge, log edge) pair of the same kind is tried as the anchor of a
    pure offset; the anchor that matches the most camera edges within
    ``max_edge_residual_s`` (plus the edges' own uncertainty, :func:`_pair_tolerance`)
    wins (ties: smallest RMS residual). A clock is then fitted to the matches (drift
    included) and the matching repeated once with it.

    Raises
    ------
    CalibError
        When two different offsets explain the edges equally well (periodic flashes
        with equal durations and a video covering only part of them).
    """
    if cfg.offset_search_s > 0:
        lo, hi = cfg.offset_guess_s - cfg.offset_search_s, cfg.offset_guess_s + cfg.offset_search_s
    else:
        lo, hi = -np.inf, np.inf
    tol = cfg.max_edge_residual_s
    scored = []
    for c in cam:
        for g in log:
            if c.rising != g.rising or not lo <= g.t_s - c.t_s <= hi:
                continue
            pairs = _pairs_for_offset(cam, log, g.t_s - c.t_s, 0.0, tol)
            res = np.array([gl.t_s - cl.t_s - (g.t_s - c.t_s) for cl, gl in pairs])
            scored.append((len(pairs), float(np.sqrt(np.mean(res**2))), g.t_s - c.t_s))
    if not scored:
        return []
    scored.sort(key=lambda s: (-s[0], s[1]))
    n_best, rms_best, off_best = scored[0]
    rivals = [s for s in scored if abs(s[2] - off_best) > 2 * tol and s[0] == n_best]
    if rivals and rivals[0][1] < 3 * rms_best + 1e-3:
        raise CalibError(
            f"sync flash edges match the log equally well at offsets {off_best:.4f} s and "
            f"{rivals[0][2]:.4f} s (periodic flashes?): set sync.offset_guess_s and "
            "sync.offset_search_s to pick one, or use flashes of distinct durations"
        )
    pairs = _pairs_for_offset(cam, log, off_best, 0.0, tol)
    if len(pairs) >= 2:
        t = np.array([c.t_s for c, _ in pairs])
        off = np.array([g.t_s - c.t_s for c, g in pairs])
        o, d, _, _ = clock_from_offsets(t, off, np.ones_like(t), fit_drift=np.ptp(t) > 1.0)
        pairs = _pairs_for_offset(cam, log, o, d, tol)
    return pairs


def _pairs_for_offset(cam, log, offset_s, drift_ppm, tol):
    """Nearest same-kind log edge within ``tol`` for each camera edge under a clock."""
    pairs = []
    for c in cam:
        t_ctrl = offset_s + (1 + drift_ppm * 1e-6) * c.t_s
        same = [g for g in log if g.rising == c.rising]
        if not same:
            continue
        g = min(same, key=lambda g: abs(g.t_s - t_ctrl))
        if abs(g.t_s - t_ctrl) <= _pair_tolerance(c, g, tol):
            pairs.append((c, g))
    return pairs


def _pair_tolerance(cam: Edge, log: Edge, tol: float) -> float:
    """Largest residual of a matching pair: ``tol`` plus the half-widths of both edges'
    uncertainty intervals (sqrt(3) sd: the half-width of a uniform distribution), so a
    coarse edge (between exposures, slow log) is not rejected for its own quantisation."""
    return tol + np.sqrt(3.0) * (cam.sd_s + log.sd_s)


@dataclass(frozen=True)
class EdgeGroup:
    """One logged edge and the frames of every camera that saw it (they share its time).

    ``pieces[e]``, ``log_z[e]`` and ``sse_min[e]`` belong to ``exposures_s[e]``
    (:func:`i2ris_calib.sync.edgetime.sse_pieces`, evidence and smallest misfit).
    """

    log: Edge
    pieces: tuple[SsePieces, ...]
    log_z: np.ndarray
    sse_min: np.ndarray


def edge_group(cams: list[Edge], log: Edge) -> EdgeGroup:
    """The frames of ``cams`` (camera edges matched to ``log``) as one likelihood term."""
    t = np.concatenate([c.frames_t_s for c in cams])
    f = np.concatenate([c.frac for c in cams])
    sd = np.concatenate([np.full(c.frac.size, c.frac_sd) for c in cams])
    pieces, log_z, s_min = [], [], []
    for k in range(len(cams[0].exposures_s)):  # the k-th candidate of every camera
        e = np.concatenate([np.full(c.frac.size, c.exposures_s[k]) for c in cams])
        pc = sse_pieces(t, f, sd, e, cams[0].ref, cams[0].rising)
        pieces.append(pc)
        log_z.append(edge_moments(pc)[0])
        s_min.append(pc.minimum())
    return EdgeGroup(log, tuple(pieces), np.array(log_z), np.array(s_min))


def edge_log_likelihood(
    group: EdgeGroup, k: int, offset_c_s: np.ndarray, drift_ppm: np.ndarray, t_c_s: float
) -> np.ndarray:
    """Log-likelihood of one logged edge's frames on a grid of clocks, exposure ``k``.

    For each clock (offset at camera time ``t_c_s``, drift) the logged edge time,
    somewhere in ``[log.t_lo_s, log.t_hi_s]``, maps to an interval of camera edge
    times ``u``. The term is minus half the best misfit inside that interval relative
    to the overall best: the edge's position inside its log interval and
    inside a gap between exposures is *profiled*, not averaged. Averaging would
    assume these positions independent from edge to edge, which they are not when a
    flash lasts a whole number of frames or log ticks (both edges then sit at the
    same phase), and would make the posterior narrower than the truth allows.

    Parameters
    ----------
    group : EdgeGroup
    k : int
        Index of the exposure in ``group.pieces``.
    offset_c_s, drift_ppm : ndarray, shape (G,)
        Grid of clocks; ``t_ctrl = offset_c_s + t_c_s + (1 + drift*1e-6) * (t_cam - t_c_s)``.

    Returns
    -------
    ndarray, shape (G,)
    """
    log = group.log
    scale = 1.0 + drift_ppm * 1e-6
    u_lo = t_c_s + (log.t_lo_s - offset_c_s - t_c_s) / scale
    u_hi = t_c_s + (log.t_hi_s - offset_c_s - t_c_s) / scale
    sse = window_min_sse(group.pieces[k], u_lo, u_hi)
    return -0.5 * (sse - group.sse_min[k])


def exposure_log_weights(groups: list[EdgeGroup]) -> np.ndarray:
    """Log prior weight of each candidate exposure from the frames' evidence, (E,).

    The summed evidence ``log_z`` (edge times free) rules out exposures that explain
    the frames far worse, e.g. a full-interval exposure when no frame is partly lit;
    differences below :data:`EXPOSURE_TRUST_NATS` are flattened, and exposures more
    than :data:`EXPOSURE_PRUNE_NATS` below the best are dropped (-inf).
    """
    total = sum(g.log_z for g in groups)
    rel = total - total.max()
    return np.where(
        rel >= -EXPOSURE_PRUNE_NATS, np.minimum(rel + EXPOSURE_TRUST_NATS, 0.0), -np.inf
    )


def clock_log_likelihood(
    groups: list[EdgeGroup], log_w: np.ndarray, oo: np.ndarray, dd: np.ndarray, t_c_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """Log-likelihood of the clocks ``(oo, dd)`` (G,), marginal over the exposures with
    log weights ``log_w`` (E,), and the per-exposure terms (E, G) (-inf: dropped)."""
    per = np.full((log_w.size, oo.size), -np.inf)
    for k in np.flatnonzero(np.isfinite(log_w)):
        per[k] = log_w[k] + sum(edge_log_likelihood(g, k, oo, dd, t_c_s) for g in groups)
    return logsumexp(per, axis=0), per


def posterior_clock(
    pairs: list[tuple[Edge, Edge]],
    t_c_s: float,
    centre: tuple[float, float],
    halfwidth: tuple[float, float],
    fit_drift: bool,
    n_grid: int = 101,
    max_rounds: int = 8,
    temper: float = 1.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Posterior mean and covariance of (offset at ``t_c_s``, drift) on an adaptive grid.

    Flat prior on the clock, :func:`exposure_log_weights` on the candidate exposures;
    likelihood = product of :func:`edge_log_likelihood` over the logged edges (the
    cameras that saw one logged edge share its unknown time), summed over the
    exposures, raised to ``1/temper``
    (``temper > 1`` widens the posterior when the edges disagree more than the grey
    noise allows). The grid is widened while posterior mass sits on its border and
    narrowed while the posterior is under-resolved.

    Returns
    -------
    mean : ndarray, shape (2,)
        (offset_c_s, drift_ppm).
    cov : ndarray, shape (2, 2)
    exposure_weights : ndarray, shape (E,)
        Posterior probability of each candidate exposure.
    misfit : float
        ``sum_g (sse_g - min sse_g)`` at the most likely clock and exposure: how far the
        edges are from all fitting one clock (0 when every edge's best time is allowed).
    """
    by_log: dict[int, tuple[list[Edge], Edge]] = {}
    for ce, le in pairs:  # one likelihood term per LOGGED edge: its time is shared
        by_log.setdefault(id(le), ([], le))[0].append(ce)
    groups = [edge_group(cs, le) for cs, le in by_log.values()]
    log_w = exposure_log_weights(groups)
    c = np.array(centre, dtype=float)
    h = np.array(halfwidth, dtype=float)
    if not fit_drift:
        h[1] = 0.0
    for _ in range(max_rounds):
        o_ax = c[0] + np.linspace(-h[0], h[0], n_grid)
        d_ax = c[1] + (np.linspace(-h[1], h[1], n_grid) if fit_drift else np.zeros(1))
        oo, dd = (a.ravel() for a in np.meshgrid(o_ax, d_ax, indexing="ij"))
        ll, per = clock_log_likelihood(groups, log_w, oo, dd, t_c_s)
        ll, per = ll / temper, per / temper
        w = np.exp(ll - ll.max())
        w /= w.sum()
        mean = np.array([w @ oo, w @ dd])
        dev = np.stack([oo - mean[0], dd - mean[1]])
        cov = (dev * w) @ dev.T
        sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
        w2 = w.reshape(o_ax.size, d_ax.size)
        border = w2[[0, -1], :].sum() + (w2[:, [0, -1]].sum() if fit_drift else 0.0)
        steps = 2 * h / (n_grid - 1)
        axes = [0, 1] if fit_drift else [0]
        if border > 1e-4:
            c, h = mean, h * 2.0
        elif any(sd[a] < 3 * steps[a] for a in axes):
            c, h = mean, np.maximum(6 * sd, h / 8)
        else:
            break
        if not fit_drift:
            h[1] = 0.0
    if not fit_drift:
        cov[1, :] = cov[:, 1] = 0.0
    pe = logsumexp(per, axis=1)
    k, gi = np.unravel_index(np.argmax(per), per.shape)
    misfit = float(-2.0 * (temper * per[k, gi] - log_w[k]))
    return mean, cov, np.exp(pe - logsumexp(pe)), misfit


def clock_from_events(cam: list[Edge], log: list[Edge], cfg: SyncConfig) -> ClockModel:
    """Offset and drift from LED edges matched between video and encoder log.

    A weighted line through the per-edge times (:func:`clock_from_offsets`) gives a
    start; the estimate is then the posterior mean of (offset, drift) given every
    matched frame's brightness (:func:`posterior_clock`), which intersects the
    interval constraints of all edges instead of averaging their midpoints. With
    ``cfg.exposure_s = 0`` the exposure is unknown and marginalised. When the edges
    disagree more than the noise allows (misfit above its degrees of freedom: one per
    logged edge less the fitted parameters) the likelihood is tempered by that ratio,
    as least squares scales a covariance by the reduced chi-square.
    Drift is fitted when the matched edges span at least ``cfg.min_drift_span_s``;
    otherwise it is held at 0 ppm (stderr NaN).

    Raises
    ------
    CalibError
        No camera edge matches a logged edge.
    """
    pairs = match_edges(cam, log, cfg)
    if not pairs:
        raise CalibError(
            f"sync flash: {len(cam)} edge(s) in the video and {len(log)} in the encoder log, "
            "but none match (check sync.frame_time_ref/exposure_s, or use sync.method = 'model')"
        )
    t = np.array([c.t_s for c, _ in pairs])
    off = np.array([g.t_s - c.t_s for c, g in pairs])
    sd = np.array([np.hypot(c.sd_s, g.sd_s) for c, g in pairs])
    fit_drift = bool(np.ptp(t) >= cfg.min_drift_span_s)
    o0, d0, cov0, chi2 = clock_from_offsets(t, off, sd, fit_drift=fit_drift)
    t_c = float(np.average(t, weights=1 / sd**2))
    centre = (o0 + d0 * 1e-6 * t_c, d0)
    j = np.array([1.0, t_c * 1e-6])
    sd_c = float(np.sqrt(j @ cov0 @ j))
    halfwidth = (5 * max(sd_c, 2e-4), 5 * max(np.sqrt(cov0[1, 1]), 1.0))
    mean, cov_c, p_exposure, misfit = posterior_clock(pairs, t_c, centre, halfwidth, fit_drift)
    n_groups = len({id(g) for _, g in pairs})
    temper = max(1.0, misfit / max(n_groups - (2 if fit_drift else 1), 1))
    if temper > 1.0:  # edges disagree beyond the grey noise (e.g. saturated bright pixels)
        mean, cov_c, p_exposure, _ = posterior_clock(
            pairs, t_c, tuple(mean), halfwidth, fit_drift, temper=temper
        )
    jac = np.array([[1.0, -t_c * 1e-6], [0.0, 1.0]])
    o, d, cov = mean[0] - mean[1] * 1e-6 * t_c, mean[1], jac @ cov_c @ jac.T
    pairs = [(edge_given_exposure(c, p_exposure), g) for c, g in pairs]
    t = np.array([c.t_s for c, _ in pairs])
    resid = np.array([g.t_s - c.t_s for c, g in pairs]) - (o + d * 1e-6 * t)
    evidence = {
        "n_camera_edges": len(cam),
        "n_log_edges": len(log),
        "n_matched": len(pairs),
        "drift_fitted": fit_drift,
        "line_fit": {"offset_s": o0, "drift_ppm": d0, "chi2_reduced": chi2},
        "exposure": exposure_evidence(pairs[0][0].exposures_s, p_exposure, cfg.exposure_s),
        "misfit": misfit,
        "likelihood_temper": temper,
        "edges": [
            {
                "camera": c.source,
                "kind": "on" if c.rising else "off",
                "t_cam_s": c.t_s,
                "t_cam_sd_s": c.sd_s,
                "t_ctrl_s": g.t_s,
                "t_ctrl_sd_s": g.sd_s,
                "residual_s": float(r),
            }
            for (c, g), r in zip(pairs, resid, strict=True)
        ],
    }
    return clock_model(o, d, cov, "event", evidence, fit_drift)


def exposure_evidence(exposures_s, weights: np.ndarray, configured_s: float) -> dict:
    """JSON summary of the exposure: configured, or the posterior over the candidates."""
    e = np.asarray(exposures_s, dtype=float)
    mean = float(weights @ e)
    return {
        "configured_s": configured_s,
        "mean_s": mean,
        "sd_s": float(np.sqrt(max(weights @ (e - mean) ** 2, 0.0))),
        "candidates_s": e.tolist(),
        "posterior": weights.tolist(),
    }
