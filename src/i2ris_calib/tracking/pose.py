"""Single-camera marker pose: both IPPE solutions, and the camera models.

Two camera models (docs/tracking.md):

* ``pinhole``: K and distortion from a calibration file; corners are undistorted
  to ideal pixels first, then every projection uses K without distortion.
* ``weak_perspective``: scaled orthographic projection, realised as a pinhole with
  a huge focal length (``weak_perspective_focal_px``) and the principal point at
  the image centre; distance then only sets the scale (magnification).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from i2ris_calib.tracking.geometry import (
    FACE_NORMALS,
    FACE_ROTATIONS,
    camera_matrix,
    marker_corners_mm,
)


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics; ``dist`` is OpenCV's distortion vector (may be empty)."""

    K: np.ndarray  # (3, 3)
    dist: np.ndarray  # (k,)
    width_px: int
    height_px: int
    model: str = "pinhole"

    def undistort(self, corners: np.ndarray) -> np.ndarray:
        """Ideal pixel coordinates (..., 2) of observed corners (no-op without distortion)."""
        c = np.asarray(corners, dtype=np.float64)
        if self.dist.size == 0 or not np.any(self.dist):
            return c

        flat = c.reshape(-1, 1, 2)
        ok = np.isfinite(flat).all(axis=2).ravel()
        out = np.full_like(flat, np.nan)
        if ok.any():
            out[ok] = cv2.undistortPoints(flat[ok], self.K, self.dist, P=self.K)
        return out.reshape(c.shape)


def weak_perspective_intrinsics(width_px: int, height_px: int, focal_px: float) -> CameraIntrinsics:
    """The weak-perspective camera as a very long pinhole centred on the image."""
    return CameraIntrinsics(camera_matrix(focal_px, width_px, height_px), np.zeros(0), width_px, height_px,
                            "weak_perspective")  # fmt: skip


def ippe_candidates(corners: np.ndarray, K: np.ndarray, marker_size_mm: float):
    """Both IPPE_SQUARE poses of one marker.

    Parameters
    ----------
    corners : ndarray (4, 2)
        Undistorted corners in IPPE order (px).
    K : ndarray (3, 3)
    marker_size_mm : float

    Returns
    -------
    R : ndarray (2, 3, 3)
        Rotations marker -> camera, best (lowest reprojection error) first.
    t : ndarray (2, 3)
        Marker centre in the camera frame (mm).
    err : ndarray (2,)
        RMS reprojection errors (px).
    """
    obj = marker_corners_mm(marker_size_mm)
    img = np.ascontiguousarray(corners, dtype=np.float64).reshape(4, 1, 2)
    n, rvecs, tvecs, errs = cv2.solvePnPGeneric(obj, img, K, None, flags=cv2.SOLVEPNP_IPPE_SQUARE)
    R = np.array([cv2.Rodrigues(r)[0] for r in rvecs[:n]])
    t = np.array([np.asarray(v, float).ravel() for v in tvecs[:n]])
    e = np.asarray(errs, float).ravel()[:n]
    if n == 1:
        R, t, e = np.repeat(R, 2, 0), np.repeat(t, 2, 0), np.repeat(e, 2)
    order = np.argsort(e, kind="stable")
    return R[order], t[order], e[order]


def tip_pose_from_marker(view: str, R_cm: np.ndarray, t_cm: np.ndarray, cube_size_mm: float):
    """Tip (cube) rotation and centre in the camera frame from a marker pose.

    ``R_ct = R_cm @ F^T`` with F the face rotation (marker -> tip); the cube centre
    lies half a cube behind the marker face.
    """
    F = FACE_ROTATIONS[view]
    R_ct = R_cm @ F.T
    t_ct = t_cm - R_ct @ (FACE_NORMALS[view] * cube_size_mm / 2.0)
    return R_ct, t_ct
