"""The reference roll fitted over the whole session (joint twist-free fit), on exactly
projected corners with noise: the hardest case, cameras aligned (no misalignment) and
the cube on the pivot, where the straight window alone leaves the roll to foreshortening."""

from __future__ import annotations

import numpy as np
import pytest
from test_edges_fuse import view_data

from i2ris_calib.simulation.presets import preset_config
from i2ris_calib.simulation.scene import make_cameras
from i2ris_calib.tracking import fuse as fz
from i2ris_calib.tracking.config import TrackingConfig
from i2ris_calib.tracking.geometry import (
    euler_zyx_deg,
    face_corner_points_tip,
    project,
    tip_rotation,
)

NOISE_PX = 0.02  # corner noise; the edge corners are 0.005-0.04 px off on rendered markers


def _motion():
    """Straight 1 s, then yaw and pitch excursions to +-40 deg and two compound moves."""
    up = np.sin(np.linspace(0, np.pi, 40))
    z = np.zeros(40)
    yaw = np.concatenate([np.zeros(30), 40 * up, -35 * up, z, z, 30 * up, -38 * up])
    pitch = np.concatenate([np.zeros(30), z, z, -40 * up, 38 * up, 25 * up, -30 * up])
    return yaw, pitch


def _views(cfg, cams, yaws, pitches, rng):
    views = []
    for cam in cams:
        X = face_corner_points_tip(cam.view, cfg.marker_size_mm, cfg.cube_size_mm)
        c = np.array([
            project(cam.K, cam.R_cb @ tip_rotation(y, p),
                    cam.R_cb @ (tip_rotation(y, p) @ np.array([cfg.pivot_mm, 0, 0])) + cam.t_cb, X)
            for y, p in zip(yaws, pitches, strict=True)
        ])  # fmt: skip
        c = c + rng.normal(0, NOISE_PX, c.shape)
        views.append(view_data(c, cam, cfg, X))
    return views


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_session_roll_removes_the_cross_talk(seed):
    cfg = preset_config("ci", misalignment_deg=0.0, pivot_mm=0.0, marker_size_px=110.0)
    cams = make_cameras(cfg, np.random.default_rng(seed))
    rng = np.random.default_rng(100 + seed)
    yaw, pitch = _motion()
    a, b = _views(cfg, cams, yaw, pitch, rng)
    t = np.arange(len(yaw)) / 30.0
    res = fz.fuse_views(a, b, t, TrackingConfig())
    ok = res.status == fz.MEASURED
    assert ok.mean() > 0.95
    window = t < 1.0
    M_true = cams[0].R_cb  # tip frame = base frame at the straight pose
    out = {}
    for mode in ("window", "session"):
        ref, r2 = fz.fit_reference(res, a, b, window, t, TrackingConfig(reference_roll=mode))
        assert ref.method == mode
        ang = fz.relative_angles(r2.Q, ref.M)
        out[mode] = (ref, (ang[:, 0] - yaw)[ok], (ang[:, 1] - pitch)[ok])
    ref, ey, ep = out["session"]
    roll_err = euler_zyx_deg(M_true.T @ ref.M)[2]
    # the stated uncertainty is honest (truth within 4 sd) and useful (< 0.05 deg)
    assert abs(roll_err) <= 4 * ref.roll_sd_deg + 1e-4, (roll_err, ref.roll_sd_deg)
    assert ref.roll_sd_deg < 0.05
    # no cross-talk: yaw error does not grow with pitch nor pitch error with yaw
    big_p, big_y = np.abs(pitch[ok]) > 15, np.abs(yaw[ok]) > 15
    rms = lambda e: float(np.sqrt(np.mean(e**2)))  # noqa: E731
    assert rms(ey[big_p]) < 0.02 and rms(ep[big_y]) < 0.02, (rms(ey[big_p]), rms(ep[big_y]))
    # the window alone leaves a roll error that the session fit removes
    _, ey_w, ep_w = out["window"]
    assert rms(ey[big_p]) + rms(ep[big_y]) <= rms(ey_w[big_p]) + rms(ep_w[big_y])


def test_straight_session_keeps_the_window_reference():
    """No bending: the roll cannot be fitted, the window mean is kept (method 'window')."""
    cfg = preset_config("ci", misalignment_deg=0.0, pivot_mm=0.0, marker_size_px=110.0)
    cams = make_cameras(cfg, np.random.default_rng(4))
    n = 60
    a, b = _views(cfg, cams, np.zeros(n), np.zeros(n), np.random.default_rng(5))
    t = np.arange(n) / 30.0
    res = fz.fuse_views(a, b, t, TrackingConfig())
    ref, _ = fz.fit_reference(res, a, b, t < 1.0, t, TrackingConfig())
    assert ref.method == "window"
    assert ref.roll_correction_deg == 0.0


def test_axis_split_uncertainty_is_half_the_disagreement_of_the_two_axes():
    """Frames bent about yaw say the roll is +0.02 deg, frames bent about pitch -0.01 deg
    (each frame's reduced normal equations centred on its own value): the systematic
    part of the roll's uncertainty is half their disagreement, 0.015 deg; with one
    axis barely bent (< 30 frames) it cannot be told and is 0."""
    rng = np.random.default_rng(0)
    n_s, n_y, n_p = 50, 40, 60
    yp = np.zeros((n_s + n_y + n_p, 2))
    yp[n_s : n_s + n_y, 0] = np.radians(rng.uniform(12, 40, n_y)) * rng.choice([-1, 1], n_y)
    yp[n_s + n_y :, 1] = np.radians(rng.uniform(12, 40, n_p)) * rng.choice([-1, 1], n_p)
    target = np.zeros((len(yp), 4))
    target[n_s : n_s + n_y, 0] = np.radians(0.02)
    target[n_s + n_y :, 0] = np.radians(-0.01)
    Sn = np.empty((len(yp), 4, 4))
    for k in range(len(yp)):
        B = rng.normal(size=(6, 4))
        Sn[k] = B.T @ B
    Sn[:n_s, 0, :] = Sn[:n_s, :, 0] = 0.0  # straight frames: no roll information
    Sn[:n_s, 0, 0] = 1e-9
    rn = -np.einsum("nij,nj->ni", Sn, target)  # gradient at g = 0
    S, rhs = Sn.sum(0), rn.sum(0)
    sd = fz._axis_split_sd(S, rhs, Sn, rn, yp)
    assert sd == pytest.approx(np.radians(0.015), rel=1e-3)
    few = yp.copy()
    few[n_s + 29 : n_s + n_y, 0] = 0.0  # 29 yaw-bent frames left
    assert fz._axis_split_sd(S, rhs, Sn, rn, few) == 0.0
