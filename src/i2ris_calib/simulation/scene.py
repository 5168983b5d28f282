"""The rendered scene: two microscope cameras looking at the marker cube on the tip.

Geometry conventions are those of :mod:`i2ris_calib.tracking.geometry`. The cube
centre sits ``pivot_mm`` distal of the bending pivot (base origin), so bending also
translates the cube in the image. Each camera is a pinhole with a long focal length
(near-orthographic), placed so the straight-pose marker is ``marker_size_px`` wide
and centred, then tilted by ``misalignment_deg`` about a random axis through the cube.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from i2ris_calib.simulation.config import SimulationConfig
from i2ris_calib.tracking.geometry import (
    FACE_NORMALS,
    FACE_ROTATIONS,
    NOMINAL_CAMERA_ROTATIONS,
    camera_matrix,
    face_corner_points_tip,
    rodrigues,
)

VIEWS = ("top", "side")


@dataclass(frozen=True)
class CameraModel:
    """A rendered camera: ``x_cam = R_cb @ x_base + t_cb`` (mm), pixels ``K @ x_cam``."""

    name: str
    view: str
    K: np.ndarray  # (3, 3)
    R_cb: np.ndarray  # (3, 3) base -> camera
    t_cb: np.ndarray  # (3,) mm
    width_px: int
    height_px: int
    marker_id: int


def make_cameras(cfg: SimulationConfig, rng: np.random.Generator) -> list[CameraModel]:
    """The two cameras ("top", "side") with random misalignment of ``misalignment_deg``."""
    K = camera_matrix(cfg.focal_px, cfg.width_px, cfg.height_px)
    dist_mm = cfg.focal_px * cfg.marker_size_mm / cfg.marker_size_px
    centre = np.array([cfg.pivot_mm, 0.0, 0.0])
    cams = []
    for i, view in enumerate(VIEWS):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        R_mis = rodrigues(axis * np.radians(cfg.misalignment_deg))
        R_cb = NOMINAL_CAMERA_ROTATIONS[view] @ R_mis
        cam_pos = centre - dist_mm * R_cb[2]
        t_cb = -R_cb @ cam_pos
        cams.append(
            CameraModel(view, view, K, R_cb, t_cb, cfg.width_px, cfg.height_px, cfg.marker_ids[i])
        )
    return cams


# Cube faces: (outward normal, in-plane u, in-plane v) in the tip frame; u x v = normal.
_FACES = {
    "+x": ((1, 0, 0), (0, 1, 0), (0, 0, 1)),
    "-x": ((-1, 0, 0), (0, 0, 1), (0, 1, 0)),
    "+y": ((0, 1, 0), (0, 0, 1), (1, 0, 0)),
    "-y": ((0, -1, 0), (1, 0, 0), (0, 0, 1)),
    "+z": ((0, 0, 1), (1, 0, 0), (0, 1, 0)),
    "-z": ((0, 0, -1), (0, 1, 0), (1, 0, 0)),
}
_MARKER_FACE = {"top": "+z", "side": "-y"}


def marker_ink_rects(bits: np.ndarray, marker_size_mm: float) -> np.ndarray:
    """Black rectangles of a marker, (k, 4, 3) in the marker frame (mm), row runs merged.

    ``bits`` (c, c) is the marker image with one pixel per cell (0 = black), as from
    ``cv2.aruco.generateImageMarker(dictionary, id, c)``; row 0 is the top (+y).
    """
    c = bits.shape[0]
    cell = marker_size_mm / c
    h = marker_size_mm / 2.0
    rects = []
    for i in range(c):
        j = 0
        while j < c:
            if bits[i, j] == 0:
                k = j
                while k + 1 < c and bits[i, k + 1] == 0:
                    k += 1
                x0, x1 = -h + j * cell, -h + (k + 1) * cell
                y0, y1 = h - i * cell, h - (i + 1) * cell
                rects.append([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0]])
                j = k + 1
            else:
                j += 1
    return np.asarray(rects, dtype=float)


@dataclass(frozen=True)
class CubeModel:
    """Cube geometry in the tip frame: face quads and the marker ink quads per view."""

    faces: dict  # face name -> (4, 3) corners, tip frame
    normals: dict  # face name -> (3,) outward normal
    ink: dict  # view -> (k, 4, 3) ink quads in the tip frame
    pivot_mm: float


def make_cube(cfg: SimulationConfig, marker_bits: dict) -> CubeModel:
    """Cube model with the two markers (``marker_bits`` view -> bit image)."""
    h = cfg.cube_size_mm / 2.0
    faces, normals = {}, {}
    for name, (n, u, v) in _FACES.items():
        n, u, v = (np.asarray(a, dtype=float) for a in (n, u, v))
        c = n * h
        faces[name] = np.array(
            [c - h * u + h * v, c + h * u + h * v, c + h * u - h * v, c - h * u - h * v]
        )
        normals[name] = n
    ink = {}
    for view, bits in marker_bits.items():
        rects = marker_ink_rects(bits, cfg.marker_size_mm)
        F = FACE_ROTATIONS[view]
        ink[view] = rects @ F.T + FACE_NORMALS[view] * h
    return CubeModel(faces, normals, ink, cfg.pivot_mm)


def cube_pose(cube: CubeModel, R_bt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation and centre (mm) of the cube in the base frame for tip rotation ``R_bt``."""
    return R_bt, R_bt @ np.array([cube.pivot_mm, 0.0, 0.0])


def projected_quads(
    cam: CameraModel, cube: CubeModel, R_bt: np.ndarray, face_gray: float, ink_gray: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Visible cube quads in pixels with their grey values.

    Returns
    -------
    quads : (m, 4, 2) pixel coordinates
    values : (m,) grey value per unit coverage (ink quads carry ink - face)
    covers : (m,) bool, True for opaque faces
    depth_mm : float, cube-centre depth offset from the straight-pose focal plane
    """
    R, p = cube_pose(cube, R_bt)
    R_ct = cam.R_cb @ R
    t_ct = cam.R_cb @ p + cam.t_cb
    quads, values, covers = [], [], []
    view_face = _MARKER_FACE.get(cam.view)
    for name, corners in cube.faces.items():
        Xc = corners @ R_ct.T + t_ct
        n_c = R_ct @ cube.normals[name]
        centre = Xc.mean(axis=0)
        cos_view = -float(n_c @ centre) / np.linalg.norm(centre)
        if cos_view <= 1e-6:
            continue
        shade = 0.3 + 0.7 * cos_view
        quads.append(_to_pixels(cam.K, Xc))
        values.append(face_gray * shade)
        covers.append(True)
        if name == view_face:
            ink = cube.ink[cam.view] @ R_ct.T + t_ct
            for q in ink:
                quads.append(_to_pixels(cam.K, q))
                values.append((ink_gray - face_gray) * shade)
                covers.append(False)
    depth = float(t_ct[2] - (cam.R_cb @ np.array([cube.pivot_mm, 0, 0]) + cam.t_cb)[2])
    return (
        np.asarray(quads, dtype=float).reshape(-1, 4, 2),
        np.asarray(values, dtype=float),
        np.asarray(covers, dtype=bool),
        depth,
    )


def _to_pixels(K: np.ndarray, Xc: np.ndarray) -> np.ndarray:
    uv = Xc[:, :2] / Xc[:, 2:3]
    return uv * np.array([K[0, 0], K[1, 1]]) + np.array([K[0, 2], K[1, 2]])


def true_marker_corners(
    cam: CameraModel, cube_size_mm: float, marker_size_mm: float, pivot_mm: float, R_bt: np.ndarray
) -> np.ndarray:
    """Pixel coordinates (4, 2) of this camera's marker corners (IPPE order)."""
    X = face_corner_points_tip(cam.view, marker_size_mm, cube_size_mm)
    Xb = X @ R_bt.T + R_bt @ np.array([pivot_mm, 0.0, 0.0])
    return _to_pixels(cam.K, Xb @ cam.R_cb.T + cam.t_cb)
