"""Edge-line corners on rendered markers; fusion on exactly projected corners."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from i2ris_calib.simulation.presets import preset_config
from i2ris_calib.simulation.render import FrameRenderer
from i2ris_calib.simulation.scene import make_cameras, make_cube, true_marker_corners
from i2ris_calib.tracking import fuse as fz
from i2ris_calib.tracking.config import TrackingConfig
from i2ris_calib.tracking.detect import MarkerDetector
from i2ris_calib.tracking.fuse import _choose
from i2ris_calib.tracking.geometry import face_corner_points_tip, project, rodrigues, tip_rotation
from i2ris_calib.tracking.pose import ippe_candidates, tip_pose_from_marker


@pytest.fixture(scope="module")
def scene():
    cfg = preset_config("ci", width_px=400, height_px=320, marker_size_px=110.0, noise_sigma=0.0)
    cams = make_cameras(cfg, np.random.default_rng(3))
    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    cube = make_cube(cfg, {c.view: cv2.aruco.generateImageMarker(d, c.marker_id, 6) for c in cams})
    return cfg, cams, cube


@pytest.mark.parametrize("yaw,pitch", [(0.0, 0.0), (17.0, 0.0), (0.0, -28.0), (-33.0, 6.0)])
def test_edge_corners_are_within_five_hundredths_of_a_pixel(scene, yaw, pitch):
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


@pytest.fixture(scope="module")
def small_scene():
    """80 px markers on a 1.0 mm cube (white margin 10 px), noise-free, aligned cameras."""
    cfg = preset_config("ci", noise_sigma=0.0, misalignment_deg=0.0)
    cams = make_cameras(cfg, np.random.default_rng(3))
    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    cube = make_cube(cfg, {c.view: cv2.aruco.generateImageMarker(d, c.marker_id, 6) for c in cams})
    return cfg, cams, cube


@pytest.mark.parametrize("view,yaw,pitch", [("top", 0.0, 45.0), ("side", -45.0, 0.0),
                                            ("side", 42.0, 0.0)])  # fmt: skip
def test_edge_runs_stay_inside_a_foreshortened_margin(small_scene, view, yaw, pitch):
    """A face tilted 42-45 deg from its camera shows a 7 px margin, with the cube's edge
    (background) beyond it: full 6 px runs read the bright level there and move the
    edge by 0.29-0.42 px (measured); runs cut at the margin's middle: 0.07-0.17 px."""
    cfg, cams, cube = small_scene
    cam = next(c for c in cams if c.view == view)
    R = tip_rotation(yaw, pitch)
    img = FrameRenderer(cfg, cam, cube, 0).render([R])
    truth = true_marker_corners(cam, cfg.cube_size_mm, cfg.marker_size_mm, cfg.pivot_mm, R)
    ratio = (cfg.cube_size_mm - cfg.marker_size_mm) / (2 * cfg.marker_size_mm)
    new = MarkerDetector("DICT_4X4_50", cam.marker_id, TrackingConfig(), ratio).detect(img)
    old = MarkerDetector("DICT_4X4_50", cam.marker_id, TrackingConfig()).detect(img)
    assert new.edge_refined and old.edge_refined
    assert np.abs(new.corners - truth).max() < 0.2
    assert np.abs(old.corners - truth).max() > 0.25
    # at the straight pose the margin is wide: the same corners either way
    img0 = FrameRenderer(cfg, cam, cube, 0).render([tip_rotation(0.0, 0.0)])
    a = MarkerDetector("DICT_4X4_50", cam.marker_id, TrackingConfig(), ratio).detect(img0)
    b = MarkerDetector("DICT_4X4_50", cam.marker_id, TrackingConfig()).detect(img0)
    np.testing.assert_array_equal(a.corners, b.corners)


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
        views.append(view_data(np.array(c), cam, cfg, X))
    return views


def view_data(c: np.ndarray, cam, cfg, X: np.ndarray) -> fz.ViewData:
    """ViewData of one camera from its corners ``c`` (frames, 4, 2): both IPPE
    solutions per frame turned into tip poses (shared by the tracking tests)."""
    Rct = np.empty((len(c), 2, 3, 3))
    tct = np.empty((len(c), 2, 3))
    for k in range(len(c)):
        Rm, tm, _ = ippe_candidates(c[k], cam.K, cfg.marker_size_mm)
        for j in range(2):
            Rct[k, j], tct[k, j] = tip_pose_from_marker(cam.view, Rm[j], tm[j], cfg.cube_size_mm)
    return fz.ViewData(c, cam.K, X, Rct, tct)


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


def test_equal_cost_minima_resolved_by_continuity_else_ambiguous():
    n = 6
    t = np.arange(n) / 30.0
    good = np.stack([tip_rotation(0.1 * k, 0) for k in range(n)])
    mirror = np.stack([tip_rotation(0.1 * k, 8.0) for k in range(n)])
    z = np.zeros((n, 3))
    c_good = np.full(n, 1.0)
    c_mirror = np.full(n, 1.2)  # within ambiguity_ratio: cost alone cannot decide
    c_mirror[0] = 50.0  # frame 0 is clear: the mirror fits badly there
    cfg = TrackingConfig()
    # the second start holds the right answer in frames 3-5: continuity must follow it
    sol1 = (
        np.concatenate([good[:3], mirror[3:]]),
        z,
        z,
        np.concatenate([c_good[:3], c_mirror[3:]]),
    )
    sol2 = (
        np.concatenate([mirror[:3], good[3:]]),
        z,
        z,
        np.concatenate([c_mirror[:3], c_good[3:]]),
    )
    Q, _, _, cost, n_comp, n_cont = _choose([sol1, sol2], t, cfg)
    assert np.allclose(Q, good) and np.isfinite(cost).all() and n_cont == n - 1 and n_comp == n
    # no clear frame anywhere: every frame stays ambiguous (cost NaN), nothing guessed
    sol1b = (good, z, z, c_good.copy())
    sol2b = (mirror, z, z, np.full(n, 1.2))
    _, _, _, cost_b, _, _ = _choose([sol1b, sol2b], t, cfg)
    assert np.isnan(cost_b).all()


def test_common_axis_positions_constant_for_a_rigid_rig(rng):
    """u_b.t_b - u_a.t_a is the rigid rig's constant; a move along u (what swapped view
    labels cause) shows up one to one, a move along either camera's depth does not."""

    R_ba = rodrigues(np.array([np.pi / 2, 0.0, 0.0]) + rng.normal(0, 0.05, 3))
    t_a = rng.normal(0, 1.0, (50, 3)) + [0, 0, 200.0]
    t_b = t_a @ R_ba.T + [3.0, -2.0, 150.0]
    d = fz.common_axis_positions(t_a, t_b, R_ba)
    assert np.ptp(d) < 1e-9
    u_a = np.cross([0, 0, 1.0], R_ba.T @ [0, 0, 1.0])
    u_a /= np.linalg.norm(u_a)
    moved = t_b + np.outer(np.linspace(0, 0.3, 50), R_ba @ u_a)
    assert np.ptp(fz.common_axis_positions(t_a, moved, R_ba)) == pytest.approx(0.3, rel=1e-9)
    deeper = t_b + np.outer(rng.normal(0, 5, 50), [0, 0, 1.0])  # camera b's depth
    assert np.ptp(fz.common_axis_positions(t_a, deeper, R_ba)) < 1e-9


@pytest.mark.parametrize(
    "given, swapped, verdict",
    [(0.0005, 0.26, "consistent"), (0.26, 0.0005, "swapped"), (0.04, 0.3, "consistent"),
     (0.002, 0.01, "inconclusive"),  # the tip barely turned: neither spread shows
     (0.1, 0.08, "inconclusive"), (float("nan"), 0.3, "inconclusive")],
)  # fmt: skip
def test_view_verdict(given, swapped, verdict):
    assert fz.view_verdict(given, swapped, cube_size_mm=1.0) == verdict
