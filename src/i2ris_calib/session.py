"""Description of one recording session (``session.toml``), as frozen dataclasses.

The file format is documented in ``docs/session.md``. Paths inside are relative to
the session folder. Loading lives in :mod:`i2ris_calib.io.session`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal


@dataclass(frozen=True)
class EncoderLogSpec:
    """Where the motor encoder log is and how to read it (controller clock).

    Documented in ``docs/sync.md``. ``file`` is relative to the session folder: a CSV
    file, a ROS1 ``.bag`` file, or a ROS2 bag folder (``metadata.yaml`` + ``.db3``/``.mcap``).
    """

    file: str = "encoders.csv"
    format: Literal["csv", "rosbag"] = "csv"
    # CSV: one row per sample; sync_column is optional (absent = no sync event).
    time_column: str = "time_s"
    time_unit_s: float = 1.0  # seconds per unit of the time column/stamps (1e-9 for ns)
    yaw_column: str = "enc_yaw"
    pitch_column: str = "enc_pitch"
    sync_column: str = "sync_flash"
    # ROS bags (ROS1 .bag or ROS2 folder/.mcap/.db3): one topic per motor.
    yaw_topic: str = "/i2ris/yaw/encoder"
    pitch_topic: str = "/i2ris/pitch/encoder"
    sync_topic: str = ""  # "" = no sync event logged
    value_field: str = "data"  # message field holding the count (dotted path allowed)
    value_index: int = 0  # element of value_field when it is an array (JointState.position)
    sync_field: str = "data"  # message field of sync_topic, nonzero = LED on
    time_source: Literal["log", "header"] = "log"  # bag receive time or msg.header.stamp
    # fastest possible encoder change, counts/s; faster samples that come back are glitches
    # (replaced by interpolation, recorded in sync.json); 0 = derived from the log itself
    max_counts_per_s: float = 0.0

    def validate(self) -> None:
        """Raise ValueError on values no log can have."""
        if not (math.isfinite(self.time_unit_s) and self.time_unit_s > 0):
            raise ValueError(
                f"time_unit_s = {self.time_unit_s} must be a number > 0 (seconds per unit of "
                "the time column: 1 for s, 0.001 for ms, 1e-9 for ns)"
            )
        if self.value_index < 0:
            raise ValueError(f"value_index = {self.value_index} must be >= 0")
        if not (math.isfinite(self.max_counts_per_s) and self.max_counts_per_s >= 0):
            raise ValueError(
                f"max_counts_per_s = {self.max_counts_per_s} must be >= 0 (0 = derived from the log)"
            )


@dataclass(frozen=True)
class CameraSpec:
    """One microscope camera: its video, frame timestamps and optics."""

    video: str = ""
    timestamps: str = ""
    model: Literal["weak_perspective", "pinhole"] = "weak_perspective"
    calibration: str = ""  # OpenCV or ROS camera_info YAML (pinhole); optional for weak perspective
    pixel_size_mm: float = (
        0.0  # object-space mm per pixel (weak perspective); 0 = derive from marker
    )
    marker_id: int = 0
    # ideal viewing direction of this camera, in the robot base frame
    view: Literal["top", "side"] = "top"

    def validate(self) -> None:
        """Raise ValueError on values no camera can have."""
        if self.marker_id < 0:
            raise ValueError(f"marker_id = {self.marker_id} must be >= 0 (an ArUco id)")
        if not (math.isfinite(self.pixel_size_mm) and self.pixel_size_mm >= 0):
            raise ValueError(f"pixel_size_mm = {self.pixel_size_mm} must be >= 0 (0 = derived)")


@dataclass(frozen=True)
class MarkerSpec:
    """The ArUco cube on the gripper."""

    dictionary: str = "DICT_4X4_50"
    marker_size_mm: float = 0.8
    cube_size_mm: float = 1.0

    def validate(self) -> None:
        """Raise ValueError unless 0 < marker_size_mm <= cube_size_mm (finite)."""
        m, c = self.marker_size_mm, self.cube_size_mm
        if not (math.isfinite(m) and m > 0):
            raise ValueError(
                f"marker_size_mm = {m} must be > 0 (the printed marker's black outer edge, mm)"
            )
        if not (math.isfinite(c) and c >= m):
            raise ValueError(
                f"cube_size_mm = {c} must be >= marker_size_mm = {m} (the marker sits on a "
                "cube face; measure both edges in mm)"
            )


@dataclass(frozen=True)
class SessionSpec:
    """A whole session: encoder log, cameras (by name) and marker geometry."""

    name: str = "session"
    encoder: EncoderLogSpec = field(default_factory=EncoderLogSpec)
    cameras: dict = field(default_factory=dict)  # name -> CameraSpec (built by io.session)
    marker: MarkerSpec = field(default_factory=MarkerSpec)
    notes: str = ""

    def validate(self) -> None:
        """Raise ValueError when ``name`` cannot be one folder name (run writes OUT/<name>)."""
        bad = (
            any(c in self.name for c in "/\\")
            or self.name.strip() in (".", "..")
            or any(ord(c) < 32 for c in self.name)
        )
        if bad:
            raise ValueError(
                f"name = {self.name!r} must be usable as one folder name (no '/', '\\', "
                "control characters, '.' or '..'; outputs go to OUT/<name>)"
            )
