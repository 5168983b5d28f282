"""``i2ris-calib calibrate``: ChArUco images/videos -> camera intrinsics YAML, or a
YAML (OpenCV or ROS ``camera_info``) converted (format in :mod:`i2ris_calib.io.camera_yaml`).
"""

from __future__ import annotations

from pathlib import Path

import cv2

from i2ris_calib.errors import CalibError
from i2ris_calib.io.camera_yaml import read_camera_yaml, write_camera_yaml
from i2ris_calib.io.outputs import claim_output_file
from i2ris_calib.io.video import iter_frames
from i2ris_calib.tracking.calibrate import CharucoSpec, calibrate_from_views

IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp"}
YAML_SUFFIXES = {".yaml", ".yml", ".xml"}


def calibrate_camera_files(inputs: list[Path], out: Path, config) -> Path:
    """``i2ris-calib calibrate``: ChArUco images/videos -> OpenCV YAML at ``out``.

    A single YAML input (OpenCV or ROS ``camera_info``) is converted instead.
    """
    cfg = config.track
    inputs = [Path(p) for p in inputs]
    for p in inputs:
        if not p.exists():
            raise CalibError(f"calibration input not found: {p}")
    claim_output_file(out, inputs)
    if len(inputs) == 1 and inputs[0].suffix.lower() in YAML_SUFFIXES:
        K, dist, w, h = read_camera_yaml(inputs[0])
        write_camera_yaml(Path(out), K, dist, w, h, {"source": str(inputs[0])})
        return Path(out)
    views = list(_calibration_views(inputs, cfg.calibration_every_nth_frame))
    spec = CharucoSpec(
        *cfg.charuco_squares, cfg.charuco_square_mm, cfg.charuco_marker_mm, cfg.charuco_dictionary
    )
    res = calibrate_from_views(views, spec)
    write_camera_yaml(Path(out), res.K, res.dist, res.width_px, res.height_px,
                      {"rms_reprojection_error_px": res.rms_px, "views_used": res.n_views,
                       "corners_used": res.n_corners})  # fmt: skip
    return Path(out)


def _calibration_views(inputs: list[Path], every: int):
    """Grey frames from images and (every n-th frame of) videos."""
    for p in inputs:
        if p.suffix.lower() in IMAGE_SUFFIXES:
            img = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
            if img is None:
                raise CalibError(f"cannot read image {p} (corrupt or unsupported format)")
            yield img
        else:
            for k, f in enumerate(iter_frames(p)):
                if k % every == 0:
                    yield f
