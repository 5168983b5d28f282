"""A second camera triggered later than the first: frames next to a step of the angle
that the interpolation cannot place are flagged, smooth motion is not."""

from __future__ import annotations

import numpy as np
import pytest

from i2ris_calib.simulation.presets import preset_config
from i2ris_calib.simulation.scene import make_cameras
from i2ris_calib.tracking import fuse as fz
from i2ris_calib.tracking.config import TrackingConfig
from i2ris_calib.tracking.geometry import face_corner_points_tip, project, tip_rotation
from i2ris_calib.tracking.pose import ippe_candidates, tip_pose_from_marker
from i2ris_calib.tracking.timing import (
    LAGGED_SPREAD_DEG,
    adopt_lagged_alternatives,
    interp_weight,
    lagged_check,
    one_sided_corners,
    refit_lagged_frames,
    resample_corners,
)

NOISE_PX = 0.02
FPS, LAG_S = 30.0, 0.005
STEP_FRAME = 100  # the true pitch steps by STEP_DEG 2 ms after this top frame


def _truth(t: np.ndarray, yaw_step_deg: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Yaw and pitch (deg) at times ``t``: straight 1 s, smooth excursions to +-40 deg,
    and a pitch step near the straight pose (as at an EGPI flag point); with
    ``yaw_step_deg`` a yaw step at the same time instead."""
    yaw = 20 * (1 - np.cos(2 * np.pi * np.clip(t - 1.0, 0, 3.0) / 3.0))
    yaw = yaw - 18 * (1 - np.cos(2 * np.pi * np.clip(t - 4.0, 0, 3.0) / 3.0))
    pitch = -17 * (1 - np.cos(2 * np.pi * np.clip(t - 5.5, 0, 3.0) / 3.0))
    after = t > STEP_FRAME / FPS + 0.002
    if yaw_step_deg:
        return yaw + np.where(after, yaw_step_deg, 0.0), pitch
    return yaw, pitch + np.where(after, -STEP_DEG, 0.0)


STEP_DEG = 1.0


def _corners(cfg, cam, yaw, pitch, rng):
    X = face_corner_points_tip(cam.view, cfg.marker_size_mm, cfg.cube_size_mm)
    c = np.array([
        project(cam.K, cam.R_cb @ tip_rotation(y, p),
                cam.R_cb @ (tip_rotation(y, p) @ np.array([cfg.pivot_mm, 0, 0])) + cam.t_cb, X)
        for y, p in zip(yaw, pitch, strict=True)
    ])  # fmt: skip
    return c + rng.normal(0, NOISE_PX, c.shape), X


def _view(c, cam, cfg, X) -> fz.ViewData:
    n = len(c)
    R, t = np.full((n, 2, 3, 3), np.nan), np.full((n, 2, 3), np.nan)
    for k in np.flatnonzero(np.isfinite(c).all(axis=(1, 2))):
        Rm, tm, _ = ippe_candidates(c[k], cam.K, cfg.marker_size_mm)
        for j in range(2):
            R[k, j], t[k, j] = tip_pose_from_marker(cam.view, Rm[j], tm[j], cfg.cube_size_mm)
    return fz.ViewData(c, cam.K, X, R, t)


@pytest.mark.parametrize("seed", [1, 2])
def test_frame_next_to_a_step_seen_by_the_lagged_camera_only_is_flagged(seed):
    cfg = preset_config("ci", misalignment_deg=0.0, pivot_mm=0.0, marker_size_px=110.0)
    cams = make_cameras(cfg, np.random.default_rng(seed))
    rng = np.random.default_rng(50 + seed)
    tc = TrackingConfig()
    t = np.arange(int(9.5 * FPS)) / FPS  # top frame times
    ts = t + LAG_S  # side frames, 5 ms late: side frame STEP_FRAME already shows the step
    ca, Xa = _corners(cfg, cams[0], *_truth(t), rng)
    cs, Xb = _corners(cfg, cams[1], *_truth(ts), rng)
    va = _view(ca, cams[0], cfg, Xa)
    vb = _view(resample_corners(ts, cs, t, tc), cams[1], cfg, Xb)
    ref, res = fz.fit_reference(fz.fuse_views(va, vb, t, tc), va, vb, t < 0.8, t, tc)
    M = ref.M  # session roll: no cross-talk at +-40 deg
    err = np.abs(fz.relative_angles(res.Q, M)[:, :2] - np.column_stack(_truth(t))).max(axis=1)
    frames = np.flatnonzero(res.status == fz.MEASURED)
    alts = [_view(one_sided_corners(ts, cs, t, side, tc), cams[1], cfg, Xb)
            for side in ("before", "after")]  # fmt: skip
    spread = lagged_check(res, va, alts, interp_weight(ts, t), M, frames, tc).spread_deg
    # the interpolated side corners put most of the step into the frame before it,
    # which the top camera cannot contradict: a wrong angle ...
    assert err[STEP_FRAME] > 0.3, err[STEP_FRAME]
    # ... that the spread of the one-sided fits flags
    assert spread[STEP_FRAME] > LAGGED_SPREAD_DEG
    flagged = np.flatnonzero(np.nan_to_num(spread) > LAGGED_SPREAD_DEG)
    # and only the frames next to the step, not the smooth +-40 deg excursions
    assert set(flagged) <= set(range(STEP_FRAME - 2, STEP_FRAME + 3)), flagged
    # every frame not flagged is right to the noise
    keep = np.setdiff1d(frames, flagged)
    bad = keep[err[keep] > 0.1]
    assert bad.size == 0, (bad, err[bad], spread[bad], res.rms_px[bad], np.median(res.rms_px))


def test_frame_rejected_across_a_large_step_is_refitted_from_the_side_it_belongs_to():
    """A 12 deg yaw step 2 ms after a top frame (110 px markers: 6 deg stays below the 1 px limit): the side frame 5 ms after it already
    shows the step, so the interpolated side corners mix the two poses, the fusion
    rejects the frame (reprojection error) and it has no pose to refit from. The refit
    starts from the neighbouring fused poses and the top camera picks the side
    extrapolated from the frames before: measured, right to the noise."""
    cfg = preset_config("ci", misalignment_deg=0.0, pivot_mm=0.0, marker_size_px=110.0)
    cams = make_cameras(cfg, np.random.default_rng(3))
    rng = np.random.default_rng(53)
    tc = TrackingConfig()
    t = np.arange(int(4.0 * FPS)) / FPS
    ts = t + LAG_S
    ca, Xa = _corners(cfg, cams[0], *_truth(t, 12.0), rng)
    cs, Xb = _corners(cfg, cams[1], *_truth(ts, 12.0), rng)
    va = _view(ca, cams[0], cfg, Xa)
    vb = _view(resample_corners(ts, cs, t, tc), cams[1], cfg, Xb)
    ref, res = fz.fit_reference(fz.fuse_views(va, vb, t, tc), va, vb, t < 0.8, t, tc)
    assert res.status[STEP_FRAME] == fz.REJECTED  # what the refit must repair
    assert not np.isfinite(res.Q[STEP_FRAME]).any()
    alts = [_view(one_sided_corners(ts, cs, t, side, tc), cams[1], cfg, Xb)
            for side in ("before", "after")]  # fmt: skip
    allowed = np.isin(res.status, (fz.MEASURED, fz.REJECTED))
    out, idx = refit_lagged_frames(res, va, alts, allowed, tc)
    assert STEP_FRAME in idx and out.status[STEP_FRAME] == fz.MEASURED
    err = np.abs(
        fz.relative_angles(out.Q[idx], ref.M)[:, :2] - np.column_stack(_truth(t[idx], 12.0))
    )
    assert err.max() < 0.1, err


def test_resample_corners_extrapolates_half_a_frame_beyond_the_other_camera():
    """The first top frame precedes the first side frame by 5 ms (of 33): the side
    corners there are extrapolated from its first two frames (exact for linear motion);
    a frame more than half an interval beyond the side frames stays NaN."""
    tc = TrackingConfig()
    ts = np.arange(10) / FPS + LAG_S
    c = np.repeat((100.0 + 30.0 * ts)[:, None, None], 4, axis=1).repeat(2, axis=2)
    t = np.array([0.0, ts[-1] + 0.01, -0.02, ts[-1] + 0.02])
    out = resample_corners(ts, c, t, tc)
    np.testing.assert_allclose(out[:2, 0, 0], 100.0 + 30.0 * t[:2])
    assert np.isnan(out[2:]).all()


def test_step_the_first_camera_sees_out_of_plane_takes_the_possible_side():
    """A 1 deg pitch step 2 ms after a top frame while pitch is near -34 deg: the top
    camera sees pitch out of its image plane, but at that tilt well enough to contradict
    the side extrapolated from the frames after (the post-step pose the 5 ms late side
    frame already shows). The frame takes the before-side fit (``side`` 0, spread 0) and
    is right to the noise, where the interpolation was off by most of the step; smooth
    frames are not touched."""
    cfg = preset_config("ci", misalignment_deg=0.0, pivot_mm=0.0, marker_size_px=110.0)
    cams = make_cameras(cfg, np.random.default_rng(1))
    rng = np.random.default_rng(51)
    tc = TrackingConfig()
    step_frame = 210  # t = 7.0 s: the pitch excursion's extreme

    def truth(t):
        yaw, pitch = _truth(t)
        pitch = pitch + STEP_DEG * (t > STEP_FRAME / FPS + 0.002)  # remove the step at 0 deg
        return yaw, pitch - STEP_DEG * (t > step_frame / FPS + 0.002)

    t = np.arange(int(9.5 * FPS)) / FPS
    ts = t + LAG_S
    ca, Xa = _corners(cfg, cams[0], *truth(t), rng)
    cs, Xb = _corners(cfg, cams[1], *truth(ts), rng)
    va = _view(ca, cams[0], cfg, Xa)
    vb = _view(resample_corners(ts, cs, t, tc), cams[1], cfg, Xb)
    ref, res = fz.fit_reference(fz.fuse_views(va, vb, t, tc), va, vb, t < 0.8, t, tc)
    true = np.column_stack(truth(t))
    before = np.abs(fz.relative_angles(res.Q, ref.M)[:, :2] - true).max(axis=1)
    assert before[step_frame] > 0.5, before[step_frame]
    frames = np.flatnonzero(res.status == fz.MEASURED)
    alts = [_view(one_sided_corners(ts, cs, t, side, tc), cams[1], cfg, Xb)
            for side in ("before", "after")]  # fmt: skip
    check = lagged_check(res, va, alts, interp_weight(ts, t), ref.M, frames, tc)
    out, idx = adopt_lagged_alternatives(res, check)
    assert check.side[step_frame] == 0 and step_frame in idx
    assert set(idx) <= set(range(step_frame - 2, step_frame + 3)), idx
    after = np.abs(fz.relative_angles(out.Q, ref.M)[:, :2] - true).max(axis=1)
    assert after[step_frame] < 0.1, after[step_frame]
    assert np.nan_to_num(check.spread_deg[step_frame]) == 0.0
