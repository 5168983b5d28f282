"""Two-camera rigid-cube fusion: the planar flip resolved, one tip rotation per frame.

Each camera sees one marker; alone, a near-orthographic view fixes the marker's
in-plane rotation well but its tilt only up to a mirror (the two IPPE solutions).
The cube is rigid and the cameras are fixed, so

1. the camera-to-camera rotation ``R_ba`` (camera b <- camera a) is constant: it is
   the consensus of the per-frame candidates ``Qb_j @ Qa_i^T`` (the right pairing
   agrees across frames, the mirrored ones wander), then refined by alternating
   with step 2 (a small bundle adjustment);
2. per frame, one rotation ``Q`` (tip -> camera a) and one cube position per camera
   are fitted to all 16 corner coordinates of both views (Levenberg-Marquardt,
   batched over frames), started from the two best-agreeing candidate pairs;
3. competing minima are resolved by cost, else by temporal continuity (forward
   and backward from unambiguous frames), else the frame is flagged ambiguous.

Angles are ``R_BT = M^T Q`` as ZYX yaw/pitch/roll (:mod:`.geometry`), ``M`` the
reference: the mean ``Q`` over the reference window (straight pose) fixes yaw =
pitch = 0; its roll is fitted over the whole session together with ``R_ba``
(:func:`fit_reference`, :func:`twist_free_fit`), because at the straight pose both
cameras see the twist about the tool axis only through foreshortening.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from i2ris_calib.tracking.geometry import (
    euler_zyx_deg,
    mean_rotation,
    project,
    rodrigues,
    rot_x,
    rot_y,
    rot_z,
    rotation_angle_deg,
)

MEASURED, NOT_FOUND, AMBIGUOUS, REJECTED = "measured", "not_found", "ambiguous", "rejected"


@dataclass(frozen=True)
class ViewData:
    """One camera's observations resampled to the fused frame times.

    Attributes
    ----------
    corners : ndarray (n, 4, 2)
        Undistorted corners (px), NaN where the marker was not measured.
    K : ndarray (3, 3)
    X_tip : ndarray (4, 3)
        The marker's corners in the tip frame (mm), same order as ``corners``.
    R_ct, t_ct : ndarray (n, 2, 3, 3), (n, 2, 3)
        Both IPPE candidates as tip -> camera rotation and cube centre, best first.
    """

    corners: np.ndarray
    K: np.ndarray
    X_tip: np.ndarray
    R_ct: np.ndarray
    t_ct: np.ndarray

    @property
    def ok(self) -> np.ndarray:
        """Frames with all four corners, shape (n,)."""
        return np.isfinite(self.corners).all(axis=(1, 2))


@dataclass(frozen=True)
class FusionResult:
    """Per-frame fused pose and quality (arrays over the n fused frames)."""

    Q: np.ndarray  # (n, 3, 3) tip -> camera a, NaN where not measured
    rms_px: np.ndarray  # (n,) RMS reprojection error over both views
    status: np.ndarray  # (n,) str
    R_ba: np.ndarray  # (3, 3) camera b <- camera a
    n_competing: int  # frames where two distinct minima were found
    n_by_continuity: int  # of those, resolved by temporal continuity
    t_a: np.ndarray | None = None  # (n, 3) cube centre in camera a (mm), NaN where not measured
    t_b: np.ndarray | None = None  # (n, 3) cube centre in camera b (mm), NaN where not measured
    cov_rot: np.ndarray | None = (
        None  # (n, 3, 3) covariance of Q's rotation vector (rad^2), camera a
    )


def _trace_cos(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """cos of the rotation angle between every pair (len(A), len(B))."""
    tr = A.reshape(len(A), 9) @ B.reshape(len(B), 9).T
    return (tr - 1.0) / 2.0


def camera_rotation_consensus(
    a: ViewData, b: ViewData, tol_deg: float = 1.5, max_frames: int = 400
) -> np.ndarray:
    """Robust initial ``R_ba`` from the candidate pairings of frames seen by both.

    Raises ValueError when no frame has both markers.
    """
    both = np.flatnonzero(a.ok & b.ok)
    if both.size == 0:
        raise ValueError("no frame shows both markers: cannot relate the two cameras")
    sub = both[np.linspace(0, both.size - 1, min(max_frames, both.size)).astype(int)]
    cands = np.einsum("njab,nicb->nijac", b.R_ct[sub], a.R_ct[sub]).reshape(-1, 3, 3)
    cos_tol = np.cos(np.radians(tol_deg))
    counts = (_trace_cos(cands, cands) > cos_tol).sum(axis=1)
    best = cands[int(np.argmax(counts))]
    inl = cands[_trace_cos(best[None], cands)[0] > cos_tol]
    return mean_rotation(inl)


def _residuals(Q, ta, tb, R_ba, a: ViewData, b: ViewData) -> np.ndarray:
    """Stacked reprojection residuals (n, 16) of both views (px)."""
    ra = project(a.K, Q, ta, a.X_tip) - a.corners
    rb = project(b.K, R_ba @ Q, tb, b.X_tip) - b.corners
    return np.concatenate([ra.reshape(-1, 8), rb.reshape(-1, 8)], axis=1)


def _apply(p: np.ndarray, Q, ta, tb):
    return rodrigues(p[:, :3]) @ Q, ta + p[:, 3:6], tb + p[:, 6:9]


def _jacobian(Q, ta, tb, R_ba, a: ViewData, b: ViewData, r: np.ndarray) -> np.ndarray:
    """Forward-difference Jacobian (n, 16, 9) of :func:`_residuals` at ``r`` (px per parameter).

    Parameters: rotation vector left-multiplying ``Q`` (rad, camera a), then the two
    cube positions (mm).
    """
    n = len(Q)
    scale = np.maximum(np.abs(np.concatenate([ta[:, 2:3], tb[:, 2:3]], axis=1)), 1.0)
    steps = np.empty((n, 9))
    steps[:, :3] = 1e-7
    steps[:, 3:6] = 1e-8 * scale[:, :1]
    steps[:, 6:9] = 1e-8 * scale[:, 1:]
    J = np.empty((n, 16, 9))
    for k in range(9):
        p = np.zeros((n, 9))
        p[:, k] = steps[:, k]
        rk = _residuals(*_apply(p, Q, ta, tb), R_ba, a, b)
        J[:, :, k] = (rk - r) / steps[:, k : k + 1]
    return J


def rotation_covariance(Q, ta, tb, R_ba, a: ViewData, b: ViewData) -> np.ndarray:
    """Covariance (n, 3, 3) of each frame's fitted rotation (rad^2, rotation vector in camera a).

    ``sigma^2 (J^T J)^-1`` restricted to the rotation block, with ``sigma^2`` the corner
    noise pooled over all frames (sum of squared residuals / (16 - 9) per frame).
    Frames with a singular normal matrix get infinite variances.
    """
    r = _residuals(Q, ta, tb, R_ba, a, b)
    J = _jacobian(Q, ta, tb, R_ba, a, b, r)
    dof = max(r.shape[0] * (16 - 9), 1)
    sigma2 = float(np.sum(r * r)) / dof
    A = np.einsum("nrk,nrl->nkl", J, J)
    out = np.full((len(Q), 3, 3), np.inf)
    ok = np.linalg.cond(A) < 1e14
    out[ok] = sigma2 * np.linalg.inv(A[ok])[:, :3, :3]
    return out


def joint_fit(Q, ta, tb, R_ba, a: ViewData, b: ViewData, iterations: int = 12):
    """Levenberg-Marquardt over (rotation, two cube positions), batched over frames.

    Parameters
    ----------
    Q : ndarray (n, 3, 3)   initial tip -> camera a rotations
    ta, tb : ndarray (n, 3) initial cube centres in camera a and b (mm)
    R_ba : ndarray (3, 3)
    a, b : ViewData restricted to the same n frames (all finite)

    Returns
    -------
    Q, ta, tb : refined, same shapes
    cost : ndarray (n,)  sum of squared residuals (px^2)
    """
    n = len(Q)
    lam = np.full(n, 1e-3)
    r = _residuals(Q, ta, tb, R_ba, a, b)
    cost = np.sum(r * r, axis=1)
    for _ in range(iterations):
        J = _jacobian(Q, ta, tb, R_ba, a, b, r)
        A = np.einsum("nrk,nrl->nkl", J, J)
        g = np.einsum("nrk,nr->nk", J, r)
        dA = np.einsum("nkk->nk", A)
        M = A + (lam[:, None] * dA + 1e-12)[:, :, None] * np.eye(9)
        delta = -np.linalg.solve(M, g[:, :, None])[:, :, 0]
        Qn, tan, tbn = _apply(delta, Q, ta, tb)
        rn = _residuals(Qn, tan, tbn, R_ba, a, b)
        cn = np.sum(rn * rn, axis=1)
        better = cn < cost
        Q = np.where(better[:, None, None], Qn, Q)
        ta = np.where(better[:, None], tan, ta)
        tb = np.where(better[:, None], tbn, tb)
        r = np.where(better[:, None], rn, r)
        cost = np.where(better, cn, cost)
        lam = np.where(better, lam * 0.3, lam * 10.0)
    return Q, ta, tb, cost


def refine_camera_rotation(
    R_ba, Q, ta, tb, a: ViewData, b: ViewData, iterations: int = 4
) -> np.ndarray:
    """Gauss-Newton on the 3 parameters of ``R_ba`` with the per-frame poses held."""
    for _ in range(iterations):
        r = _residuals(Q, ta, tb, R_ba, a, b).ravel()
        J = np.empty((r.size, 3))
        for k in range(3):
            w = np.zeros(3)
            w[k] = 1e-7
            J[:, k] = (_residuals(Q, ta, tb, rodrigues(w) @ R_ba, a, b).ravel() - r) / 1e-7
        d = -np.linalg.lstsq(J, r, rcond=None)[0]
        R_ba = rodrigues(d) @ R_ba
        if np.linalg.norm(d) < 1e-10:
            break
    return R_ba


def _subset(v: ViewData, idx: np.ndarray) -> ViewData:
    """The frames ``idx`` of a view."""
    return ViewData(v.corners[idx], v.K, v.X_tip, v.R_ct[idx], v.t_ct[idx])


def _starts(a: ViewData, b: ViewData, R_ba: np.ndarray):
    """Two starting points per frame from the two best-agreeing candidate pairs."""
    Qb_in_a = np.einsum("ac,njcd->njad", R_ba.T, b.R_ct)  # (n, 2, 3, 3)
    tr = np.einsum("niab,njab->nij", a.R_ct, Qb_in_a).reshape(-1, 4)
    order = np.argsort(-tr, axis=1)
    n = len(tr)
    out = []
    for rank in (0, 1):
        i, j = np.divmod(order[:, rank], 2)
        Qa = a.R_ct[np.arange(n), i]
        Qb = Qb_in_a[np.arange(n), j]
        U, _, Vt = np.linalg.svd(Qa + Qb)
        d = np.sign(np.linalg.det(U @ Vt))
        U[:, :, 2] *= d[:, None]
        Q0 = U @ Vt
        out.append((Q0, a.t_ct[np.arange(n), i], b.t_ct[np.arange(n), j]))
    return out


def fuse_views(a: ViewData, b: ViewData, times_s: np.ndarray, cfg) -> FusionResult:
    """Fused tip rotation per frame with status (see module doc).

    Parameters
    ----------
    a, b : ViewData over the same n fused frames
    times_s : ndarray (n,) frame times (s), increasing
    cfg : TrackingConfig
    """
    n = len(times_s)
    both = np.flatnonzero(a.ok & b.ok)
    Q = np.full((n, 3, 3), np.nan)
    rms = np.full(n, np.nan)
    status = np.full(n, NOT_FOUND, dtype=object)
    R_ba = camera_rotation_consensus(a, b)
    A, B = _subset(a, both), _subset(b, both)
    sols = [joint_fit(*s, R_ba, A, B, cfg.iterations) for s in _starts(A, B, R_ba)]
    Qs, ta, tb, cost, n_comp, n_cont = _choose(sols, times_s[both], cfg)
    for _ in range(cfg.extrinsic_rounds):
        good = np.isfinite(cost)
        R_ba = refine_camera_rotation(
            R_ba, Qs[good], ta[good], tb[good], _subset(A, good), _subset(B, good)
        )
        Qs[good], ta[good], tb[good], cost[good] = joint_fit(
            Qs[good], ta[good], tb[good], R_ba, _subset(A, good), _subset(B, good), cfg.iterations
        )
    Q[both] = Qs
    cov = np.full((n, 3, 3), np.nan)
    good = np.isfinite(cost)
    if good.any():
        cov[both[good]] = rotation_covariance(
            Qs[good], ta[good], tb[good], R_ba, _subset(A, good), _subset(B, good)
        )
    cen_a = np.full((n, 3), np.nan)
    cen_b = np.full((n, 3), np.nan)
    cen_a[both], cen_b[both] = ta, tb
    rms[both] = np.sqrt(cost / 16.0)
    st = np.where(np.isfinite(cost), MEASURED, AMBIGUOUS).astype(object)
    st[np.isfinite(cost) & (np.sqrt(cost / 16.0) > cfg.max_reproj_err_px)] = REJECTED
    status[both] = st
    Q[status != MEASURED] = np.nan
    cen_a[status != MEASURED] = np.nan
    cen_b[status != MEASURED] = np.nan
    cov[status != MEASURED] = np.nan
    return FusionResult(Q, rms, status, R_ba, n_comp, n_cont, cen_a, cen_b, cov)


def _choose(sols, t: np.ndarray, cfg):
    """Pick one of two minima per frame: distinct + clear cost winner, else continuity.

    Frames that stay unresolved get cost NaN (flagged ambiguous by the caller).
    """
    (Q1, a1, b1, c1), (Q2, a2, b2, c2) = sols
    n = len(t)
    dist = np.degrees(np.arccos(np.clip((np.einsum("nab,nab->n", Q1, Q2) - 1) / 2, -1, 1)))
    lo, hi = np.minimum(c1, c2), np.maximum(c1, c2)
    same = dist < cfg.ambiguity_deg
    clear = same | (hi > cfg.ambiguity_ratio * np.maximum(lo, 1e-12))
    pick = np.where(c2 < c1, 1, 0)
    resolved = clear.copy()
    n_comp = int((~same).sum())
    n_cont = 0
    cands = np.stack([Q1, Q2], axis=1)
    for order in (range(n), range(n - 1, -1, -1)):
        last = None
        for k in order:
            if resolved[k]:
                last = k
                continue
            if last is None or abs(t[k] - t[last]) > cfg.continuity_gap_s:
                continue
            ref = cands[last, pick[last]]
            d = [
                np.degrees(np.arccos(np.clip((np.sum(ref * cands[k, m]) - 1) / 2, -1, 1)))
                for m in (0, 1)
            ]
            m = int(np.argmin(d))
            if d[m] <= cfg.max_step_deg and d[1 - m] > d[m] + cfg.ambiguity_deg:
                pick[k] = m
                resolved[k] = True
                n_cont += 1
                last = k
    sel = pick.astype(bool)
    Q = np.where(sel[:, None, None], Q2, Q1)
    ta = np.where(sel[:, None], a2, a1)
    tb = np.where(sel[:, None], b2, b1)
    cost = np.where(sel, c2, c1).astype(float)
    cost[~resolved] = np.nan
    return Q, ta, tb, cost, n_comp, n_cont


def reference_rotation(Q: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Mean tip -> camera rotation ``M`` over the reference frames ``mask`` (n,) bool."""
    sel = mask & np.isfinite(Q).all(axis=(1, 2))
    if not sel.any():
        raise ValueError("no measured frame in the reference window")
    return mean_rotation(Q[sel])


def relative_angles(Q: np.ndarray, M: np.ndarray) -> np.ndarray:
    """Yaw, pitch, roll (n, 3) deg of ``R_BT = M^T Q`` (NaN rows stay NaN)."""
    return euler_zyx_deg(M.T @ Q)


@dataclass(frozen=True)
class ReferenceFit:
    """The reference rotation, and how its roll (twist about the tool axis) was set.

    Attributes
    ----------
    M : ndarray (3, 3)
        Tip -> camera a rotation of the straight reference pose.
    R_ba : ndarray (3, 3)
        Camera b <- camera a rotation fitted together with ``M``.
    method : str
        ``session`` (joint fit over the whole session) or ``window`` (mean over the
        reference window only).
    roll_correction_deg : float
        Roll applied to the window mean: ``M = M_window Rx(-roll_correction)`` (deg).
    roll_sd_deg : float
        Standard uncertainty of the reference roll (deg): for ``session`` the largest of
        the least-squares figure, the block jackknife and half the disagreement between
        the yaw-bent and the pitch-bent frames (:func:`_axis_split_sd`), for ``window`` the window
        mean's standard error from the per-frame covariances (noise only; optimistic
        when the faces are square to their cameras).
    camera_rotation_change_deg : float
        Angle between ``R_ba`` before and after the joint fit (deg).
    frames : int
        Frames in the joint fit.
    window_frames : int
        Measured frames in the reference window.
    """

    M: np.ndarray
    R_ba: np.ndarray
    method: str
    roll_correction_deg: float
    roll_sd_deg: float
    camera_rotation_change_deg: float
    frames: int
    window_frames: int


def _rz_ry(y: np.ndarray, p: np.ndarray) -> np.ndarray:
    """``Rz(y) Ry(p)`` batched, (n, 3, 3), angles in rad."""
    cy, sy, cp, sp = np.cos(y), np.sin(y), np.cos(p), np.sin(p)
    z = np.zeros_like(y)
    return np.stack(
        [
            np.stack([cy * cp, -sy, cy * sp], -1),
            np.stack([sy * cp, cy, sy * sp], -1),
            np.stack([-sp, z, cp], -1),
        ],
        -2,
    )


def _twist_free_residuals(g, L, M0, R_ba0, a: ViewData, b: ViewData) -> np.ndarray:
    """Residuals (n, 16) px of the twist-free model.

    ``g = (e, w_ba)``: reference roll (rad) and camera-rotation update (rotation vector);
    ``L`` (n, 8): yaw, pitch (rad), cube centre in camera a and b (mm).
    """
    M = M0 @ rot_x(-g[0])
    Q = M @ _rz_ry(L[:, 0], L[:, 1])
    return _residuals(Q, L[:, 2:5], L[:, 5:8], rodrigues(g[1:4]) @ R_ba0, a, b)


def twist_free_fit(
    Q,
    ta,
    tb,
    R_ba,
    M0,
    a: ViewData,
    b: ViewData,
    times_s,
    prior_sd_rad=np.inf,
    iterations=15,
    blocks=10,
):
    """Joint fit of the reference roll, the camera-to-camera rotation and per-frame poses.

    Model: the tip does not twist about its own axis, ``Q_t = M0 Rx(-e) Rz(yaw_t)
    Ry(pitch_t)``; camera b sees ``R_ba Q_t``. The reference roll ``e`` and the
    rotation of camera b about the axis both cameras see sideways are each seen only
    through foreshortening at the straight pose; once the tip bends, the tool axis
    turns towards a viewing direction, the twist becomes partly an in-plane rotation
    in that view, and both are determined by all the bent frames together.
    Levenberg-Marquardt on 4 global + 8 per-frame parameters (Schur complement).

    Parameters
    ----------
    Q : ndarray (n, 3, 3)
        Free-fit tip -> camera a rotations (start), all finite.
    ta, tb : ndarray (n, 3)
        Cube centres in camera a and b (mm).
    R_ba : ndarray (3, 3)
    M0 : ndarray (3, 3)
        Reference from the window mean (fixes yaw = pitch = 0).
    a, b : ViewData over the same n frames.
    times_s : ndarray (n,)
        Frame times (s), for the block jackknife.
    prior_sd_rad : float
        Uncertainty of the window mean's roll (rad): the window's evidence ``e ~ N(0,
        prior_sd^2)`` is combined with the session's (inf, the default: the session
        alone; :func:`fit_reference` uses that because the window's noise-only figure
        is overconfident where the roll is seen to second order only: 0.43 deg off
        with a stated 0.14 deg on aligned rendered cameras).

    Returns
    -------
    e_deg : float
        Reference roll correction (deg).
    sd_deg : float
        Its standard uncertainty (deg): max of least-squares, block jackknife and the
        yaw/pitch split (:func:`_axis_split_sd`).
    R_ba : ndarray (3, 3)
        Refitted camera-to-camera rotation.
    """
    n = len(Q)
    ang = euler_zyx_deg(M0.T @ Q)
    L = np.concatenate([np.radians(ang[:, :2]), ta, tb], axis=1)
    g = np.zeros(4)
    r = _twist_free_residuals(g, L, M0, R_ba, a, b)
    # prior weight in px^2 / rad^2: corner variance / prior variance
    wp = float(np.sum(r * r)) / max(n * 8 - 4, 1) / prior_sd_rad**2
    scale = np.maximum(np.abs(np.concatenate([ta[:, 2:3], tb[:, 2:3]], axis=1)), 1.0)
    hl = np.concatenate([np.full((n, 2), 1e-7), 1e-8 * np.repeat(scale, 3, axis=1)], axis=1)
    g, L, cost, normal = _twist_free_solution(g, L, r, wp, hl, M0, R_ba, a, b, iterations)
    sd = _roll_sd(normal, cost, n, times_s, L[:, :2], blocks)
    return float(np.degrees(g[0])), float(np.degrees(sd)), rodrigues(g[1:4]) @ R_ba


@dataclass(frozen=True)
class _ReducedNormal:
    """Normal equations of the global parameters ``g`` with the per-frame ones
    eliminated (Schur complement), as :func:`_twist_free_solution` last formed them."""

    S: np.ndarray  # (4, 4) over all frames, the prior's term included
    rhs: np.ndarray  # (4,) gradient, the prior's term included
    Sn: np.ndarray  # (n, 4, 4) per-frame terms of S
    rn: np.ndarray  # (n, 4) per-frame terms of rhs


def _twist_free_jacobians(g, L, r, hl, M0, R_ba, a: ViewData, b: ViewData):
    """Forward-difference Jacobians of :func:`_twist_free_residuals` at ``r``: per-frame
    parameters ``Jl`` (n, 16, 8) with steps ``hl`` (n, 8), global ones ``Jg`` (n, 16, 4)."""
    n = len(L)
    Jl = np.empty((n, 16, 8))
    for k in range(8):
        d = np.zeros((n, 8))
        d[:, k] = hl[:, k]
        Jl[:, :, k] = (_twist_free_residuals(g, L + d, M0, R_ba, a, b) - r) / hl[:, k : k + 1]
    Jg = np.empty((n, 16, 4))
    for k in range(4):
        d = np.zeros(4)
        d[k] = 1e-7
        Jg[:, :, k] = (_twist_free_residuals(g + d, L, M0, R_ba, a, b) - r) / 1e-7
    return Jl, Jg


def _twist_free_step(Jl, Jg, r, g, wp, lam):
    """One damped Gauss-Newton step ``(dg, dL)`` of the global (4,) and per-frame (n, 8)
    parameters, and the reduced normal equations (:class:`_ReducedNormal`) it solved."""
    All = np.einsum("nrk,nrl->nkl", Jl, Jl)
    Alg = np.einsum("nrk,nrl->nkl", Jl, Jg)
    bl = np.einsum("nrk,nr->nk", Jl, r)
    Aggn = np.einsum("nrk,nrl->nkl", Jg, Jg)
    bgn = np.einsum("nrk,nr->nk", Jg, r)
    Ainv = np.linalg.inv(All + (lam * np.einsum("nkk->nk", All) + 1e-12)[:, :, None] * np.eye(8))
    X = np.einsum("nlk,nlm->nkm", Alg, Ainv)  # Alg^T Ainv, (n, 4, 8)
    Sn = Aggn - np.einsum("nkm,nmj->nkj", X, Alg)
    rn = bgn - np.einsum("nkm,nm->nk", X, bl)
    S, rhs = Sn.sum(0), rn.sum(0)
    S[0, 0] += wp
    rhs[0] += wp * g[0]
    dg = -np.linalg.solve(S + lam * np.diag(np.diag(S)), rhs)
    dL = -np.einsum("nkl,nl->nk", Ainv, bl + Alg @ dg)
    return dg, dL, _ReducedNormal(S, rhs, Sn, rn)


def _twist_free_solution(g, L, r, wp, hl, M0, R_ba, a: ViewData, b: ViewData, iterations):
    """Levenberg-Marquardt from ``g`` (4,), ``L`` (n, 8) with residuals ``r``.

    Returns
    -------
    g, L : the solution
    cost : float
        Sum of squared residuals (px^2), the prior's term not included.
    normal : _ReducedNormal
        From the last iteration.
    """
    cost = float(np.sum(r * r))
    lam = 1e-3
    for _ in range(iterations):
        Jl, Jg = _twist_free_jacobians(g, L, r, hl, M0, R_ba, a, b)
        dg, dL, normal = _twist_free_step(Jl, Jg, r, g, wp, lam)
        r_new = _twist_free_residuals(g + dg, L + dL, M0, R_ba, a, b)
        c_new = float(np.sum(r_new * r_new)) + wp * (g[0] + dg[0]) ** 2
        if c_new < cost + wp * g[0] ** 2:
            done = cost + wp * g[0] ** 2 - c_new < 1e-9 * cost
            g, L, r = g + dg, L + dL, r_new
            cost = c_new - wp * g[0] ** 2
            lam *= 0.3
            if done:
                break
        else:
            lam *= 10.0
    return g, L, cost, normal


def _roll_sd(normal: _ReducedNormal, cost: float, n: int, times_s, yp, blocks: int) -> float:
    """Standard uncertainty (rad) of the reference roll at the solution: the largest of
    the least-squares figure ``sigma^2 S^-1``, a block jackknife of one Gauss-Newton step
    over ``blocks`` time blocks, and :func:`_axis_split_sd` (``yp``: yaw, pitch (n, 2) rad)."""
    S, rhs, Sn, rn = normal.S, normal.rhs, normal.Sn, normal.rn
    sigma2 = cost / max(n * 8 - 4, 1)
    sd_ls = float(np.sqrt(sigma2 * np.linalg.inv(S)[0, 0]))
    edges = np.quantile(times_s, np.linspace(0, 1, blocks + 1))
    blk = np.clip(np.searchsorted(edges, times_s, side="right") - 1, 0, blocks - 1)
    est = np.array([-np.linalg.solve(S - Sn[blk == k].sum(0), rhs - rn[blk == k].sum(0))[0]
                    for k in range(blocks)])  # fmt: skip
    sd_jk = float(np.sqrt((blocks - 1) / blocks * np.sum((est - est.mean()) ** 2)))
    sd_axes = _axis_split_sd(S, rhs, Sn, rn, yp)
    return max(sd_ls, sd_jk, sd_axes)


def _axis_split_sd(S, rhs, Sn, rn, yp, bent_rad=np.radians(10.0), min_frames=30) -> float:
    """Systematic part of the roll's uncertainty (rad): yaw-bent vs pitch-bent frames.

    The roll is seen through the yaw-bent frames (top face turning) and through the
    pitch-bent frames (side face turning) independently; under the twist-free model
    both give the same roll. Each estimate (one Gauss-Newton step from the joint
    solution, from the near-straight frames plus the frames bent mainly about one
    axis) carries the pose-dependent corner biases of its own strongly tilted face;
    half their difference is a floor for the joint roll's uncertainty. 0 when either
    axis has fewer than ``min_frames`` bent frames.

    Parameters
    ----------
    S, rhs : ndarray (4, 4), (4,)
        Reduced normal matrix and gradient of the global parameters (all frames).
    Sn, rn : ndarray (n, 4, 4), (n, 4)
        Their per-frame terms.
    yp : ndarray (n, 2)
        Yaw and pitch per frame (rad).
    """
    a = np.abs(yp)
    straight = a.max(axis=1) <= bent_rad
    by_yaw = ~straight & (a[:, 0] >= a[:, 1])
    by_pitch = ~straight & (a[:, 0] < a[:, 1])
    if by_yaw.sum() < min_frames or by_pitch.sum() < min_frames:
        return 0.0
    prior = S - Sn.sum(0)  # the prior's term (zero without one)
    est = []
    for sel in (straight | by_yaw, straight | by_pitch):
        try:
            est.append(-np.linalg.solve(prior + Sn[sel].sum(0), rhs - rn[~sel].sum(0))[0])
        except np.linalg.LinAlgError:
            return 0.0
    return float(abs(est[0] - est[1]) / 2.0)


def fit_reference(res: FusionResult, a: ViewData, b: ViewData, window: np.ndarray,
                  times_s: np.ndarray, cfg, max_frames: int = 4000, max_sd_deg: float = 0.05,
                  min_bent_frames: int = 30, bent_deg: float = 10.0):  # fmt: skip
    """The reference rotation (and refitted per-frame poses) from the whole session.

    ``cfg.reference_roll == "window"``: the mean over the measured window frames.
    ``"session"``: :func:`twist_free_fit` on up to ``max_frames`` measured frames
    (evenly spread) gives the reference roll and ``R_ba``; the free per-frame fits
    are then redone with that ``R_ba`` (so the per-frame angles do not assume the
    twist-free model). Falls back to the window (the tip bent too little) with fewer
    than ``min_bent_frames`` measured frames bent beyond ``bent_deg`` about either
    axis, or when the roll's uncertainty exceeds ``max_sd_deg``.

    Returns
    -------
    ReferenceFit, FusionResult (updated Q, rms_px, R_ba, centres and covariances)

    Raises
    ------
    ValueError
        No measured frame in the reference window.
    """
    meas = res.status == MEASURED
    M0 = reference_rotation(res.Q, window & meas)
    n_win = int((window & meas).sum())
    # the window mean's roll uncertainty: each frame's variance about the tool axis
    x = M0[:, 0]
    var = np.einsum("i,nij,j->n", x, res.cov_rot[window & meas], x)
    var = var[np.isfinite(var) & (var > 0)]
    win_sd = float(np.sqrt(1.0 / np.sum(1.0 / var))) if var.size else np.inf
    win = ReferenceFit(M0, res.R_ba, "window", 0.0, float(np.degrees(win_sd)), 0.0, 0, n_win)
    idx = np.flatnonzero(meas)
    bent = np.abs(euler_zyx_deg(M0.T @ res.Q[idx])[:, :2]).max(axis=1) > bent_deg
    if cfg.reference_roll == "window" or bent.sum() < min_bent_frames:
        return win, res
    sub = idx[np.linspace(0, idx.size - 1, min(max_frames, idx.size)).astype(int)]
    A, B = _subset(a, sub), _subset(b, sub)
    try:
        e, sd, R_ba = twist_free_fit(res.Q[sub], res.t_a[sub], res.t_b[sub], res.R_ba, M0, A, B,
                                     times_s[sub])  # fmt: skip
    except np.linalg.LinAlgError:
        return win, res
    if not (np.isfinite(sd) and sd <= max_sd_deg):
        return win, res
    A, B = _subset(a, idx), _subset(b, idx)
    Q, ta, tb, cost = joint_fit(res.Q[idx], res.t_a[idx], res.t_b[idx], R_ba, A, B, cfg.iterations)
    newQ, rms = res.Q.copy(), res.rms_px.copy()
    cen_a, cen_b, cov = res.t_a.copy(), res.t_b.copy(), res.cov_rot.copy()
    newQ[idx], cen_a[idx], cen_b[idx], rms[idx] = Q, ta, tb, np.sqrt(cost / 16.0)
    cov[idx] = rotation_covariance(Q, ta, tb, R_ba, A, B)
    change = float(rotation_angle_deg(res.R_ba, R_ba))
    # re-zero yaw and pitch on the window (the refit moves the straight pose's distal axis)
    M = M0 @ rot_x(-np.radians(e))
    yp = euler_zyx_deg(M.T @ newQ[window & meas]).mean(axis=0)
    M = M @ rot_z(np.radians(yp[0])) @ rot_y(np.radians(yp[1]))
    ref = ReferenceFit(M, R_ba, "session", e, sd, change, int(sub.size), n_win)
    return ref, replace(res, Q=newQ, rms_px=rms, R_ba=R_ba, t_a=cen_a, t_b=cen_b, cov_rot=cov)


def common_axis_positions(t_a: np.ndarray, t_b: np.ndarray, R_ba: np.ndarray) -> np.ndarray:
    """Cube centre along the one axis both cameras see sideways, shape (n,) mm.

    Both cameras measure the cube centre's position across their viewing direction
    well (the depth poorly). The axis ``u`` perpendicular to both viewing directions
    is seen across by both, so for a rigid two-camera rig ``u_b . t_b - u_a . t_a`` is
    one constant (the cameras' separation along ``u``) in every frame. The fitted
    centres are the marker centres minus the face offset ``cube/2 * normal``: with the
    ``view`` labels swapped the offsets go to the wrong faces and this quantity moves
    by up to the cube size as the tip turns.

    Parameters
    ----------
    t_a, t_b : ndarray (n, 3)
        Cube centre in camera a and camera b (mm), NaN where not measured.
    R_ba : ndarray (3, 3)
        Rotation camera b <- camera a.

    Returns
    -------
    ndarray (n,)
        ``u_b . t_b - u_a . t_a`` (mm); NaN where either centre is missing.
    """
    z = np.array([0.0, 0.0, 1.0])
    u_a = np.cross(z, R_ba.T @ z)
    norm = np.linalg.norm(u_a)
    if norm < 1e-6:  # parallel cameras: no common sideways axis
        return np.full(len(t_a), np.nan)
    u_a /= norm
    return t_b @ (R_ba @ u_a) - t_a @ u_a


def rigid_rig_spread_mm(res: FusionResult) -> float:
    """Standard deviation (mm) of :func:`common_axis_positions` over measured frames.

    Near the corner-noise level (micrometres) when the fused poses describe one rigid
    cube seen by two fixed cameras; NaN with fewer than 10 measured frames.
    """
    d = common_axis_positions(res.t_a, res.t_b, res.R_ba)
    d = d[np.isfinite(d)]
    return float(np.std(d)) if d.size >= 10 else float("nan")


#: A labelling is told apart when its rigid-rig spread exceeds this fraction of the cube
#: edge and this multiple of the other labelling's spread.
SWAP_MIN_SPREAD_CUBE = 0.03
SWAP_RATIO = 4.0


def view_verdict(as_labelled_mm: float, swapped_mm: float, cube_size_mm: float) -> str:
    """``swapped``, ``consistent`` or ``inconclusive`` from the two rigid-rig spreads.

    Parameters
    ----------
    as_labelled_mm, swapped_mm : float
        :func:`rigid_rig_spread_mm` with the ``view`` labels as given and swapped (mm).
    cube_size_mm : float

    Returns
    -------
    str
        ``swapped`` when the labels as given spread by more than 3 % of the cube edge
        and 4 times the swapped labels; ``consistent`` in the mirror case; else
        ``inconclusive`` (the tip turned too little, or NaN spreads).
    """
    if not (np.isfinite(as_labelled_mm) and np.isfinite(swapped_mm)):
        return "inconclusive"
    least, floor = SWAP_MIN_SPREAD_CUBE * cube_size_mm, 1e-3 * cube_size_mm
    if as_labelled_mm > least and as_labelled_mm > SWAP_RATIO * max(swapped_mm, floor):
        return "swapped"
    if swapped_mm > least and swapped_mm > SWAP_RATIO * max(as_labelled_mm, floor):
        return "consistent"
    return "inconclusive"
