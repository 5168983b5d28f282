"""Configuration of the fitting stage (TOML section, see docs/config.md)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class FitConfig:
    """Settings of the fitting stage. Units are in the field names."""

    def validate(self) -> None:
        """Raise ValueError on inconsistent settings."""
