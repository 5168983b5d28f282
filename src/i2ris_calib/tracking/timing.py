"""Cameras not triggered together: the second camera's corners at the first camera's
frame times (interpolated, or extrapolated from one side), the refit of frames where the
interpolation disagrees with the first view, the per-frame timing uncertainty of the
interpolation, and the grey level of the nearest frame (for the sync flash).

Pure array functions (no files): ``commands.track`` calls them while fusing a session; see
docs/design/tracking.md ("Cameras not triggered together" under Known limits, and "Flagging what
the interpolation cannot place").
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from i2ris_calib.tracking import fuse as fz
from i2ris_calib.tracking.config import TrackingConfig


def resample_corners(
    t_src: np.ndarray, c_src: np.ndarray, t_dst: np.ndarray, cfg: TrackingConfig
) -> np.ndarray:
    """Corners (n_dst, 4, 2) at times ``t_dst``: same frame, or linear between neighbours.

    Before the first frame of ``t_src`` or after its last (a camera triggered later than
    the other misses the other's first frame) the corners are extrapolated from the two
    nearest frames, by at most half their interval. NaN when no frame is within
    ``same_frame_tol_s`` and the bracketing frames are missing or more than
    ``max_interp_gap_s`` apart.
    """
    out = np.full((len(t_dst), 4, 2), np.nan)
    j = np.clip(np.searchsorted(t_src, t_dst), 1, len(t_src) - 1)
    t0, t1 = t_src[j - 1], t_src[j]
    near = np.where(np.abs(t_dst - t0) <= np.abs(t1 - t_dst), j - 1, j)
    same = np.abs(t_src[near] - t_dst) <= cfg.same_frame_tol_s
    out[same] = c_src[near[same]]
    w = np.clip((t_dst - t0) / np.maximum(t1 - t0, 1e-12), 0, 1)
    interp = ~same & (t1 - t0 <= cfg.max_interp_gap_s) & (t_dst >= t0) & (t_dst <= t1)
    ci = (1 - w)[:, None, None] * c_src[j - 1] + w[:, None, None] * c_src[j]
    out[interp] = ci[interp]
    if len(t_src) >= 2:
        for side, beyond, dt in (
            ("after", t_dst < t_src[0], t_src[1] - t_src[0]),
            ("before", t_dst > t_src[-1], t_src[-1] - t_src[-2]),
        ):
            k = np.flatnonzero(~same & beyond & (np.abs(t_dst - t_src[near]) <= 0.5 * dt))
            if k.size:
                out[k] = one_sided_corners(t_src, c_src, t_dst[k], side, cfg)
    return out


#: a measured frame whose reprojection error exceeds this many times the session's median
#: (and :data:`REFIT_MIN_PX`) is refitted with the second camera's corners extrapolated
#: from the frames on one side (:func:`refit_lagged_frames`)
REFIT_FACTOR = 5.0
REFIT_MIN_PX = 0.1


def interp_weight(t_src: np.ndarray, t_dst: np.ndarray) -> np.ndarray:
    """Weight of the later of the two frames of ``t_src`` bracketing each of ``t_dst``
    in :func:`resample_corners` (0..1)."""
    j = np.clip(np.searchsorted(t_src, t_dst), 1, len(t_src) - 1)
    t0, t1 = t_src[j - 1], t_src[j]
    return np.clip((t_dst - t0) / np.maximum(t1 - t0, 1e-12), 0, 1)


def one_sided_corners(
    t_src: np.ndarray, c_src: np.ndarray, t_dst: np.ndarray, side: str, cfg: TrackingConfig
) -> np.ndarray:
    """Corners (n_dst, 4, 2) at ``t_dst`` from the two frames before (``side="before"``:
    the last two at or before ``t_dst``) or after (``"after"``), linearly extrapolated.

    NaN where those frames are missing, more than ``max_interp_gap_s`` apart, or the
    nearer one is more than ``max_interp_gap_s`` from ``t_dst``.
    """
    n = len(t_src)
    if side == "before":
        i1 = np.searchsorted(t_src, t_dst, side="right") - 1
        i0 = i1 - 1
    else:
        i0 = np.searchsorted(t_src, t_dst, side="left")
        i1 = i0 + 1
    ok = (i0 >= 0) & (i1 < n) & (i1 >= 0) & (i0 < n)
    a, b = np.clip(i0, 0, n - 1), np.clip(i1, 0, n - 1)
    span = t_src[b] - t_src[a]
    near = np.minimum(np.abs(t_dst - t_src[a]), np.abs(t_dst - t_src[b]))
    ok &= (span > 0) & (span <= cfg.max_interp_gap_s) & (near <= cfg.max_interp_gap_s)
    w = (t_dst - t_src[a]) / np.where(span > 0, span, 1.0)
    out = c_src[a] + w[:, None, None] * (c_src[b] - c_src[a])
    out[~ok] = np.nan
    return out


def refit_lagged_frames(
    res: fz.FusionResult, va: fz.ViewData, alternatives: list[fz.ViewData], allowed: np.ndarray,
    cfg: TrackingConfig,
) -> tuple[fz.FusionResult, np.ndarray]:  # fmt: skip
    """Refit frames where the second camera's interpolated corners disagree with the first.

    The second camera's corners are interpolated linearly to the first camera's frame
    times. Where the angle changes faster than linearly between two of its frames (a
    step, a sharp turn) the interpolated corners show a pose the first camera never saw,
    and the fused frame's reprojection error jumps far above the session's. Such frames
    (error > :data:`REFIT_FACTOR` x the median of the measured frames and >
    :data:`REFIT_MIN_PX`) are refitted with the camera-to-camera rotation held, once per
    alternative set of corners (extrapolated from the two frames before, and from the
    two after: one of them lies on the first camera's side of the change); the best fit
    is kept when it halves the error and is below ``max_reproj_err_px``. A frame the
    fusion rejected for its error has no pose; its refit starts from the nearest fused
    pose on the side the alternative extrapolates from (:func:`neighbour_start`).

    Parameters
    ----------
    res : FusionResult
        After the reference fit (final ``R_ba``).
    va : ViewData
        First camera.
    alternatives : list of ViewData
        The second camera with other corners (NaN where none): ``[0]`` extrapolated from
        its frames before, ``[1]`` from its frames after.
    allowed : ndarray of bool, shape (n,)
        Frames that may be refitted (fusion statuses measured or rejected, valid times).

    Returns
    -------
    FusionResult, ndarray of int
        Updated result (status ``measured`` for accepted frames) and the accepted frames.
    """
    meas = res.status == fz.MEASURED
    if not meas.any():
        return res, np.zeros(0, dtype=int)
    thr = max(REFIT_FACTOR * float(np.nanmedian(res.rms_px[meas])), REFIT_MIN_PX)
    cand = np.flatnonzero(allowed & np.isfinite(res.rms_px) & (res.rms_px > thr) & va.ok)
    if cand.size == 0:
        return res, np.zeros(0, dtype=int)
    best = res.rms_px[cand].copy()
    Q, ta, tb = res.Q[cand].copy(), res.t_a[cand].copy(), res.t_b[cand].copy()
    cov = res.cov_rot[cand].copy()
    for side, vb in zip(("before", "after"), alternatives, strict=False):
        start = neighbour_start(res, side)
        k = np.flatnonzero(vb.ok[cand] & has_pose(start)[cand])
        if k.size == 0:
            continue
        idx = cand[k]
        A, B, q, a, b, cost = _refit_frames(start, va, vb, idx, cfg)
        rms = np.sqrt(cost / 16.0)
        better = rms < best[k]
        if better.any():
            kb = k[better]
            best[kb], Q[kb], ta[kb], tb[kb] = rms[better], q[better], a[better], b[better]
            cv = fz.rotation_covariance(q, a, b, res.R_ba, A, B)
            cov[kb] = cv[better]
    accept = (best < 0.5 * res.rms_px[cand]) & (best <= cfg.max_reproj_err_px)
    idx = cand[accept]
    if idx.size == 0:
        return res, idx
    newQ, rms_px, cen_a, cen_b = res.Q.copy(), res.rms_px.copy(), res.t_a.copy(), res.t_b.copy()
    cov_rot, status = res.cov_rot.copy(), res.status.copy()
    newQ[idx], cen_a[idx], cen_b[idx] = Q[accept], ta[accept], tb[accept]
    rms_px[idx], cov_rot[idx], status[idx] = best[accept], cov[accept], fz.MEASURED
    return replace(res, Q=newQ, rms_px=rms_px, t_a=cen_a, t_b=cen_b, cov_rot=cov_rot,
                   status=status), idx  # fmt: skip


def has_pose(res: fz.FusionResult) -> np.ndarray:
    """Frames (bool, shape (n,)) with a finite pose: ``Q``, ``t_a`` and ``t_b``."""
    has = np.isfinite(res.Q).all(axis=(1, 2)) & np.isfinite(res.t_a).all(axis=1)
    return has & np.isfinite(res.t_b).all(axis=1)


def neighbour_start(res: fz.FusionResult, side: str) -> fz.FusionResult:
    """``res`` with the pose (``Q``, ``t_a``, ``t_b``) of every frame that has none (a
    fused frame rejected for its reprojection error) taken from the nearest frame that
    has one on ``side`` ("before" or "after"): the start of a refit whose second-camera
    corners are extrapolated from that side."""
    has = has_pose(res)
    if has.all() or not has.any():
        return res
    n = len(has)
    idx = np.where(has, np.arange(n), -1 if side == "before" else n)
    if side == "before":
        src = np.maximum.accumulate(idx)
    else:
        src = np.minimum.accumulate(idx[::-1])[::-1]
    fill = ~has & (src >= 0) & (src < n)
    Q, ta, tb = res.Q.copy(), res.t_a.copy(), res.t_b.copy()
    Q[fill], ta[fill], tb[fill] = res.Q[src[fill]], res.t_a[src[fill]], res.t_b[src[fill]]
    return replace(res, Q=Q, t_a=ta, t_b=tb)


def _refit_frames(
    res: fz.FusionResult, va: fz.ViewData, vb: fz.ViewData, idx: np.ndarray,
    cfg: TrackingConfig,
):  # fmt: skip
    """Refit frames ``idx`` from views ``va``, ``vb`` (camera-to-camera rotation held),
    starting from the fused poses: ``(A, B, Q, t_a, t_b, cost)`` of :func:`tracking.fuse.joint_fit`."""
    A, B = fz._subset(va, idx), fz._subset(vb, idx)
    q, a, b, cost = fz.joint_fit(res.Q[idx], res.t_a[idx], res.t_b[idx], res.R_ba, A, B,
                                 cfg.iterations)  # fmt: skip
    return A, B, q, a, b, cost


#: a frame whose angles, fitted with the second camera's corners extrapolated from its
#: two frames before and from its two frames after, differ by more than this (deg, yaw or
#: pitch) is flagged ``ambiguous`` (:func:`flag_lagged_frames`)
LAGGED_SPREAD_DEG = 0.2
#: an alternative fit counts as possible when its cost is at most this many times the
#: median cost of that alternative over the session (~ the 99.5 % point of the cost's
#: chi-square spread)
LAGGED_COST_FACTOR = 3.0


@dataclass(frozen=True)
class LaggedCheck:
    """What :func:`lagged_check` found per frame (n frames).

    Attributes
    ----------
    spread_deg : ndarray, shape (n,)
        Timing uncertainty of the fused angles, deg (NaN outside the checked frames and
        where a side has no two frames; 0 where one alternative is the only possible pose).
    side : ndarray of int, shape (n,)
        The alternative (0: extrapolated from before, 1: from after) that the first
        camera leaves as the only possible pose, -1 elsewhere.
    Q, t_a, t_b, cov_rot : ndarray
        That alternative's fit (shapes as :class:`~i2ris_calib.tracking.fuse.FusionResult`),
        NaN where ``side`` is -1.
    """

    spread_deg: np.ndarray
    side: np.ndarray
    Q: np.ndarray
    t_a: np.ndarray
    t_b: np.ndarray
    cov_rot: np.ndarray


def lagged_check(
    res: fz.FusionResult, va: fz.ViewData, alternatives: list[fz.ViewData], w: np.ndarray,
    M: np.ndarray, frames: np.ndarray, cfg: TrackingConfig,
) -> LaggedCheck:  # fmt: skip
    """Per-frame uncertainty of the second camera's interpolation in time, and the
    frames where the first camera allows one side only.

    The second camera's corners at the first camera's frame time are interpolated
    between its frames before and after, at weight ``w`` (0: the frame before). The
    frame is refitted (camera-to-camera rotation held) with the second camera's corners
    extrapolated from its two frames before (``alternatives[0]``) and from its two frames
    after (``alternatives[1]``); ``d0``, ``d1`` are the largest yaw or pitch differences
    to the fused angles. Motion that is linear on either side of the interpolation
    interval makes that side's difference vanish (a change in a neighbouring interval
    does not count). A change of size ``S`` inside the interval (a step: the true angle
    there is either the value before or the value after) gives ``d0 = w S`` and
    ``d1 = (1 - w) S``; its size is estimated as ``S = min(d0 / w, d1 / (1 - w))`` and the
    interpolation is then off by up to ``max(w, 1 - w) S``: the spread. An alternative
    the first camera contradicts (cost above :data:`LAGGED_COST_FACTOR` times that
    alternative's median over ``frames``) is not a possible pose. When the spread exceeds
    :data:`LAGGED_SPREAD_DEG` (a step, not smooth motion) and one side is possible while
    the other was tested and is not, the step happened beyond the possible side's
    frames, so that side's fit is the frame's pose (``side``, spread 0); when neither is
    possible the interpolation stays (spread 0).

    Returns
    -------
    LaggedCheck
    """
    n = len(res.status)
    out = np.full(n, np.nan)
    side = np.full(n, -1)
    Q, ta, tb, cov = (np.full((n, *s), np.nan) for s in ((3, 3), (3,), (3,), (3, 3)))
    meas = res.status == fz.MEASURED
    if not meas.any() or frames.size == 0:
        return LaggedCheck(out, side, Q, ta, tb, cov)
    var = float(np.nanmedian(res.rms_px[meas])) ** 2  # corner noise variance (px^2)
    base = fz.relative_angles(res.Q[frames], M)[:, :2]
    d = np.full((2, n), np.nan)
    fits = []
    for s, vb in enumerate(alternatives):
        k = np.flatnonzero(vb.ok[frames] & va.ok[frames])
        if k.size == 0:
            fits.append(None)
            continue
        idx = frames[k]
        A, B, q, a, b, cost = _refit_frames(res, va, vb, idx, cfg)
        fits.append((idx, A, B, q, a, b))
        # possible: fits as well as this alternative usually fits on the session (its
        # extrapolated corners are noisier than the interpolated ones)
        possible = cost <= LAGGED_COST_FACTOR * max(float(np.nanmedian(cost)), 16.0 * var)
        dd = np.abs(fz.relative_angles(q, M)[:, :2] - base[k]).max(axis=1)
        d[s, idx] = np.where(possible, dd, np.inf)
    wc = np.clip(w, 1e-3, 1 - 1e-3)
    s0, s1 = d[0] / wc, d[1] / (1 - wc)
    size = np.where(np.isinf(s0), s1, np.where(np.isinf(s1), s0, np.minimum(s0, s1)))
    size = np.where(np.isinf(size), 0.0, size)  # neither side possible: interpolation only
    ok = np.isfinite(size)
    out[ok] = (np.maximum(wc, 1 - wc) * size)[ok]
    for s, fit in enumerate(fits):
        if fit is None:
            continue
        idx, A, B, q, a, b = fit
        # only where the interpolation would be flagged: on smooth curved motion the
        # longer extrapolation is the one the first camera rejects, and the interpolation
        # is then better than either side
        only = np.isfinite(d[s, idx]) & np.isinf(d[1 - s, idx]) & (out[idx] > LAGGED_SPREAD_DEG)
        if only.any():
            j = idx[only]
            side[j], out[j] = s, 0.0
            Q[j], ta[j], tb[j] = q[only], a[only], b[only]
            cv = fz.rotation_covariance(q, a, b, res.R_ba, A, B)
            cov[j] = cv[only]
    return LaggedCheck(out, side, Q, ta, tb, cov)


def adopt_lagged_alternatives(
    res: fz.FusionResult, check: LaggedCheck
) -> tuple[fz.FusionResult, np.ndarray]:
    """``res`` with the frames where :func:`lagged_check` left one possible side taking
    that side's pose, and those frames."""
    idx = np.flatnonzero(check.side >= 0)
    if idx.size == 0:
        return res, idx
    Q, t_a, t_b, cov = res.Q.copy(), res.t_a.copy(), res.t_b.copy(), res.cov_rot.copy()
    Q[idx], t_a[idx], t_b[idx] = check.Q[idx], check.t_a[idx], check.t_b[idx]
    cov[idx] = check.cov_rot[idx]
    return replace(res, Q=Q, t_a=t_a, t_b=t_b, cov_rot=cov), idx


def nearest_time(t_src: np.ndarray, t_dst: np.ndarray) -> np.ndarray:
    """Time of the frame of ``t_src`` (sorted) nearest to each of ``t_dst``."""
    j = np.clip(np.searchsorted(t_src, t_dst), 1, len(t_src) - 1)
    return np.where(
        np.abs(t_dst - t_src[j - 1]) <= np.abs(t_src[j] - t_dst), t_src[j - 1], t_src[j]
    )


def nearest_frame_gray(
    t_src: np.ndarray, gray_src: np.ndarray, t_dst: np.ndarray, cfg: TrackingConfig
) -> tuple[np.ndarray, np.ndarray]:
    """Mean grey level of the frame nearest to each of ``t_dst``, and that frame's time.

    Not interpolated: a frame's grey level is the light of its own exposure, which the
    sync stage reads as the lit fraction of that exposure at the frame's own time
    (``time_s_<camera>``). Interpolating it to another camera's frame times (5 ms apart,
    say) mixes two exposures and biases the LED edge times. NaN (both) where the nearest
    frame is more than ``max_interp_gap_s`` away.

    Returns
    -------
    gray, time_s : ndarray, shape (n_dst,)
    """
    j = np.clip(np.searchsorted(t_src, t_dst), 1, len(t_src) - 1)
    near = np.where(np.abs(t_dst - t_src[j - 1]) <= np.abs(t_src[j] - t_dst), j - 1, j)
    far = np.abs(t_src[near] - t_dst) > cfg.max_interp_gap_s
    gray = np.where(far, np.nan, np.asarray(gray_src, dtype=float)[near])
    return gray, np.where(far, np.nan, t_src[near])
