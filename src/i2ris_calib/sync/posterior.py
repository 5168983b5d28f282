"""Posterior of the clock (offset, drift) given matched LED edges.

One likelihood term per logged edge: the frames of every camera that saw it share its
unknown time. The edge's position inside its log interval and inside an exposure gap
is profiled (:func:`edge_log_likelihood`), the exposure marginalised with weights from
the frames' evidence (:func:`exposure_log_weights`), and the posterior mean and
covariance taken on an adaptive grid (:func:`posterior_clock`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import logsumexp

from i2ris_calib.sync.edgetime import (
    SsePieces,
    edge_moments,
    sse_pieces,
    window_log_prob,
    window_min_sse,
)
from i2ris_calib.sync.flash import CameraEdge
from i2ris_calib.sync.logedges import LogEdge
from i2ris_calib.sync.matching import EdgePair

#: exposures whose evidence is this many nats below the best are dropped from the clock posterior
EXPOSURE_PRUNE_NATS = 40.0
#: evidence differences between exposures smaller than this (nats) are not trusted: the
#: evidence assumes flash times random relative to the frames, but round flash times
#: (e.g. 0.5 s at 30 fps) sit at frame centres and are partly lit whatever the exposure
EXPOSURE_TRUST_NATS = 6.0


@dataclass(frozen=True)
class EdgeGroup:
    """One logged edge and the frames of every camera that saw it (they share its time).

    ``pieces[e]``, ``log_z[e]`` and ``sse_min[e]`` belong to ``exposures_s[e]``
    (:func:`i2ris_calib.sync.edgetime.sse_pieces`, evidence and smallest misfit).
    """

    log: LogEdge
    pieces: tuple[SsePieces, ...]
    log_z: np.ndarray
    sse_min: np.ndarray


def edge_group(cams: list[CameraEdge], log: LogEdge) -> EdgeGroup:
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
    group: EdgeGroup,
    k: int,
    offset_c_s: np.ndarray,
    drift_ppm: np.ndarray,
    t_c_s: float,
    mode: str = "profile",
) -> np.ndarray:
    """Log-likelihood of one logged edge's frames on a grid of clocks, exposure ``k``.

    For each clock (offset at camera time ``t_c_s``, drift) the logged edge time,
    somewhere in ``[log.t_lo_s, log.t_hi_s]``, maps to an interval of camera edge
    times ``u``. ``mode="integral"`` (interval-censored likelihood): the term is the
    log probability, given the frames, that the edge lies in that interval (the
    edge uniform inside its log interval, convolved with the camera's timing error;
    :func:`i2ris_calib.sync.edgetime.window_log_prob`). ``mode="profile"``: minus half
    the best misfit inside the interval relative to the overall best (the position
    inside the interval maximised, not integrated: flat wherever the frames allow
    the edge, so coarse edges in exposure gaps count only as bounds).

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
    if mode == "integral":
        return window_log_prob(group.pieces[k], u_lo, u_hi)
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
    groups: list[EdgeGroup],
    log_w: np.ndarray,
    oo: np.ndarray,
    dd: np.ndarray,
    t_c_s: float,
    mode: str = "profile",
) -> tuple[np.ndarray, np.ndarray]:
    """Log-likelihood of the clocks ``(oo, dd)`` (G,), marginal over the exposures with
    log weights ``log_w`` (E,), and the per-exposure terms (E, G) (-inf: dropped)."""
    per = np.full((log_w.size, oo.size), -np.inf)
    for k in np.flatnonzero(np.isfinite(log_w)):
        per[k] = log_w[k] + sum(edge_log_likelihood(g, k, oo, dd, t_c_s, mode) for g in groups)
    return logsumexp(per, axis=0), per


def posterior_clock(
    pairs: list[EdgePair],
    t_c_s: float,
    centre: tuple[float, float],
    halfwidth: tuple[float, float],
    fit_drift: bool,
    n_grid: int = 101,
    max_rounds: int = 8,
    temper: float = 1.0,
    mode: str = "profile",
    span_s: tuple[float, float] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Posterior estimate and covariance of (offset at ``t_c_s``, drift) on an adaptive grid.

    Flat prior on the clock, :func:`exposure_log_weights` on the candidate exposures;
    likelihood = product of :func:`edge_log_likelihood` over the logged edges (the
    cameras that saw one logged edge share its unknown time), summed over the
    exposures, raised to ``1/temper``
    (``temper > 1`` widens the posterior when the edges disagree more than the grey
    noise allows). The grid is widened while posterior mass sits on its border and
    narrowed while the posterior is under-resolved. ``mode``: see
    :func:`edge_log_likelihood`.

    ``span_s = (t_first, t_last)`` (camera clock, s) asks for the clock with the
    smallest worst-case error over that span instead of the posterior mean: the
    clock error is linear in time, so its largest value over the span is at one of
    its ends, and the estimate is the line through the mid-ranges (between the 0.1 %
    and 99.9 % quantiles) of the posterior of the clock at the two ends (their
    Chebyshev centre). With log intervals that bound the clock to a polygon (a
    sampled LED state) the posterior is flat-topped and its mean can sit 2/3 of a
    tick from a corner where the truth may lie; the mid-range is at most half a
    tick from any point of it. For a symmetric posterior both are the same.

    Returns
    -------
    mean : ndarray, shape (2,)
        (offset_c_s, drift_ppm): the posterior mean, or the mid-range estimate
        with ``span_s``.
    cov : ndarray, shape (2, 2)
        Posterior covariance about the returned estimate (the posterior mean
        squared error: covariance plus the outer product of the estimate's
        distance from the mean).
    exposure_weights : ndarray, shape (E,)
        Posterior probability of each candidate exposure.
    misfit : float
        ``sum_g (sse_g - min sse_g)`` at the most likely clock and exposure: how far the
        edges are from all fitting one clock (0 when every edge's best time is allowed).
    """
    by_log: dict[int, tuple[list[CameraEdge], LogEdge]] = {}
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
        ll, per = clock_log_likelihood(groups, log_w, oo, dd, t_c_s, mode)
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
    if span_s is not None:
        est = midrange_clock(w, oo, dd, t_c_s, span_s, fit_drift)
        cov = cov + np.outer(est - mean, est - mean)
        mean = est
    if not fit_drift:
        cov[1, :] = cov[:, 1] = 0.0
    pe = logsumexp(per, axis=1)
    if mode != "profile":
        _, per = clock_log_likelihood(groups, log_w, oo, dd, t_c_s, "profile")
    else:
        per = per * temper
    k, gi = np.unravel_index(np.argmax(per), per.shape)
    misfit = float(-2.0 * (per[k, gi] - log_w[k]))
    return mean, cov, np.exp(pe - logsumexp(pe)), misfit


def weighted_quantile(x: np.ndarray, w: np.ndarray, q: float) -> float:
    """Quantile ``q`` of the values ``x`` (G,) with probabilities ``w`` (G,)."""
    order = np.argsort(x)
    cw = np.cumsum(w[order])
    return float(x[order][min(np.searchsorted(cw, q * cw[-1]), x.size - 1)])


def midrange_clock(
    w: np.ndarray,
    oo: np.ndarray,
    dd: np.ndarray,
    t_c_s: float,
    span_s: tuple[float, float],
    fit_drift: bool,
    q: float = 1e-3,
) -> np.ndarray:
    """(offset at ``t_c_s``, drift) through the mid-ranges of the clock at the span's ends.

    ``w`` (G,): posterior probabilities of the grid clocks ``(oo, dd)``. The offsets at
    ``span_s[0]`` and ``span_s[1]`` have the posterior quantiles ``q`` and ``1 - q``;
    the returned clock passes through the middle of each (drift held when not fitted).
    """
    t0, t1 = float(span_s[0]), float(span_s[1])
    if not fit_drift or t1 - t0 <= 0:
        o = 0.5 * (weighted_quantile(oo, w, q) + weighted_quantile(oo, w, 1 - q))
        return np.array([o, float(w @ dd)])
    ends = []
    for t in (t0, t1):
        x = oo + dd * 1e-6 * (t - t_c_s)
        ends.append(0.5 * (weighted_quantile(x, w, q) + weighted_quantile(x, w, 1 - q)))
    drift = (ends[1] - ends[0]) / (t1 - t0) * 1e6
    return np.array([ends[0] - drift * 1e-6 * (t0 - t_c_s), drift])
