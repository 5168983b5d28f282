"""Configuration of the tracking stage (TOML section, see docs/config.md)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class TrackingConfig:
    """Settings of the tracking stage. Units are in the field names."""

    def validate(self) -> None:
        """Raise ValueError on inconsistent settings."""
