"""TOML configuration -> frozen dataclasses, validated on load.

Every config section is a frozen dataclass whose fields carry defaults. Loading
walks the TOML table against the dataclass fields: unknown keys are rejected with
the closest valid name suggested, values are type-checked and coerced (int -> float,
list -> tuple), nested dataclasses are recursed into, and each dataclass may define
``validate(self) -> None`` raising ``ValueError`` for cross-field checks.
"""

from __future__ import annotations

import dataclasses
import difflib
import json
import sys
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from i2ris_calib.config import PipelineConfig
from i2ris_calib.errors import CalibError

T = TypeVar("T")


def load_toml(path: str | Path) -> dict[str, Any]:
    """Read a TOML file into a dict; one-line CalibError when unreadable or invalid."""
    p = Path(path)
    if not p.is_file():
        raise CalibError(
            f"config file not found: {p} (give an existing TOML file, see docs/config.md)"
        )
    try:
        # utf-8-sig: a byte-order mark (some Windows editors write one) is dropped
        return tomllib.loads(p.read_text(encoding="utf-8-sig"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise CalibError(f"invalid TOML in {p}: {exc}") from None


def dataclass_from_mapping(cls: type[T], data: Mapping[str, Any], where: str = "") -> T:
    """Build the frozen dataclass ``cls`` from ``data``, validating every key.

    Parameters
    ----------
    cls : dataclass type
        Target type; every field must have a default.
    data : mapping
        Parsed TOML table.
    where : str
        Location prefix for messages, e.g. ``"config.toml [fit]"``.
    """
    if not isinstance(data, Mapping):
        raise CalibError(f"{where or cls.__name__}: expected a table, got {type(data).__name__}")
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    hints = typing.get_type_hints(cls)
    kwargs: dict[str, Any] = {}
    for key, value in data.items():
        if key not in fields:
            close = difflib.get_close_matches(key, list(fields), n=1, cutoff=0.5)
            hint = (
                f"; did you mean '{close[0]}'?"
                if close
                else f"; valid keys: {', '.join(sorted(fields))}"
            )
            raise CalibError(f"{where or cls.__name__}: unknown key '{key}'{hint}")
        if dataclasses.is_dataclass(hints[key]):  # a section: "config.toml [track]"
            sub = f"{where} [{key}]" if where else f"[{key}]"
        else:
            sub = f"{where}.{key}" if where else key
        kwargs[key] = _coerce(hints[key], value, sub)
    try:
        obj = cls(**kwargs)
        if hasattr(obj, "validate"):
            obj.validate()
    except (ValueError, TypeError) as exc:
        raise CalibError(f"{where or cls.__name__}: {exc}") from None
    return obj


def _coerce(tp: Any, value: Any, where: str) -> Any:
    """Check ``value`` against type hint ``tp`` and convert TOML types to field types."""
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        return _coerce_union(typing.get_args(tp), value, where)
    if origin is typing.Literal:
        return _coerce_literal(typing.get_args(tp), value, where)
    if dataclasses.is_dataclass(tp):
        return dataclass_from_mapping(tp, value, where)
    if origin in (tuple, list) or tp in (tuple, list):
        return _coerce_sequence(origin, typing.get_args(tp), value, where)
    if origin in (dict, Mapping) or tp is dict:
        if not isinstance(value, Mapping):
            raise CalibError(f"{where}: expected a table, got {value!r}")
        return dict(value)
    return _coerce_scalar(tp, value, where)


def _coerce_union(args: tuple[Any, ...], value: Any, where: str) -> Any:
    """``value`` as the first member type of a union (``args``) that accepts it; None
    when the union is optional and ``value`` is None. The first member's message when
    none accepts it."""
    if value is None and type(None) in args:
        return None
    errors = []
    for a in args:
        if a is type(None):
            continue
        try:
            return _coerce(a, value, where)
        except CalibError as exc:
            errors.append(str(exc))
    raise CalibError(errors[0] if errors else f"{where}: bad value {value!r}")


def _coerce_literal(args: tuple[Any, ...], value: Any, where: str) -> Any:
    """``value`` when it is one of the ``Literal`` values ``args``; else a message with
    the closest one."""
    if value not in args:
        close = difflib.get_close_matches(str(value), [str(a) for a in args], n=1)
        hint = f"; did you mean '{close[0]}'?" if close else ""
        raise CalibError(f"{where}: '{value}' is not one of {', '.join(map(str, args))}{hint}")
    return value


def _coerce_sequence(origin: Any, args: tuple[Any, ...], value: Any, where: str) -> tuple:
    """A TOML array as a tuple: items coerced for ``tuple[X, ...]`` and fixed-length
    ``tuple[X, Y]`` (length checked), as given for a bare ``tuple``/``list``."""
    if not isinstance(value, (list, tuple)):
        raise CalibError(f"{where}: expected a list, got {value!r}")
    if origin is tuple and len(args) == 2 and args[1] is Ellipsis:
        return tuple(_coerce(args[0], v, f"{where}[{i}]") for i, v in enumerate(value))
    if origin is tuple and args:
        if len(args) != len(value):
            raise CalibError(f"{where}: expected {len(args)} values, got {len(value)}")
        return tuple(
            _coerce(a, v, f"{where}[{i}]") for i, (a, v) in enumerate(zip(args, value, strict=True))
        )
    return tuple(value)


def _coerce_scalar(tp: Any, value: Any, where: str) -> Any:
    """``value`` checked against ``float`` (ints converted), ``int``, ``bool`` or ``str``
    (bools are not numbers); any other hint passes ``value`` through."""
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise CalibError(f"{where}: expected a number, got {value!r}")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise CalibError(f"{where}: expected an integer, got {value!r}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise CalibError(f"{where}: expected true or false, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise CalibError(f"{where}: expected a string, got {value!r}")
        return value
    return value


def dataclass_to_dict(obj: Any) -> Any:
    """Plain-Python (JSON/TOML-safe) view of a config dataclass, for provenance."""
    if dataclasses.is_dataclass(obj):
        return {f.name: dataclass_to_dict(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, (list, tuple)):
        return [dataclass_to_dict(v) for v in obj]
    if isinstance(obj, Mapping):
        return {str(k): dataclass_to_dict(v) for k, v in obj.items()}
    return obj


def load_config(path: str | Path | None = None):
    """Load the pipeline TOML (or defaults when ``path`` is None) as PipelineConfig."""
    if path is None:
        return PipelineConfig()
    return dataclass_from_mapping(PipelineConfig, load_toml(path), where=str(path))


def to_toml(obj: Any) -> str:
    """TOML text of a config dataclass tree (tables for nested dataclasses/dicts).

    Round-trips through :func:`dataclass_from_mapping` for the types config uses
    (str, bool, int, float, tuples/lists of those, nested tables). ``None`` values are
    omitted (TOML has no null), so they fall back to the field default on reload.
    """
    lines: list[str] = []
    _toml_table(dataclass_to_dict(obj), [], lines)
    return "\n".join(lines).strip() + "\n"


def _toml_table(table: Mapping[str, Any], path: list[str], lines: list[str]) -> None:
    scalars = {k: v for k, v in table.items() if not isinstance(v, Mapping) and v is not None}
    tables = {k: v for k, v in table.items() if isinstance(v, Mapping)}
    if path and (scalars or not tables):
        lines.append(f"\n[{'.'.join(_toml_key(p) for p in path)}]")
    for k, v in scalars.items():
        lines.append(f"{_toml_key(k)} = {_toml_value(v)}")
    for k, v in tables.items():
        _toml_table(v, [*path, k], lines)


def _toml_key(key: str) -> str:
    return key if key.replace("_", "").replace("-", "").isalnum() else json.dumps(key)


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        if v != v or v in (float("inf"), float("-inf")):
            return {True: "nan"}.get(v != v, "inf" if v > 0 else "-inf")
        return repr(v)
    if isinstance(v, int):
        return str(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")
