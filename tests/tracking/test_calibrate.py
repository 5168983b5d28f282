"""ChArUco calibration on rendered views with known intrinsics; camera YAML formats."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from i2ris_calib.cli import main
from i2ris_calib.errors import CalibError
from i2ris_calib.io.camera_yaml import read_camera_yaml, write_camera_yaml
from i2ris_calib.tracking.calibrate import CharucoSpec, calibrate_from_views, charuco_board
from i2ris_calib.tracking.geometry import rot_x, rot_y, rot_z

K_TRUE = np.array([[800.0, 0, 321.0], [0, 800.0, 238.0], [0, 0, 1]])
PX_PER_MM = 100


def _views(spec: CharucoSpec, n: int = 8):
    board = charuco_board(spec)
    tex = board.generateImage((spec.squares_x * PX_PER_MM, spec.squares_y * PX_PER_MM))
    # texture pixel (u, v), centre at +0.5, -> board mm
    S = np.array(
        [[1 / PX_PER_MM, 0, 0.5 / PX_PER_MM], [0, 1 / PX_PER_MM, 0.5 / PX_PER_MM], [0, 0, 1]]
    )
    rng = np.random.default_rng(2)
    views = []
    for _ in range(n):
        R = (
            rot_z(rng.uniform(-0.3, 0.3))
            @ rot_y(rng.uniform(-0.5, 0.5))
            @ rot_x(rng.uniform(-0.5, 0.5))
        )
        centre = np.array([spec.squares_x / 2, spec.squares_y / 2, 0.0])
        t = np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), 11.0]) - R @ centre
        H = K_TRUE @ np.column_stack([R[:, 0], R[:, 1], t]) @ S
        img = cv2.warpPerspective(tex, H, (640, 480), flags=cv2.INTER_AREA, borderValue=255)
        views.append(cv2.GaussianBlur(img, (0, 0), 0.7))
    return views


def test_calibration_recovers_known_intrinsics():
    spec = CharucoSpec()
    res = calibrate_from_views(_views(spec), spec)
    assert abs(res.K[0, 0] - 800) / 800 < 0.02  # focal length within 2 %
    assert np.abs(res.K[:2, 2] - K_TRUE[:2, 2]).max() < 8  # principal point within 8 px
    assert res.rms_px < 0.5 and res.n_views >= 6


def test_too_few_board_views_is_a_clear_error():
    blank = [np.full((480, 640), 200, np.uint8)] * 4
    with pytest.raises(CalibError, match="view"):
        calibrate_from_views(blank, CharucoSpec())


def test_opencv_yaml_round_trip(tmp_path):
    p = tmp_path / "cam.yaml"
    write_camera_yaml(p, K_TRUE, np.array([0.1, -0.2, 0, 0, 0.01]), 640, 480)
    K, dist, w, h = read_camera_yaml(p)
    assert (
        np.allclose(K, K_TRUE)
        and np.allclose(dist, [0.1, -0.2, 0, 0, 0.01])
        and (w, h) == (640, 480)
    )


def test_ros_camera_info_yaml(tmp_path):
    p = tmp_path / "ros.yaml"
    p.write_text(
        "image_width: 640\nimage_height: 480\ncamera_name: scope\n"
        "camera_matrix:\n  rows: 3\n  cols: 3\n  data: [900.0, 0.0, 320.5, 0.0, 901.0, 240.5, 0.0, 0.0, 1.0]\n"
        "distortion_model: plumb_bob\n"
        "distortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [0.1, -0.2, 0.001, 0.002, 0.0]\n"
    )
    K, dist, w, h = read_camera_yaml(p)
    assert K[1, 1] == 901.0 and K[0, 2] == 320.5 and dist[3] == 0.002 and (w, h) == (640, 480)


def test_bad_yaml_is_a_clear_error(tmp_path):
    p = tmp_path / "bad.yaml"
    p.write_text("camera_matrix: 3\n")
    with pytest.raises(CalibError, match="camera_matrix"):
        read_camera_yaml(p)


def test_calibrate_cli_from_images_and_ros_conversion(tmp_path):
    paths = []
    for k, img in enumerate(_views(CharucoSpec())):
        paths.append(tmp_path / f"v{k}.png")
        cv2.imwrite(str(paths[-1]), img)
    out = tmp_path / "cam.yaml"
    assert main(["calibrate", *map(str, paths), "--out", str(out)]) == 0
    K, _, w, h = read_camera_yaml(out)
    assert abs(K[0, 0] - 800) < 16 and (w, h) == (640, 480)
    assert main(["calibrate", str(out), "--out", str(tmp_path / "copy.yaml")]) == 0
    assert np.allclose(read_camera_yaml(tmp_path / "copy.yaml")[0], K)
    assert main(["calibrate", str(tmp_path / "missing.png"), "--out", str(out)]) == 2
