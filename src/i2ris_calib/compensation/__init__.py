"""Feedforward compensation by exact inversion of fitted hysteresis models."""

from i2ris_calib.compensation.inverse import STATUS_NAMES, CompensationResult, compensate

__all__ = ["STATUS_NAMES", "CompensationResult", "compensate"]
