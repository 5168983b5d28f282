"""Extended models <-> plain dicts (the ``final_model.json`` format, docs/diagnosis.md).

Format ``i2ris-calib.model/1``::

    {"schema": "i2ris-calib.model/1",
     "base": {"kind": "egpi", "n": 30, "deadband_counts": 0.0,
              "params": {"a1": ..., "v_f": ...}, "fixed": ["v_f"]},
     "effects": [{"name": "time_delay", "label": "time_delay", "params": {"tau_s": 0.12}}],
     "params": {"a1": ..., "time_delay.tau_s": 0.12}}

``effects`` are innermost first (the order they were added); ``params`` repeats
every value under the extended model's parameter names, for readers that only
want numbers.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

from i2ris_calib.diagnosis.effects import base_of, build_model, effects_of
from i2ris_calib.errors import CalibError
from i2ris_calib.hysteresis.model import Model
from i2ris_calib.hysteresis.registry import (
    BUILT_KINDS,
    DEFAULT_DEADBAND_COUNTS,
    DEFAULT_N_OPERATORS,
    model_for_kind,
)

SCHEMA = "i2ris-calib.model/1"


def base_kind(model: Model) -> str:
    """The registry kind (``"gpi"``, ``"egpi"``, ``"egpi_c"``) of the base model: the
    kinds this format can rebuild (:func:`~i2ris_calib.hysteresis.registry.model_for_kind`)."""
    name = base_of(model).name
    if name in BUILT_KINDS:
        return name
    raise CalibError(
        f"cannot save base model '{name}': only the model kinds {', '.join(BUILT_KINDS)} are "
        "supported"
    )


def model_to_dict(model: Model) -> dict:
    """JSON-ready dict of an (extended) model with its parameter values."""
    base = base_of(model)
    rec = {
        "kind": base_kind(model),
        "n": int(getattr(base, "n", DEFAULT_N_OPERATORS)),
        "params": {p.name: float(p.value) for p in base.parameters},
        "fixed": [p.name for p in base.parameters if p.fixed],
    }
    if hasattr(base, "deadband_counts"):
        rec["deadband_counts"] = float(base.deadband_counts)
    return {
        "schema": SCHEMA,
        "base": rec,
        "effects": [{"name": n, "label": lbl, "params": v} for n, lbl, v in effects_of(model)],
        "params": {p.name: float(p.value) for p in model.parameters},
    }


def base_from_dict(rec: Mapping) -> Model:
    """The base model described by ``rec`` (the ``base`` entry), built by the one
    kind -> model registry (:func:`~i2ris_calib.hysteresis.registry.model_for_kind`,
    its defaults for a missing ``n`` or ``deadband_counts``)."""
    try:
        kind, params = rec["kind"], dict(rec["params"])
        model = model_for_kind(
            kind,
            n=int(rec.get("n", DEFAULT_N_OPERATORS)),
            deadband_counts=float(rec.get("deadband_counts", DEFAULT_DEADBAND_COUNTS)),
            **params,
        )
        fixed = set(rec.get("fixed", []))
    except (KeyError, TypeError, ValueError) as exc:
        raise CalibError(f"model file: bad 'base' record ({exc}); see docs/diagnosis.md") from None
    return replace(
        model, parameters=tuple(replace(p, fixed=p.name in fixed) for p in model.parameters)
    )


def model_from_dict(obj: Mapping) -> Model:
    """Rebuild the extended model saved by :func:`model_to_dict`."""
    if obj.get("schema") != SCHEMA:
        raise CalibError(
            f"model file: schema is {obj.get('schema')!r}, expected '{SCHEMA}' (docs/diagnosis.md)"
        )
    base = base_from_dict(obj.get("base", {}))
    effects = obj.get("effects", [])
    if not isinstance(effects, list):
        raise CalibError("model file: 'effects' must be a list (docs/diagnosis.md)")
    model = base
    for e in effects:
        try:
            name, params = e["name"], dict(e.get("params", {}))
            if name == "dead_zone" and "width_counts" in params:
                name = "backlash"  # files written before dead_zone became the dead band
            model = build_model(model, {name: params})
        except (KeyError, TypeError) as exc:
            raise CalibError(f"model file: bad effect record {e!r} ({exc})") from None
    return model
