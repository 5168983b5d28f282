"""Configuration of the tracking stage (TOML section ``[track]``, see docs/tracking.md)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from i2ris_calib._validate import validated_config


@dataclass(frozen=True)
class TrackingConfig:
    """Settings of ``i2ris-calib track``. Units are in the field names."""

    # --- detection ----------------------------------------------------------------
    # "edges" = ArUco SUBPIX, then line fits to the four outer edges (tracking/edges.py)
    corner_refinement: Literal["edges", "subpix", "contour", "apriltag", "none"] = "edges"
    edge_half_width_px: int = 6  # pixels each side of an edge in the edge integrals
    corner_win_size_px: int = 5  # half window of the ArUco sub-pixel refinement
    corner_max_iterations: int = 50
    corner_accuracy_px: float = 0.001  # sub-pixel refinement stops below this step
    use_roi: bool = True  # search around the last detection first
    roi_margin: float = 0.4  # ROI = marker bounding box grown by this fraction of its size
    workers: int = 2  # camera streams decoded/detected in parallel (processes); 1 = serial
    # --- optics -------------------------------------------------------------------
    weak_perspective_focal_px: float = 1.0e6  # pinhole stand-in for weak perspective
    # --- fusion -------------------------------------------------------------------
    max_interp_gap_s: float = 0.1  # interpolate the other camera only across gaps <= this
    same_frame_tol_s: float = 1.0e-4  # frames closer than this count as simultaneous
    iterations: int = 12  # Levenberg-Marquardt iterations of the joint two-camera fit
    extrinsic_rounds: int = 3  # alternations camera-to-camera rotation <-> per-frame poses
    ambiguity_deg: float = 0.5  # two fits differing by more than this are competing
    ambiguity_ratio: float = 2.0  # competing fits with cost ratio below this are ambiguous
    max_step_deg: float = 5.0  # continuity: max rotation between consecutive measured frames
    continuity_gap_s: float = 0.5  # continuity is used only across gaps up to this
    max_reproj_err_px: float = 1.0  # RMS reprojection error above this -> rejected
    # --- reference (straight) pose -----------------------------------------------
    reference_start_s: float = 0.0  # window start, s after the first frame
    reference_duration_s: float = 0.8  # window length (s); the tip must be straight in it
    # roll of the reference: "session" = fitted over all frames (no twist in single-axis
    # bends), "window" = the window mean only (poorly determined, leaks into the angles)
    reference_roll: Literal["session", "window"] = "session"
    # --- calibrate: the ChArUco board ----------------------------------------------
    charuco_squares: tuple[int, int] = (7, 5)  # squares along x, y
    charuco_square_mm: float = 1.0
    charuco_marker_mm: float = 0.7
    charuco_dictionary: str = "DICT_4X4_50"
    calibration_every_nth_frame: int = 10  # video input: use every n-th frame
    # --- output -------------------------------------------------------------------
    plain: bool = True  # also write single-camera IPPE top-solution angles (comparison)

    def __post_init__(self) -> None:
        """Validated on construction, not only when loaded from TOML: field types, then
        :meth:`validate`; a CalibError either way."""
        validated_config(self)

    def validate(self) -> None:
        """Raise ValueError on inconsistent settings."""
        if self.corner_win_size_px < 1 or self.corner_max_iterations < 1:
            raise ValueError("corner_win_size_px and corner_max_iterations must be >= 1")
        if self.edge_half_width_px < 2:
            raise ValueError("edge_half_width_px must be >= 2")
        if self.roi_margin < 0.1:
            raise ValueError("roi_margin must be >= 0.1")
        if self.workers < 1:
            raise ValueError("workers must be >= 1")
        if self.reference_duration_s <= 0:
            raise ValueError("reference_duration_s must be > 0")
        if self.reference_roll not in ("session", "window"):
            raise ValueError(
                f"reference_roll must be 'session' or 'window', got {self.reference_roll!r}"
            )
        if self.ambiguity_ratio < 1.0:
            raise ValueError("ambiguity_ratio must be >= 1")
        if not 0 < self.charuco_marker_mm < self.charuco_square_mm:
            raise ValueError("charuco_marker_mm must be > 0 and smaller than charuco_square_mm")
        if min(self.charuco_squares) < 2 or self.calibration_every_nth_frame < 1:
            raise ValueError(
                "charuco_squares must be >= 2 each and calibration_every_nth_frame >= 1"
            )
        if self.max_reproj_err_px <= 0 or self.iterations < 1:
            raise ValueError("max_reproj_err_px must be > 0 and iterations >= 1")
        positive = ("corner_accuracy_px", "weak_perspective_focal_px", "ambiguity_deg",
                    "max_step_deg", "max_reproj_err_px", "reference_duration_s",
                    "charuco_square_mm", "charuco_marker_mm", "roi_margin")  # fmt: skip
        non_negative = ("max_interp_gap_s", "same_frame_tol_s", "continuity_gap_s",
                        "reference_start_s", "extrinsic_rounds")  # fmt: skip
        for name in positive + non_negative:
            v = getattr(self, name)
            if not math.isfinite(v) or v < 0 or (v == 0 and name in positive):
                need = "> 0" if name in positive else ">= 0"
                raise ValueError(f"{name} = {v} must be a finite number {need}")
