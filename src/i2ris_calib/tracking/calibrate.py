"""Camera intrinsics from ChArUco board views (``cv2.aruco.CharucoDetector`` + ``calibrateCamera``).

Microscopes: at very long focal lengths only f/Z is determined and the principal
point wanders (docs/tracking.md); calibrate with a tilted board and several
poses, or use the weak-perspective model instead.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from i2ris_calib.errors import CalibError
from i2ris_calib.tracking.detect import aruco_dictionary


@dataclass(frozen=True)
class CharucoSpec:
    """A ChArUco board: squares (x, y), square and marker size (mm), dictionary."""

    squares_x: int = 7
    squares_y: int = 5
    square_mm: float = 1.0
    marker_mm: float = 0.7
    dictionary: str = "DICT_4X4_50"


@dataclass(frozen=True)
class Intrinsics:
    """Calibration result: K (3, 3), dist (5,), image size, RMS error (px), views used."""

    K: np.ndarray
    dist: np.ndarray
    width_px: int
    height_px: int
    rms_px: float
    n_views: int
    n_corners: int


def charuco_board(spec: CharucoSpec):
    """The ``cv2.aruco.CharucoBoard`` of ``spec``."""
    return cv2.aruco.CharucoBoard(
        (spec.squares_x, spec.squares_y),
        spec.square_mm,
        spec.marker_mm,
        aruco_dictionary(spec.dictionary),
    )


def board_points(board, gray: np.ndarray, min_corners: int = 6):
    """Matched (object (k, 3), image (k, 2)) ChArUco corners of one view, or None."""
    det = cv2.aruco.CharucoDetector(board)
    cc, ids, _, _ = det.detectBoard(gray)
    if ids is None or len(ids) < min_corners:
        return None
    obj = board.getChessboardCorners()[ids.ravel()]
    return np.asarray(obj, np.float32), np.asarray(cc, np.float32).reshape(-1, 2)


def calibrate_from_views(
    views: list[np.ndarray], spec: CharucoSpec, fix_aspect: bool = True
) -> Intrinsics:
    """Calibrate from grey images (h, w) uint8 showing the board.

    Raises CalibError when fewer than 3 views show enough corners.
    """
    board = charuco_board(spec)
    objs, imgs = [], []
    for g in views:
        pts = board_points(board, g)
        if pts is not None:
            objs.append(pts[0])
            imgs.append(pts[1])
    if len(objs) < 3:
        raise CalibError(
            f"only {len(objs)} view(s) show the ChArUco board ({spec.squares_x}x{spec.squares_y}, "
            f"{spec.dictionary}); need >= 3 (check [track] charuco_* settings)"
        )
    h, w = views[0].shape[:2]
    flags = cv2.CALIB_FIX_ASPECT_RATIO if fix_aspect else 0
    K0 = np.array(
        [[float(max(w, h)), 0, (w - 1) / 2], [0, float(max(w, h)), (h - 1) / 2], [0, 0, 1]]
    )
    rms, K, dist, _, _ = cv2.calibrateCamera(objs, imgs, (w, h), K0, np.zeros(5), flags=flags)
    return Intrinsics(
        K, np.asarray(dist).ravel(), w, h, float(rms), len(objs), int(sum(len(o) for o in objs))
    )
