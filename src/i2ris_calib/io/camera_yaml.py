"""Camera intrinsics files: OpenCV FileStorage YAML and ROS ``camera_info`` YAML.

OpenCV: ``camera_matrix`` and ``distortion_coefficients`` as ``!!opencv-matrix``
nodes, plus ``image_width``/``image_height``. ROS (``camera_calibration`` output):
``camera_matrix: {rows, cols, data}``, ``distortion_coefficients: {rows, cols,
data}``, ``image_width``, ``image_height``, ``distortion_model: plumb_bob``.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from i2ris_calib import __version__
from i2ris_calib.errors import CalibError
from i2ris_calib.io.atomic import atomic_path


def _node_matrix(node, rows: int, cols: int | None = None) -> np.ndarray:
    """Matrix from an OpenCV matrix node or a ROS ``{rows, cols, data}`` map."""
    if node.empty():
        return np.zeros((0,))
    if not (node.isMap() and node.getNode("dt").empty()):  # OpenCV matrix node
        m = node.mat()
        if m is not None and m.size:
            return np.asarray(m, dtype=float)
    data = node.getNode("data") if node.isMap() else node
    if not data.isSeq():
        return np.zeros((0,))
    items = [data.at(i) for i in range(data.size())]
    if not all(it.isReal() or it.isInt() for it in items):
        raise ValueError("non-numeric matrix entries")
    vals = np.array([it.real() for it in items], dtype=float)
    return vals.reshape(rows, -1) if cols is None else vals.reshape(rows, cols)


def read_camera_yaml(path: str | Path) -> tuple[np.ndarray, np.ndarray, int, int]:
    """Read intrinsics: ``(K (3, 3), dist (k,), width_px, height_px)``.

    Accepts OpenCV FileStorage YAML/XML and ROS camera_info YAML; CalibError with
    the file name when unreadable or incomplete.
    """
    p = Path(path)
    if not p.is_file():
        raise CalibError(f"camera calibration file not found: {p}")
    fix = "(expected OpenCV FileStorage or ROS camera_info YAML, see docs/session.md; rerun 'i2ris-calib calibrate')"
    try:
        fs = cv2.FileStorage(str(p), cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError):  # OpenCV 5 raises SystemError on unparsable text
        raise CalibError(f"{p}: not a readable OpenCV/ROS YAML file {fix}") from None
    if not fs.isOpened():
        raise CalibError(f"{p}: not a readable OpenCV/ROS YAML file {fix}")
    try:
        K = _node_matrix(fs.getNode("camera_matrix"), 3, 3)
        dist = _node_matrix(fs.getNode("distortion_coefficients"), 1).ravel()
        w = int(fs.getNode("image_width").real()) if not fs.getNode("image_width").empty() else 0
        h = int(fs.getNode("image_height").real()) if not fs.getNode("image_height").empty() else 0
    except (cv2.error, ValueError, SystemError):
        raise CalibError(
            f"{p}: malformed camera_matrix/distortion_coefficients (3x3 and 1xN numeric "
            f"matrices) {fix}"
        ) from None
    finally:
        fs.release()
    plausible = (
        K.shape == (3, 3)
        and np.all(np.isfinite(K))
        and 0 < K[0, 0] < 1e12
        and 0 < K[1, 1] < 1e12
        and np.allclose(K[2], [0.0, 0.0, 1.0])
        and np.all(np.abs(K) < 1e12)
    )
    if not plausible:
        raise CalibError(
            f"{p}: no valid 3x3 camera_matrix (finite focal lengths > 0, last row 0 0 1) {fix}"
        )
    if not np.all(np.isfinite(dist)) or np.any(np.abs(dist) > 1e6) or w < 0 or h < 0:
        raise CalibError(
            f"{p}: invalid distortion_coefficients or image size (finite numbers expected) {fix}"
        )
    return K, dist, w, h


def write_camera_yaml(
    path: Path, K: np.ndarray, dist: np.ndarray, width: int, height: int, extra: dict | None = None
) -> None:
    """Intrinsics as OpenCV FileStorage YAML (camera_matrix, distortion_coefficients)."""
    with atomic_path(path) as tmp:
        fs = cv2.FileStorage(str(tmp), cv2.FILE_STORAGE_WRITE)
        fs.write("image_width", int(width))
        fs.write("image_height", int(height))
        fs.write("camera_matrix", np.asarray(K, dtype=float))
        fs.write("distortion_coefficients", np.asarray(dist, dtype=float).reshape(1, -1))
        fs.write("written_by", f"i2ris-calib {__version__}")  # io/outputs.py: ours to replace
        for k, v in (extra or {}).items():
            fs.write(k, v)
        fs.release()
