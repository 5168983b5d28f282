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

Angles are ``R_BT = M^T Q`` with ``M`` the mean ``Q`` over the reference window
(straight pose), as ZYX yaw/pitch/roll (:mod:`.geometry`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from i2ris_calib.tracking.geometry import euler_zyx_deg, mean_rotation, project, rodrigues

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
    steps = np.empty((n, 9))
    for _ in range(iterations):
        scale = np.maximum(np.abs(np.concatenate([ta[:, 2:3], tb[:, 2:3]], axis=1)), 1.0)
        steps[:, :3] = 1e-7
        steps[:, 3:6] = 1e-8 * scale[:, :1]
        steps[:, 6:9] = 1e-8 * scale[:, 1:]
        J = np.empty((n, 16, 9))
        for k in range(9):
            p = np.zeros((n, 9))
            p[:, k] = steps[:, k]
            rk = _residuals(*_apply(p, Q, ta, tb), R_ba, a, b)
            J[:, :, k] = (rk - r) / steps[:, k : k + 1]
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
    return FusionResult(Q, rms, status, R_ba, n_comp, n_cont, cen_a, cen_b)


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
