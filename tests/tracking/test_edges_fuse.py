"""Edge-line corners on rendered markers; fusion on exactly projected corners."""

from __future__ import annotations

import numpy as np
import pytest

from i2ris_calib.simulation.presets import preset_config
from i2ris_calib.simulation.render import FrameRenderer
from i2ris_calib.simulation.scene import make_cameras, make_cube, true_marker_corners
from i2ris_calib.tracking import fuse as fz
from i2ris_calib.tracking.config import TrackingConfig
from i2ris_calib.tracking.geometry import face_corner_points_tip, project, tip_rotation
from i2ris_calib.tracking.pose import ippe_candidates, tip_pose_from_marker


@pytest.fixture(scope="module")
def scene():
    import cv2

    cfg = preset_config("ci", width_px=400, height_px=320, marker_size_px=110.0, noise_sigma=0.0)
    cams = make_cameras(cfg, np.random.default_rng(3))
    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    cube = make_cube(cfg, {c.view: cv2.aruco.generateImageMarker(d, c.marker_id, 6) for c in cams})
    return cfg, cams, cube


@pytest.mark.parametrize("yaw,pitch", [(0.0, 0.0), (17.0, 0.0), (0.0, -28.0), (-33.0, 6.0)])
def test_edge_corners_are_within_five_hundredths_of_a_pixel(scene, yaw, pitch):
    from i2ris_calib.tracking.detect import MarkerDetector

    cfg, cams, cube = scene
    for cam in cams:
        R = tip_rotation(yaw, pitch)
        img = FrameRenderer(cfg, cam, cube, 0).render([R])
        det = MarkerDetector("DICT_4X4_50", cam.marker_id, TrackingConfig()).detect(img)
        assert det.edge_refined
        truth = true_marker_corners(cam, cfg.cube_size_mm, cfg.marker_size_mm, cfg.pivot_mm, R)
        assert np.abs(det.corners - truth).max() < 0.05  # noise-free: 0.005-0.04 px measured
        sub = MarkerDetector(
            "DICT_4X4_50", cam.marker_id, TrackingConfig(corner_refinement="subpix")
        )
        assert np.abs(sub.detect(img).corners - truth).max() > 0.05  # ArUco's biased corners


def _views(scene, yaws, pitches, noise, rng):
    cfg, cams, _ = scene
    views = []
    for cam in cams:
        X = face_corner_points_tip(cam.view, cfg.marker_size_mm, cfg.cube_size_mm)
        c = []
        for y, p in zip(yaws, pitches, strict=True):
            R = tip_rotation(y, p)
            Rc = cam.R_cb @ R
            tc = cam.R_cb @ (R @ np.array([cfg.pivot_mm, 0, 0])) + cam.t_cb
            c.append(project(cam.K, Rc, tc, X) + rng.normal(0, noise, (4, 2)))
        c = np.array(c)
        Rct = np.empty((len(c), 2, 3, 3))
        tct = np.empty((len(c), 2, 3))
        for k in range(len(c)):
            Rm, tm, _ = ippe_candidates(c[k], cam.K, cfg.marker_size_mm)
            for j in range(2):
                Rct[k, j], tct[k, j] = tip_pose_from_marker(
                    cam.view, Rm[j], tm[j], cfg.cube_size_mm
                )
        views.append(fz.ViewData(c, cam.K, X, Rct, tct))
    return views


def test_fusion_recovers_angles_from_projected_corners(scene):
    rng = np.random.default_rng(5)
    n = 120
    yaws = np.concatenate([np.zeros(30), np.linspace(0, 40, 45), np.zeros(45)])
    pitches = np.concatenate([np.zeros(75), np.linspace(0, -35, 45)])
    a, b = _views(scene, yaws, pitches, 0.005, rng)
    t = np.arange(n) / 30.0
    res = fz.fuse_views(a, b, t, TrackingConfig())
    assert (res.status == fz.MEASURED).all()
    ang = fz.relative_angles(res.Q, fz.reference_rotation(res.Q, t < 0.8))
    assert np.abs(ang[:, 0] - yaws).max() < 0.02
    assert np.abs(ang[:, 1] - pitches).max() < 0.02


def test_missing_view_gives_not_found_and_nan(scene):
    rng = np.random.default_rng(6)
    a, b = _views(scene, np.zeros(40), np.linspace(0, 5, 40), 0.005, rng)
    b.corners[10:15] = np.nan
    res = fz.fuse_views(a, b, np.arange(40) / 30.0, TrackingConfig())
    assert (res.status[10:15] == fz.NOT_FOUND).all()
    assert np.isnan(res.Q[10:15]).all()
    assert (res.status[:10] == fz.MEASURED).all()
