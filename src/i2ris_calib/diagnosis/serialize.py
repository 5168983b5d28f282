"""Extended models <-> plain dicts (the ``final_model.json`` format, docs/diagnosis.md):
re-exported from the model codec, :mod:`i2ris_calib.hysteresis.codec`, where the
format is written and read."""

from i2ris_calib.hysteresis.codec import (
    MODEL_SCHEMA as SCHEMA,
)
from i2ris_calib.hysteresis.codec import (
    base_from_dict,
    base_kind,
    model_from_dict,
    model_to_dict,
)

__all__ = ["SCHEMA", "base_from_dict", "base_kind", "model_from_dict", "model_to_dict"]
