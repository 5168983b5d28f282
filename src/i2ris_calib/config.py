"""The whole pipeline's configuration: one TOML file, one section per stage.

Loaded and validated by :func:`i2ris_calib.io.config_io.load_config`; documented in
``docs/config.md``; example in ``configs/default.toml``. The stage sections live in their
stages (``fitting.config``, ...); the sections of no stage (``[run]``, ``[columns]`` of the
synced CSV reader :mod:`i2ris_calib.io.columns`) are declared here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from i2ris_calib._validate import validated_config
from i2ris_calib.compensation.config import CompensateConfig
from i2ris_calib.diagnosis.config import DiagnosisConfig
from i2ris_calib.fitting.config import FitConfig
from i2ris_calib.report.config import ReportConfig
from i2ris_calib.simulation.config import SimulationConfig
from i2ris_calib.sync.config import SyncConfig
from i2ris_calib.tracking.config import TrackingConfig

#: the synced CSV's own column names, in file order (the keys naming a column)
STANDARD_COLUMNS = ("time_s", "enc_yaw", "enc_pitch", "yaw_deg", "pitch_deg", "status")
ANGLE_UNITS = ("deg", "rad")


@dataclass(frozen=True)
class ColumnsConfig:
    """Which column of the file is which, and the file's units.

    Each column key is a standard synced-CSV column; its value is that column's
    header in the file (compared with surrounding spaces stripped). Default: the
    standard names, i.e. a synced CSV as ``sync`` writes it.

    Attributes
    ----------
    time_s, enc_yaw, enc_pitch, yaw_deg, pitch_deg, status : str
        Header of the file's column holding the sample time, the yaw and pitch motor
        encoders (counts), the measured yaw and pitch angles and the tracking status.
        A column named here other than its standard name must be in the file; the
        other axis's columns and ``status`` may be absent under their standard names.
    time_unit_s : float
        Seconds per unit of the time column: 1 for s, 0.001 for ms, 1e-9 for ns.
        Times from 1970 (epoch clocks) are read at full precision and counted from
        the first sample (docs/formats.md).
    angle_unit : str
        Unit of the angle columns: ``"deg"`` or ``"rad"`` (converted to degrees).
    """

    time_s: str = "time_s"
    enc_yaw: str = "enc_yaw"
    enc_pitch: str = "enc_pitch"
    yaw_deg: str = "yaw_deg"
    pitch_deg: str = "pitch_deg"
    status: str = "status"
    time_unit_s: float = 1.0
    angle_unit: str = "deg"

    def __post_init__(self) -> None:
        """Validated on construction, not only when loaded from TOML: field types, then
        :meth:`validate`; a CalibError either way."""
        validated_config(self)

    def validate(self) -> None:
        """Raise ValueError on a unit no file has, an empty name or one column read twice."""
        if not (math.isfinite(self.time_unit_s) and self.time_unit_s > 0):
            raise ValueError(
                f"time_unit_s = {self.time_unit_s} must be a number > 0 (seconds "
                "per unit of the time column: 1 for s, 0.001 for ms, 1e-9 for ns)"
            )
        if self.angle_unit not in ANGLE_UNITS:
            raise ValueError(f'angle_unit = \'{self.angle_unit}\' must be "deg" or "rad"')
        seen: dict[str, str] = {}
        for key in STANDARD_COLUMNS:
            name = getattr(self, key).strip()
            if not name:
                raise ValueError(f"{key} is empty; give the header of the file's {key} column")
            if name in seen:
                raise ValueError(
                    f"{seen[name]} and {key} both read column '{name}'; "
                    "each column of the file can be only one of them"
                )
            seen[name] = key

    def mapping(self) -> dict[str, str]:
        """``{standard name: header in the file}`` (stripped) for every column key."""
        return {key: getattr(self, key).strip() for key in STANDARD_COLUMNS}

    def is_mapped(self, key: str) -> bool:
        """True when column ``key`` is read under another name than its standard one."""
        return getattr(self, key).strip() != key


@dataclass(frozen=True)
class RunConfig:
    """Settings of ``run`` itself (TOML section ``[run]``).

    Attributes
    ----------
    diagnose : bool
        Also diagnose every axis and motion direction after ``fit``
        (outputs in ``<run>/diagnose/<axis><direction>/``, shown by the report).
    """

    diagnose: bool = False

    def __post_init__(self) -> None:
        """Validated on construction, not only when loaded from TOML: field types, then
        :meth:`validate`; a CalibError either way."""
        validated_config(self)

    def validate(self) -> None:
        """Raise ValueError on a non-boolean value."""
        if not isinstance(self.diagnose, bool):
            raise ValueError("diagnose must be true or false")


@dataclass(frozen=True)
class PipelineConfig:
    """All stage sections; every key has a default so an empty file is valid."""

    simulate: SimulationConfig = field(default_factory=SimulationConfig)
    track: TrackingConfig = field(default_factory=TrackingConfig)
    sync: SyncConfig = field(default_factory=SyncConfig)
    fit: FitConfig = field(default_factory=FitConfig)
    diagnose: DiagnosisConfig = field(default_factory=DiagnosisConfig)
    report: ReportConfig = field(default_factory=ReportConfig)
    compensate: CompensateConfig = field(default_factory=CompensateConfig)
    run: RunConfig = field(default_factory=RunConfig)
    columns: ColumnsConfig = field(default_factory=ColumnsConfig)

    def __post_init__(self) -> None:
        """Every section checked on construction: ``PipelineConfig(fit="trf")`` or
        ``PipelineConfig(fit=FitConfig)`` is a CalibError naming the section."""
        validated_config(self)
