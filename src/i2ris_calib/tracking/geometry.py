"""Frames, rotations and the marker cube: the conventions shared by tracking and simulation.

Conventions (documented in ``docs/tracking.md``):

* Base frame B (robot, right-handed, mm): ``x`` distal along the straight tool,
  ``z`` up towards the top microscope, ``y = z x x``.
* Tip frame T: fixed to the cube; equal to B at the reference (straight) pose.
* Tip orientation ``R_BT = Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (ZYX Euler angles).
  Positive yaw turns the tip from +x towards +y; positive pitch turns it from +x
  towards -z (right-hand rule about +y). Yaw and pitch depend only on the tip's
  distal axis ``R_BT[:, 0]``.
* Cube faces: the *top* camera sees the marker on the +z face, the *side* camera the
  marker on the -y face. On both faces the marker's x axis (corner 0 -> corner 1)
  points distally (+x of T).
* Marker frame M (OpenCV ``SOLVEPNP_IPPE_SQUARE``): corners in the order
  ``(-s/2, s/2, 0), (s/2, s/2, 0), (s/2, -s/2, 0), (-s/2, -s/2, 0)``, z out of the
  marker; ArUco returns corners in this order (top-left, clockwise).
* Camera frames follow OpenCV: x right, y down, z along the viewing direction;
  pixel centres at integer coordinates.
"""

from __future__ import annotations

import numpy as np

#: Rotation marker frame -> tip frame for each view (columns: marker x, y, z in T).
FACE_ROTATIONS = {
    "top": np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),
    "side": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]),
}
#: Outward normal of the marker face, in the tip frame.
FACE_NORMALS = {"top": np.array([0.0, 0.0, 1.0]), "side": np.array([0.0, -1.0, 0.0])}
#: Nominal (perfectly aligned) rotation base -> camera for each view (rows: camera axes in B).
NOMINAL_CAMERA_ROTATIONS = {
    "top": np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]),
    "side": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]),
}


def rot_x(a: float) -> np.ndarray:
    """Rotation matrix (3, 3) about x by ``a`` rad."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(a: float) -> np.ndarray:
    """Rotation matrix (3, 3) about y by ``a`` rad."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(a: float) -> np.ndarray:
    """Rotation matrix (3, 3) about z by ``a`` rad."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def tip_rotation(yaw_deg: float, pitch_deg: float, roll_deg: float = 0.0) -> np.ndarray:
    """``R_BT = Rz(yaw) Ry(pitch) Rx(roll)``, shape (3, 3), angles in deg."""
    return rot_z(np.radians(yaw_deg)) @ rot_y(np.radians(pitch_deg)) @ rot_x(np.radians(roll_deg))


def euler_zyx_deg(R: np.ndarray) -> np.ndarray:
    """Yaw, pitch, roll (deg) of rotation(s) ``R`` (..., 3, 3) in the ZYX convention.

    Returns an array (..., 3): ``[yaw, pitch, roll]``.
    """
    R = np.asarray(R, dtype=float)
    yaw = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    pitch = -np.arcsin(np.clip(R[..., 2, 0], -1.0, 1.0))
    roll = np.arctan2(R[..., 2, 1], R[..., 2, 2])
    return np.degrees(np.stack([yaw, pitch, roll], axis=-1))


def rodrigues(rvec: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) from rotation vectors (..., 3) (rad, axis * angle)."""
    r = np.asarray(rvec, dtype=float)
    th = np.linalg.norm(r, axis=-1, keepdims=True)
    safe = np.where(th > 1e-12, th, 1.0)
    k = r / safe
    K = np.zeros(r.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2] = -k[..., 2], k[..., 1]
    K[..., 1, 0], K[..., 1, 2] = k[..., 2], -k[..., 0]
    K[..., 2, 0], K[..., 2, 1] = -k[..., 1], k[..., 0]
    s = np.sin(th)[..., None]
    c = np.cos(th)[..., None]
    R = np.eye(3) + s * K + (1 - c) * (K @ K)
    # exact for tiny angles: first-order term
    small = (th[..., 0] <= 1e-12)[..., None, None]
    Rs = np.eye(3) + _skew(r)
    return np.where(small, Rs, R)


def _skew(r: np.ndarray) -> np.ndarray:
    K = np.zeros(r.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2] = -r[..., 2], r[..., 1]
    K[..., 1, 0], K[..., 1, 2] = r[..., 2], -r[..., 0]
    K[..., 2, 0], K[..., 2, 1] = -r[..., 1], r[..., 0]
    return K


def rotation_angle_deg(Ra: np.ndarray, Rb: np.ndarray) -> np.ndarray:
    """Angle (deg) of the rotation ``Ra^T Rb``, shape (...)."""
    M = np.swapaxes(Ra, -1, -2) @ Rb
    tr = np.trace(M, axis1=-2, axis2=-1)
    return np.degrees(np.arccos(np.clip((tr - 1.0) / 2.0, -1.0, 1.0)))


def mean_rotation(Rs: np.ndarray) -> np.ndarray:
    """Chordal L2 mean of rotations ``Rs`` (n, 3, 3): nearest rotation to their average."""
    U, _, Vt = np.linalg.svd(np.mean(Rs, axis=0))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt


def marker_corners_mm(marker_size_mm: float) -> np.ndarray:
    """Marker corners (4, 3) in the marker frame, IPPE_SQUARE order (mm)."""
    h = marker_size_mm / 2.0
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


def face_corner_points_tip(view: str, marker_size_mm: float, cube_size_mm: float) -> np.ndarray:
    """Marker corners (4, 3) of the face seen by ``view``, in the tip frame (mm).

    The tip frame origin is the cube centre.
    """
    F = FACE_ROTATIONS[view]
    return marker_corners_mm(marker_size_mm) @ F.T + FACE_NORMALS[view] * (cube_size_mm / 2.0)


def camera_matrix(focal_px: float, width_px: int, height_px: int) -> np.ndarray:
    """Pinhole intrinsics K (3, 3) with the principal point at the image centre."""
    return np.array(
        [
            [focal_px, 0.0, (width_px - 1) / 2.0],
            [0.0, focal_px, (height_px - 1) / 2.0],
            [0.0, 0.0, 1.0],
        ]
    )


def project(K: np.ndarray, R: np.ndarray, t: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Pinhole projection of points ``X`` (..., n, 3) with pose (R (..., 3, 3), t (..., 3)).

    Returns pixel coordinates (..., n, 2) (no distortion).
    """
    Xc = X @ np.swapaxes(R, -1, -2) + t[..., None, :]
    uv = Xc[..., :2] / Xc[..., 2:3]
    return uv * np.array([K[0, 0], K[1, 1]]) + np.array([K[0, 2], K[1, 2]])
