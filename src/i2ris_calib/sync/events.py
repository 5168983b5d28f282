"""Clock sync from a sync event: LED flash edges in the video matched to the log.

The controller switches an LED that both microscopes see and logs it as
``sync_flash``. In the video the flash is a jump of the mean grey level. A frame
whose exposure straddles the LED edge is partially bright; its brightness fraction
gives the edge time inside the exposure (sub-frame timing). Matching camera edges to
logged edges gives pairs ``(t_cam, t_ctrl)``; a weighted line through them gives
offset and drift (several flashes are needed for drift).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from i2ris_calib.errors import CalibError
from i2ris_calib.sync.clock import ClockModel, clock_from_offsets, clock_model
from i2ris_calib.sync.config import SyncConfig
from i2ris_calib.sync.log import Channel

TIME_FLOOR_S = 1e-5  # smallest standard deviation given to any edge time
LEVEL_FRAMES = 8  # steady frames each side of an edge used for the dark/bright levels
_REF = {"start": 0.0, "middle": 0.5, "end": 1.0}


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
    frames_t_s, frac, frac_sd, exposure_s, ref
        Camera edges only: timestamps and observed lit fractions of the frames
        around the edge, the fraction's sd, the exposure and its time reference.
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
    exposure_s: float = 0.0
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


def exposure_windows(t_s: np.ndarray, exposure_s: float, ref: str) -> tuple[np.ndarray, np.ndarray]:
    """(start, end) of each frame's exposure, s, from timestamps and where they sit in it."""
    start = t_s - _REF[ref] * exposure_s
    return start, start + exposure_s


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


def subframe_edge_time(
    t_s: np.ndarray,
    frac: np.ndarray,
    frac_sd: float,
    exposure_s: float,
    ref: str,
    rising: bool,
    level_frames: int = 0,
) -> tuple[float, float]:
    """Edge time (s) and its standard deviation from frames around one edge.

    Least squares over the edge time ``u`` of ``sum_j (lit_fraction_j(u) - frac_j)^2``
    (the exposure integrates the LED edge, so a straddling frame is partly lit).
    When no frame straddles the edge the objective is flat between the last dark and
    the first bright exposure: the estimate is the middle of that interval and its
    width enters the uncertainty as a uniform distribution.

    Parameters
    ----------
    t_s : ndarray, shape (k,)
        Timestamps of the frames around the edge (camera clock), s.
    frac : ndarray, shape (k,)
        Observed lit fraction of each frame: (grey - dark) / (bright - dark).
    frac_sd : float
        Standard deviation of ``frac`` (grey-level noise / contrast).
    level_frames : int
        Frames behind each of the dark/bright levels (medians); their error is
        propagated too (0 = levels known exactly).
    exposure_s : float
        Exposure time, s.
    ref, rising
        See :func:`exposure_windows` and :func:`lit_fraction`.
    """
    start, end = exposure_windows(t_s, exposure_s, ref)
    lo, hi = float(start.min()), float(end.max())
    step = max(exposure_s * 1e-4, 1e-7)
    grid = np.arange(lo, hi + step, step)
    sse = ((lit_fraction(grid, start, end, rising) - frac) ** 2).sum(axis=1)
    best = float(sse.min())
    flat = grid[sse <= best + max(1e-12, 1e-9 * best)]
    a, b = float(flat.min()), float(flat.max())
    t_hat = 0.5 * (a + b)
    # frames whose exposure contains the estimate carry the timing information
    # (boundaries included: a clipped, nearly dark/bright frame still has noise)
    eps = 1e-3 * step
    n_partial = int(((start - eps <= t_hat) & (t_hat <= end + eps)).sum())
    # noise of the partial frames plus that of the median levels (efficiency pi/2)
    level_var = np.pi / 2 / level_frames if level_frames else 0.0
    sd_noise = exposure_s * frac_sd * np.sqrt(1.0 / n_partial + level_var) if n_partial else 0.0
    sd = float(np.sqrt(((b - a) ** 2) / 12.0 + sd_noise**2 + TIME_FLOOR_S**2))
    return t_hat, sd


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
        ``flash_min_contrast_gray``, ``exposure_s``, ``frame_time_ref``, ``use_falling_edges``.

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
    exposure = cfg.exposure_s if cfg.exposure_s > 0 else interval
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
        lvl_before = _level(g, win_before, dark if rising else bright)
        lvl_after = _level(g, win_after, bright if rising else dark)
        lo_lvl, hi_lvl = (lvl_before, lvl_after) if rising else (lvl_after, lvl_before)
        if hi_lvl - lo_lvl < cfg.flash_min_contrast_gray:
            continue
        # frames near the edge, excluding frames that may straddle the neighbouring edges
        lo_b = bounds[i] + (1 if i > 0 else 0)
        hi_b = bounds[i + 2] - (1 if i + 2 < bounds.size - 1 else 0)
        idx = np.arange(max(k - 3, lo_b), min(k + 3, hi_b))
        frac = (g[idx] - lo_lvl) / (hi_lvl - lo_lvl)
        n_lvl = max(min(win_before.size, win_after.size), 1)
        frac_sd = noise / (hi_lvl - lo_lvl)
        te, sd = subframe_edge_time(
            t[idx], frac, frac_sd, exposure, cfg.frame_time_ref, rising, n_lvl
        )
        edges.append(
            Edge(
                te,
                sd,
                rising,
                camera,
                frames_t_s=t[idx],
                frac=frac,
                frac_sd=float(frac_sd * np.sqrt(1.0 + np.pi / 2 / n_lvl)),
                exposure_s=exposure,
                ref=cfg.frame_time_ref,
            )
        )
    return edges


def _level(g: np.ndarray, idx: np.ndarray, fallback: float) -> float:
    """Median grey level over frames ``idx`` (``fallback`` when there are none)."""
    return float(np.median(g[idx])) if idx.size else fallback


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
    ``max_edge_residual_s`` wins (ties: smallest RMS residual). A clock is then fitted
    to the matches (drift included) and the matching repeated once with it.

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
        if abs(g.t_s - t_ctrl) <= tol:
            pairs.append((c, g))
    return pairs


def edge_log_likelihood(
    cams: list[Edge], log: Edge, offset_c_s: np.ndarray, drift_ppm: np.ndarray, t_c_s: float
) -> np.ndarray:
    """Log-likelihood of one logged edge's camera observations on a grid of clocks.

    For each clock (offset at camera time ``t_c_s``, drift) the logged edge time,
    uniform in ``[log.t_lo_s, log.t_hi_s]``, maps to an interval of camera edge times
    ``u`` (one camera clock: the same ``u`` for every camera that saw the edge). The
    frames' lit fractions predicted by :func:`lit_fraction` are compared with the
    observed ones (Gaussian, sd ``frac_sd``) for all ``cams`` together, and the
    likelihood is averaged over that interval exactly, through its cumulative integral
    on a fine ``u`` grid. Flat stretches (an edge between two exposures) stay flat:
    the constraint is a hard interval, softened only by the noise.

    Parameters
    ----------
    cams : list of Edge
        The camera edges matched to ``log`` (one per camera).
    offset_c_s, drift_ppm : ndarray, shape (G,)
        Grid of clocks; ``t_ctrl = offset_c_s + t_c_s + (1 + drift*1e-6) * (t_cam - t_c_s)``.

    Returns
    -------
    ndarray, shape (G,)
    """
    windows = [exposure_windows(c.frames_t_s, c.exposure_s, c.ref) for c in cams]
    step = max(min(c.exposure_s * c.frac_sd for c in cams) / 4.0, 1e-7)
    lo = min(w[0].min() for w in windows)
    hi = max(w[1].max() for w in windows)
    grid = np.arange(lo - step, hi + 2 * step, step)
    sse = sum(
        (((lit_fraction(grid, a, b, c.rising) - c.frac) / c.frac_sd) ** 2).sum(axis=1)
        for c, (a, b) in zip(cams, windows, strict=True)
    )
    sse_min = float(sse.min())
    like = np.exp(-0.5 * (sse - sse_min))
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (like[1:] + like[:-1]) * step)])

    def integral(u: np.ndarray) -> np.ndarray:
        """Cumulative likelihood, extended linearly (constant likelihood) beyond the grid."""
        inside = np.interp(u, grid, cum)
        below = np.minimum(u - grid[0], 0.0) * like[0]
        above = np.maximum(u - grid[-1], 0.0) * like[-1]
        return inside + below + above

    scale = 1.0 + drift_ppm * 1e-6
    u_lo = t_c_s + (log.t_lo_s - offset_c_s - t_c_s) / scale
    u_hi = t_c_s + (log.t_hi_s - offset_c_s - t_c_s) / scale
    width = u_hi - u_lo
    if log.t_hi_s > log.t_lo_s:
        mean_like = (integral(u_hi) - integral(u_lo)) / width
    else:
        mean_like = np.interp(u_hi, grid, like)
    return -0.5 * sse_min + np.log(np.maximum(mean_like, 1e-300))


def posterior_clock(
    pairs: list[tuple[Edge, Edge]],
    t_c_s: float,
    centre: tuple[float, float],
    halfwidth: tuple[float, float],
    fit_drift: bool,
    n_grid: int = 121,
    max_rounds: int = 6,
) -> tuple[np.ndarray, np.ndarray]:
    """Posterior mean and covariance of (offset at ``t_c_s``, drift) on an adaptive grid.

    Flat prior; likelihood = product of :func:`edge_log_likelihood` over the logged
    edges (the cameras that saw one logged edge share its unknown time). The grid is widened while posterior mass sits on its border and narrowed
    while the posterior is under-resolved.

    Returns
    -------
    mean : ndarray, shape (2,)
        (offset_c_s, drift_ppm).
    cov : ndarray, shape (2, 2)
    """
    by_log: dict[int, tuple[list[Edge], Edge]] = {}
    for ce, le in pairs:  # one likelihood term per LOGGED edge: its time is shared
        by_log.setdefault(id(le), ([], le))[0].append(ce)
    groups = list(by_log.values())
    c = np.array(centre, dtype=float)
    h = np.array(halfwidth, dtype=float)
    if not fit_drift:
        h[1] = 0.0
    for _ in range(max_rounds):
        o_ax = c[0] + np.linspace(-h[0], h[0], n_grid)
        d_ax = c[1] + (np.linspace(-h[1], h[1], n_grid) if fit_drift else np.zeros(1))
        oo, dd = (a.ravel() for a in np.meshgrid(o_ax, d_ax, indexing="ij"))
        ll = sum(edge_log_likelihood(cs, le, oo, dd, t_c_s) for cs, le in groups)
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
    return mean, cov


def clock_from_events(cam: list[Edge], log: list[Edge], cfg: SyncConfig) -> ClockModel:
    """Offset and drift from LED edges matched between video and encoder log.

    A weighted line through the per-edge times (:func:`clock_from_offsets`) gives a
    start; the estimate is then the posterior mean of (offset, drift) given every
    matched frame's brightness (:func:`posterior_clock`), which combines the
    interval constraints of many edges far better than averaging their midpoints.
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
    mean, cov_c = posterior_clock(pairs, t_c, centre, halfwidth, fit_drift)
    jac = np.array([[1.0, -t_c * 1e-6], [0.0, 1.0]])
    o, d, cov = mean[0] - mean[1] * 1e-6 * t_c, mean[1], jac @ cov_c @ jac.T
    resid = off - (o + d * 1e-6 * t)
    evidence = {
        "n_camera_edges": len(cam),
        "n_log_edges": len(log),
        "n_matched": len(pairs),
        "drift_fitted": fit_drift,
        "line_fit": {"offset_s": o0, "drift_ppm": d0, "chi2_reduced": chi2},
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
