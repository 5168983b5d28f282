"""Configuration of the report stage (TOML section ``[report]``, see docs/report.md)."""

from __future__ import annotations

from dataclasses import dataclass

from i2ris_calib._validate import validated_config


@dataclass(frozen=True)
class ReportConfig:
    """Settings of the report stage. Units are in the field names.

    Attributes
    ----------
    figure_dpi : int
        Resolution of every PNG figure (dots per inch). Figure sizes are fixed in
        inches, so this sets the pixel size and the file size.
    max_plot_points : int
        Longest series drawn per curve; longer series are thinned by taking every
        k-th sample (deterministic). Keeps the HTML small for long recordings.
    detection_window_s : float
        Width of the moving window for the detection-rate-over-time plot (s, camera clock).
    """

    figure_dpi: int = 100
    max_plot_points: int = 20000
    detection_window_s: float = 1.0

    def __post_init__(self) -> None:
        """Validated on construction, not only when loaded from TOML: field types, then
        :meth:`validate`; a CalibError either way."""
        validated_config(self)

    def validate(self) -> None:
        """Raise ValueError on inconsistent settings."""
        if not 30 <= self.figure_dpi <= 600:
            raise ValueError(f"figure_dpi must be in [30, 600], got {self.figure_dpi}")
        if self.max_plot_points < 100:
            raise ValueError(f"max_plot_points must be >= 100, got {self.max_plot_points}")
        if not self.detection_window_s > 0:
            raise ValueError(f"detection_window_s must be > 0 s, got {self.detection_window_s}")
