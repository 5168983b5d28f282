"""Configuration of the report stage (TOML section, see docs/config.md)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class ReportConfig:
    """Settings of the report stage. Units are in the field names."""

    def validate(self) -> None:
        """Raise ValueError on inconsistent settings."""
