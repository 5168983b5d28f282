"""The whole pipeline's configuration: one TOML file, one section per stage.

Loaded and validated by :func:`i2ris_calib.io.config_io.load_config`; documented in
``docs/config.md``; example in ``configs/default.toml``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from i2ris_calib._validate import validated_config
from i2ris_calib.compensation.config import CompensateConfig
from i2ris_calib.diagnosis.config import DiagnosisConfig
from i2ris_calib.fitting.config import FitConfig
from i2ris_calib.io.columns import ColumnsConfig
from i2ris_calib.report.config import ReportConfig
from i2ris_calib.simulation.config import SimulationConfig
from i2ris_calib.sync.config import SyncConfig
from i2ris_calib.tracking.config import TrackingConfig


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
