"""The catalogue of candidate effects, re-exported from its home in the model layer,
:mod:`i2ris_calib.hysteresis.effects` (docs/diagnosis.md, Python API)."""

from i2ris_calib.hysteresis.effects import (
    CATALOGUE,
    RATE_WINDOW_S,
    Effect,
    EffectModel,
    add_effect,
    base_of,
    build_model,
    effects_of,
    get_effect,
    model_values,
    other_axis_moves,
)

__all__ = [
    "CATALOGUE",
    "RATE_WINDOW_S",
    "Effect",
    "EffectModel",
    "add_effect",
    "base_of",
    "build_model",
    "effects_of",
    "get_effect",
    "model_values",
    "other_axis_moves",
]
