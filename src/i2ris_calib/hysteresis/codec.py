"""The model codec: a model (a registry kind, the general EGPI, a model extended by
effects) <-> a JSON-ready record, for the files that hold models (docs/formats.md).

* :func:`encode_model` / :func:`decode_model`: the ``model`` record of a saved fit
  (``FitResult.save``, format ``i2ris-calib.fit-result/1``): its ``codec`` (``kind``, or
  ``effects`` for a model extended by effects: the base model's record, then each
  effect innermost first with its label, values and fixed flags), the kind's settings
  and every parameter's declaration and value. Decoding rebuilds the same model, so
  ``predict`` gives the saved output to the last bit.
* :func:`model_to_dict` / :func:`model_from_dict`: ``final_model.json`` (format
  :data:`MODEL_SCHEMA`, docs/diagnosis.md), what ``diagnose`` writes::

    {"schema": "i2ris-calib.model/1",
     "base": {"kind": "egpi", "n": 30, "deadband_counts": 0.0,
              "params": {"a1": ..., "v_f": ...}, "fixed": ["v_f"]},
     "effects": [{"name": "time_delay", "label": "time_delay", "params": {"tau_s": 0.12}}],
     "params": {"a1": ..., "time_delay.tau_s": 0.12}}

  ``effects`` are innermost first (the order they were added); ``params`` repeats
  every value under the extended model's parameter names, for readers that only want
  numbers.
* :func:`fit_json_fields` / :func:`model_from_fit_json`: what a model record of the
  ``fit`` command's fit.json (schema ``i2ris-calib.fit/1``, docs/fit.md, written by
  :mod:`i2ris_calib.io.fit`) says of the model itself: the parameter units, the base
  model's operators and dead band; its ``params`` are the fitted values.

Both know every effect of the catalogue (:mod:`i2ris_calib.hysteresis.effects`): a
model with effects loads with no import beforehand.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace

from i2ris_calib.errors import CalibError
from i2ris_calib.hysteresis.effects import (
    EffectModel,
    base_of,
    build_model,
    effects_of,
    get_effect,
)
from i2ris_calib.hysteresis.models import EGPIModel, egpi_model
from i2ris_calib.hysteresis.registry import (
    BUILT_KINDS,
    DEFAULT_DEADBAND_COUNTS,
    DEFAULT_N_OPERATORS,
    kind_of,
    model_for_kind,
)
from i2ris_calib.model import Model

#: The format of final_model.json (:func:`model_to_dict`).
MODEL_SCHEMA = "i2ris-calib.model/1"


# ------------------------------------------------------- a saved fit's model record


def encode_model(model: Model) -> dict:
    """JSON-ready record of ``model``: its codec, structure and every parameter's value,
    bounds and fixed flag (:func:`decode_model` rebuilds it)."""
    rec = _encode_effects(model)
    if rec is not None:
        return {"codec": "effects", **rec}
    rec = _encode_kind(model)
    if rec is not None:
        return {"codec": "kind", **rec}
    raise CalibError(
        f"cannot save model '{model.name}' ({type(model).__name__}): saved fits carry the "
        "registry's model kinds, the general EGPI and models extended by catalogue effects"
    )


def decode_model(rec: Mapping) -> Model:
    """The model :func:`encode_model` wrote."""
    name = rec.get("codec")
    if name == "kind":
        return _decode_kind(rec)
    if name == "effects":
        return _decode_effects(rec)
    raise CalibError(f"saved model: unknown codec {name!r} (kind, effects)")


def declarations(model: Model) -> list[dict]:
    """Every parameter's ``name``, ``value``, ``lower``, ``upper``, ``fixed``."""
    return [
        {"name": p.name, "value": float(p.value), "lower": float(p.lower),
         "upper": float(p.upper), "fixed": bool(p.fixed)}
        for p in model.parameters
    ]  # fmt: skip


def declared(model, decl: Sequence[Mapping]):
    """``model`` (a ParametricModel) with the values, bounds and fixed flags of ``decl``
    (units and meanings stay the model's); CalibError when the names differ."""
    names = [d["name"] for d in decl]
    if list(model.names) != names:
        raise CalibError(
            f"saved model: parameters {names} do not match model '{model.name}' "
            f"({list(model.names)})"
        )
    params = tuple(
        replace(p, value=float(d["value"]), lower=float(d["lower"]), upper=float(d["upper"]),
                fixed=bool(d["fixed"]))
        for p, d in zip(model.parameters, decl, strict=True)
    )  # fmt: skip
    return replace(model, parameters=params)


def _encode_kind(model: Model) -> dict | None:
    info = kind_of(model)
    if info is not None and type(model) is info.model_class:
        rec = {"kind": info.kind, "n": int(model.n), "parameters": declarations(model)}
        if info.uses_deadband:
            rec["deadband_counts"] = float(model.deadband_counts)
        return rec
    if type(model) is EGPIModel:
        return {
            "kind": "egpi_general",
            "envelopes": [[el.kind, er.kind] for el, er in model.envelopes],
            "n": int(model.n),
            "deadband": float(model.deadband),
            "parameters": declarations(model),
        }
    return None


def _decode_kind(rec: Mapping) -> Model:
    decl = rec["parameters"]
    if rec["kind"] == "egpi_general":
        values = {d["name"]: float(d["value"]) for d in decl}
        model = egpi_model(
            [tuple(e) for e in rec["envelopes"]], values, n=int(rec["n"]),
            deadband=float(rec["deadband"]),
        )  # fmt: skip
    else:
        extra = (
            {"deadband_counts": float(rec["deadband_counts"])} if "deadband_counts" in rec else {}
        )
        model = model_for_kind(rec["kind"], n=int(rec["n"]), **extra)
    return declared(model, decl)


# A saved fit (FitResult.save) of an extended model: the base model's record, then each
# effect innermost first with its label, values and fixed flags (values exact, not
# checked against the effect's bounds: a fit may end outside them).
def _encode_effects(model: Model) -> dict | None:
    if not isinstance(model, EffectModel):
        return None
    stack = []
    while isinstance(model, EffectModel):
        stack.append(
            {
                "name": model.effect.name,
                "label": model.label,
                "values": [float(x) for x in model.effect_values],
                "fixed": [bool(f) for f in model.fixed],
            }
        )
        model = model.inner
    return {"base": encode_model(model), "effects": stack[::-1]}


def _decode_effects(rec: Mapping) -> Model:
    model = decode_model(rec["base"])
    for e in rec["effects"]:
        model = EffectModel(
            inner=model,
            effect=get_effect(e["name"]),
            effect_values=tuple(float(x) for x in e["values"]),
            label=str(e["label"]),
            fixed=tuple(bool(f) for f in e["fixed"]),
        )
    return model


# ---------------------------------------------------------------- final_model.json


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


def _base_settings(model: Model, n_missing: int) -> tuple[int, dict]:
    """The base model's number of operators (``n_missing`` for a base without) and
    ``{"deadband_counts": ...}`` for a base with a dead band in counts (else ``{}``)."""
    base = base_of(model)
    n = int(getattr(base, "n", n_missing))
    if hasattr(base, "deadband_counts"):
        return n, {"deadband_counts": float(base.deadband_counts)}
    return n, {}


def model_to_dict(model: Model) -> dict:
    """JSON-ready dict of an (extended) model with its parameter values."""
    base = base_of(model)
    n, deadband = _base_settings(model, DEFAULT_N_OPERATORS)
    rec = {
        "kind": base_kind(model),
        "n": n,
        "params": {p.name: float(p.value) for p in base.parameters},
        "fixed": [p.name for p in base.parameters if p.fixed],
        **deadband,
    }
    return {
        "schema": MODEL_SCHEMA,
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
    if obj.get("schema") != MODEL_SCHEMA:
        raise CalibError(
            f"model file: schema is {obj.get('schema')!r}, expected '{MODEL_SCHEMA}' (docs/diagnosis.md)"
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


# ------------------------------------------------------ fit.json's model records


def fit_json_fields(model: Model) -> dict:
    """What a fit.json model record says of ``model`` itself, in the record's key order:
    ``units`` (every parameter's), ``n_operators`` (the base model's; 0 for a base
    without operators) and, for a base with a dead band in counts, ``deadband_counts``.
    The record's other keys (``params``, ``stderr``, metrics, ...) are the fit's."""
    n, deadband = _base_settings(model, 0)
    return {"units": {p.name: p.unit for p in model.parameters}, "n_operators": n, **deadband}


def model_from_fit_json(kind: str, rec: Mapping) -> Model:
    """The fitted model of registry kind ``kind`` a fit.json model record ``rec``
    describes: its ``params`` on the kind's model with the record's ``n_operators`` and
    ``deadband_counts`` (the registry's defaults when missing), built by
    :func:`~i2ris_calib.hysteresis.registry.model_for_kind`."""
    return model_for_kind(
        kind,
        n=int(rec.get("n_operators") or DEFAULT_N_OPERATORS),
        deadband_counts=float(rec.get("deadband_counts", DEFAULT_DEADBAND_COUNTS)),
        **rec["params"],
    )
