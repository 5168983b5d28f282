"""Data-driven starts: the recipe lives with the models, :mod:`i2ris_calib.hysteresis.start`
(``model.guess``); these names are re-exported for the fitting and diagnosis stages."""

from __future__ import annotations

from i2ris_calib.hysteresis.start import (
    envelope_values,
    flag_point,
    initial_values,
    keep_fixed,
    reversal_distance,
    segments,
    shape_defaults,
    start_values,
)

__all__ = [
    "envelope_values",
    "flag_point",
    "initial_values",
    "keep_fixed",
    "reversal_distance",
    "segments",
    "shape_defaults",
    "start_values",
]
