"""ArUco detection of one marker per frame, with a region of interest around the last hit.

OpenCV 5: ``cv2.aruco.ArucoDetector`` (objdetect). Corner convention: with
``CORNER_REFINE_SUBPIX`` the corners lie on the true pixel edges in OpenCV pixel
coordinates (pixel centres at integers); NONE/CONTOUR return the centres of the
outermost pixels and APRILTAG is about +0.5 px off (docs/tracking.md).
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass

import cv2
import numpy as np

from i2ris_calib.errors import CalibError
from i2ris_calib.tracking.config import TrackingConfig
from i2ris_calib.tracking.edges import refine_corners_by_edges

_REFINE = {"edges": "CORNER_REFINE_SUBPIX", "none": "CORNER_REFINE_NONE", "subpix": "CORNER_REFINE_SUBPIX",
           "contour": "CORNER_REFINE_CONTOUR", "apriltag": "CORNER_REFINE_APRILTAG"}  # fmt: skip


def aruco_dictionary(name: str):
    """``cv2.aruco.Dictionary`` for a name such as ``DICT_4X4_50``; CalibError if unknown."""
    if not name.startswith("DICT_") or not hasattr(cv2.aruco, name):
        valid = [n for n in dir(cv2.aruco) if n.startswith("DICT_")]

        close = difflib.get_close_matches(name, valid, n=1)
        hint = f"; did you mean '{close[0]}'?" if close else " (e.g. DICT_4X4_50)"
        raise CalibError(f"unknown ArUco dictionary '{name}'{hint}")
    return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))


@dataclass
class Detection:
    """One frame's result: corners (4, 2) in IPPE order or None, and why not."""

    corners: np.ndarray | None
    other_ids: tuple[int, ...] = ()  # ids seen that are not the wanted one
    used_roi: bool = False
    edge_refined: bool = False


class MarkerDetector:
    """Finds marker ``marker_id`` in grey frames; searches a ROI around the last hit.

    Parameters
    ----------
    dictionary : str
        ArUco dictionary name.
    marker_id : int
        The marker wanted in this camera.
    cfg : TrackingConfig
    margin_ratio : float, optional
        White margin around the marker / marker edge (``(cube - marker) / (2 marker)``);
        lets the edge corners keep their runs inside a foreshortened margin
        (:func:`~.edges.refine_corners_by_edges`). None: not adapted.
    """

    def __init__(
        self,
        dictionary: str,
        marker_id: int,
        cfg: TrackingConfig,
        margin_ratio: float | None = None,
    ):
        self.marker_id = int(marker_id)
        self.cfg = cfg
        self.margin_ratio = margin_ratio
        # the black border is one cell of the (markerSize + 2)-cell marker
        self.border_ratio = 1.0 / (int(aruco_dictionary(dictionary).markerSize) + 2)
        p = cv2.aruco.DetectorParameters()
        p.cornerRefinementMethod = getattr(cv2.aruco, _REFINE[cfg.corner_refinement])
        p.cornerRefinementWinSize = int(cfg.corner_win_size_px)
        p.cornerRefinementMaxIterations = int(cfg.corner_max_iterations)
        p.cornerRefinementMinAccuracy = float(cfg.corner_accuracy_px)
        # markers near the border are kept here and judged by touches_border()
        p.minDistanceToBorder = 0
        self._full = cv2.aruco.ArucoDetector(aruco_dictionary(dictionary), p)
        self._last: np.ndarray | None = None

    def detect(self, gray: np.ndarray) -> Detection:
        """Detect in a grey frame (h, w) uint8: ROI first when possible, else full frame.

        With ``corner_refinement = "edges"`` the ArUco corners are then replaced by
        the edge-line corners (:func:`~.edges.refine_corners_by_edges`) when that
        succeeds (``edge_refined``).
        """
        det = self._locate(gray)
        if det.corners is not None and self.cfg.corner_refinement == "edges":
            ref = refine_corners_by_edges(
                gray,
                det.corners,
                self.cfg.edge_half_width_px,
                margin_ratio=self.margin_ratio,
                border_ratio=self.border_ratio,
            )
            if ref is not None:
                det.corners, det.edge_refined = ref, True
        return det

    def _locate(self, gray: np.ndarray) -> Detection:
        if self.cfg.use_roi and self._last is not None:
            roi = self._roi(gray.shape)
            y0, y1, x0, x1 = roi
            det = self._detect_in(gray[y0:y1, x0:x1], (x0, y0))
            if det.corners is not None and self._inside(det.corners, roi, gray.shape):
                det.used_roi = True
                self._last = det.corners
                return det
        det = self._detect_in(gray, (0, 0))
        self._last = det.corners
        return det

    def _detect_in(self, img: np.ndarray, origin: tuple[int, int]) -> Detection:
        corners, ids, _ = self._full.detectMarkers(img)
        if ids is None or len(ids) == 0:
            return Detection(None)
        ids = ids.ravel()
        hit = np.flatnonzero(ids == self.marker_id)
        others = tuple(int(i) for i in ids if i != self.marker_id)
        if hit.size != 1:
            return Detection(None, others)
        c = np.asarray(corners[hit[0]], dtype=np.float64).reshape(4, 2) + np.asarray(origin, float)
        return Detection(c, others)

    def _roi(self, shape: tuple[int, ...]) -> tuple[int, int, int, int]:
        c = self._last
        size = float(np.max(c.max(axis=0) - c.min(axis=0)))
        m = self.cfg.roi_margin * size
        x0 = int(max(np.floor(c[:, 0].min() - m), 0))
        x1 = int(min(np.ceil(c[:, 0].max() + m), shape[1]))
        y0 = int(max(np.floor(c[:, 1].min() - m), 0))
        y1 = int(min(np.ceil(c[:, 1].max() + m), shape[0]))
        return y0, y1, x0, x1

    @staticmethod
    def _inside(c: np.ndarray, roi: tuple, shape: tuple) -> bool:
        """Marker well inside the ROI (else it may be cut by the ROI border)."""
        y0, y1, x0, x1 = roi
        pad = 3.0
        ok_x = (c[:, 0].min() - x0 > pad or x0 == 0) and (
            x1 - c[:, 0].max() > pad or x1 == shape[1]
        )
        ok_y = (c[:, 1].min() - y0 > pad or y0 == 0) and (
            y1 - c[:, 1].max() > pad or y1 == shape[0]
        )
        return bool(ok_x and ok_y)


def touches_border(corners: np.ndarray, shape: tuple[int, ...], margin_px: float = 2.0) -> bool:
    """Whether a detected marker touches the image border (partly outside the image)."""
    h, w = shape[:2]
    return bool(
        corners[:, 0].min() < margin_px
        or corners[:, 1].min() < margin_px
        or corners[:, 0].max() > w - 1 - margin_px
        or corners[:, 1].max() > h - 1 - margin_px
    )
