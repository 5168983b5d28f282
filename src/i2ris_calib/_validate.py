"""Argument checks at the entry of the public API: one-line :class:`CalibError` messages.

Every public function (``i2ris_calib.__all__``, docs/api.md) checks its arguments here
before any work, so a notebook user who passes the wrong thing (a factory instead of
a model, a column vector, arrays of different lengths, NaN in an input, a DataFrame
or a string where a config belongs) is told what was wrong and how to fix it, e.g.::

    fit: model is the factory i2ris_egpi_model, not a model; call it: i2ris_egpi_model()
    make_dataset: enc has shape (500, 1); give a 1-D array (use .ravel())

Messages start with the function's name and name the argument. The checks cost
O(n) once per call; nothing here runs inside a fit's iterations. This module imports
only :mod:`i2ris_calib.errors` and :mod:`i2ris_calib.model` (numpy only),
so every module can use it.
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import inspect
import math
import numbers
import os
import types
import typing
from collections.abc import Callable, Iterable, Mapping

import numpy as np

from i2ris_calib.errors import CalibError
from i2ris_calib.model import Signals

__all__ = [
    "as_1d_bool",
    "as_1d_float",
    "as_real",
    "check_callable",
    "check_choice",
    "check_choices",
    "check_config_fields",
    "check_instance",
    "check_model",
    "check_path",
    "check_signals",
    "check_str",
    "describe",
    "same_length",
    "validated_config",
]


# --------------------------------------------------------------------------- describing


def _short(x: object, limit: int = 40) -> str:
    text = repr(x)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def describe(x: object) -> str:
    """What ``x`` is, in a few words: ``"None"``, ``"the str 'abc'"``, ``"a pandas
    DataFrame (500 rows x 3 columns)"``, ``"the function f"``, ``"the class C"``, ...
    """
    if x is None:
        return "None"
    if isinstance(x, str):
        return f"the str {_short(x)}"
    if isinstance(x, type):
        return f"the class {x.__name__}"
    if isinstance(x, functools.partial):
        return f"a partial of {getattr(x.func, '__name__', 'a function')}"
    if isinstance(x, (types.FunctionType, types.BuiltinFunctionType, types.MethodType)):
        return f"the function {x.__name__}"
    mod = type(x).__module__.split(".")[0]
    name = type(x).__name__
    if mod == "pandas" and name == "DataFrame":
        r, c = x.shape
        return f"a pandas DataFrame ({r} rows x {c} columns)"
    if mod == "pandas" and name == "Series":
        return f"a pandas Series ({len(x)} rows)"
    if isinstance(x, (list, tuple)):
        kinds = sorted({type(e).__name__ for e in x})
        inner = f" of {'/'.join(kinds)}" if kinds and len(kinds) <= 2 else ""
        return f"a {name} of {len(x)} item{'s' if len(x) != 1 else ''}{inner}"
    article = "an" if name[:1].lower() in "aeiou" else "a"
    if isinstance(x, (bool, numbers.Number, np.generic)):
        return f"{article} {name} ({_short(x)})"
    if isinstance(x, np.ndarray):
        return f"an array of shape {x.shape}"
    return f"{article} {name}"


def _is_dataframe(x: object) -> bool:
    return type(x).__name__ == "DataFrame" and type(x).__module__.startswith("pandas")


# --------------------------------------------------------------------------- arrays


def _count(n: int, what: str) -> str:
    return f"{n} {what}{'' if n == 1 else 's'}"


def as_1d_float(
    func: str,
    name: str,
    x: object,
    *,
    nan_ok: bool = False,
    finite: bool = True,
    size: int | None = None,
    min_size: int = 0,
    hint: str = "an input must be finite everywhere",
) -> np.ndarray:
    """``x`` as a float array of shape (n,), or CalibError naming ``func`` and ``name``.

    Refused: None, a str, a mapping, a DataFrame of several columns, non-numeric
    values, a scalar, an array of more than one dimension (a column (n, 1) included:
    the message says ``.ravel()``), fewer than ``min_size`` (or not exactly ``size``)
    values, and with ``finite`` NaN (unless ``nan_ok``) and +-inf values (``hint`` says
    why they are not allowed). A pandas Series or a list is fine.
    """
    if x is None:
        raise CalibError(f"{func}: {name} is None; give an array of shape (n,)")
    if isinstance(x, (str, bytes)):
        raise CalibError(f"{func}: {name} is {describe(x)}; give an array of numbers")
    if isinstance(x, Mapping) or (dataclasses.is_dataclass(x) and not isinstance(x, type)):
        raise CalibError(f"{func}: {name} is {describe(x)}; give an array of numbers")
    if _is_dataframe(x) and x.shape[1] != 1:
        raise CalibError(
            f"{func}: {name} is {describe(x)}; give one column, e.g. df['{_first_col(x)}']"
        )
    try:
        raw = np.asarray(x)
        if raw.dtype.kind == "c":
            raise TypeError("complex numbers")
        if raw.dtype.kind in "mM":
            raise TypeError(f"{raw.dtype} values; give seconds as numbers")
        arr = np.asarray(raw, dtype=float)
    except (TypeError, ValueError) as exc:
        why = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise CalibError(
            f"{func}: {name} is not numeric ({why}); give an array of numbers"
        ) from None
    if arr.ndim == 0:
        raise CalibError(f"{func}: {name} is {describe(x)}; give an array of shape (n,)")
    if arr.ndim > 1:
        column = arr.ndim == 2 and 1 in arr.shape
        how = "use .ravel()" if column else "one value per sample"
        raise CalibError(f"{func}: {name} has shape {arr.shape}; give a 1-D array ({how})")
    if size is not None and arr.size != size:
        raise CalibError(f"{func}: {name} has {_count(arr.size, 'value')}; give {size}")
    if arr.size < min_size:
        raise CalibError(
            f"{func}: {name} has {_count(arr.size, 'sample')}; give at least {min_size}"
        )
    if finite:
        _check_finite(func, name, arr, nan_ok, hint)
    return arr


def _first_col(df) -> str:
    return str(df.columns[0]) if len(df.columns) else "column"


def _check_finite(func: str, name: str, arr: np.ndarray, nan_ok: bool, hint: str) -> None:
    if np.isfinite(arr).all():  # the common case: one pass
        return
    nan = np.isnan(arr)
    inf = np.isinf(arr)
    if nan_ok:
        if inf.any():
            k = int(np.flatnonzero(inf)[0])
            raise CalibError(
                f"{func}: {name} has {_count(int(inf.sum()), 'infinite value')} "
                f"(first at index {k}); {hint}"
            )
        return
    bad = nan | inf
    k = int(np.flatnonzero(bad)[0])
    parts = []
    if nan.any():
        parts.append(f"{int(nan.sum())} NaN")
    if inf.any():
        parts.append(f"{int(inf.sum())} infinite")
    what = " and ".join(parts) + (" value" if int(bad.sum()) == 1 else " values")
    raise CalibError(f"{func}: {name} has {what} (first at index {k}); {hint}")


def as_1d_bool(func: str, name: str, x: object, n: int | None = None) -> np.ndarray:
    """``x`` as a boolean mask of shape (n,): bool values, or numbers that are all 0/1.

    An index array (``[3, 4, 5]``) is refused rather than read as a mask.
    """
    arr = as_1d_float(func, name, x, finite=False) if np.asarray(x).dtype != bool else None
    if arr is not None:
        if not np.isin(arr, (0.0, 1.0)).all():
            raise CalibError(
                f"{func}: {name} is not a boolean mask (values other than 0/1: an index "
                "array?); give a bool array of shape (n,), e.g. np.isin(np.arange(n), idx)"
            )
        out = arr.astype(bool)
    else:
        out = np.asarray(x)
        if out.ndim != 1:
            column = out.ndim == 2 and 1 in out.shape
            how = "use .ravel()" if column else "one value per sample"
            raise CalibError(f"{func}: {name} has shape {out.shape}; give a 1-D array ({how})")
    if n is not None and out.size != n:
        raise CalibError(
            f"{func}: {name} has {_count(out.size, 'sample')} but the data {n}; give one "
            "flag per sample"
        )
    return out


def same_length(func: str, **arrays: np.ndarray | None) -> int:
    """The common length of the given 1-D arrays (None skipped), or CalibError naming
    the first that differs from the first one given."""
    named = [(k, a) for k, a in arrays.items() if a is not None]
    if not named:
        return 0
    ref_name, ref = named[0]
    for k, a in named[1:]:
        if a.size != ref.size:
            raise CalibError(
                f"{func}: {k} has {_count(a.size, 'sample')} but {ref_name} {ref.size}; "
                "give arrays of the same length"
            )
    return int(ref.size)


def check_signals(func: str, name: str, signals: object):
    """``signals`` (a :class:`~i2ris_calib.model.Signals` or an input array)
    checked: a 1-D finite input ``v``, finite ``t_s`` / ``v_other`` of its length when
    given, ``theta_other_deg`` of its length (NaN allowed: an angle). Returns
    ``signals`` itself when it is a Signals, else the input as a float array."""
    if not isinstance(signals, Signals):
        return as_1d_float(func, name, signals)
    v = as_1d_float(func, f"{name}.v", signals.v)
    fields = {}
    for field, nan_ok in (("t_s", False), ("v_other", False), ("theta_other_deg", True)):
        x = getattr(signals, field, None)
        if x is not None:
            fields[f"{name}.{field}"] = as_1d_float(
                func, f"{name}.{field}", x, nan_ok=nan_ok,
                hint="angles may be NaN (unmeasured), never infinite" if nan_ok else
                "an input must be finite everywhere",
            )  # fmt: skip
    same_length(func, **{f"{name}.v": v}, **fields)
    return signals


# --------------------------------------------------------------------------- scalars


def as_real(
    func: str,
    name: str,
    x: object,
    *,
    integer: bool = False,
    none_ok: bool = False,
    finite: bool = True,
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
    hi_open: bool = False,
):
    """``x`` as a float (an int with ``integer``) in ``[lo, hi]`` (``(lo`` / ``hi)``
    with ``lo_open`` / ``hi_open``), or None when ``none_ok``; CalibError otherwise.
    A bool, a str, an array or NaN is refused; an integer setting refuses 3.0."""
    if x is None:
        if none_ok:
            return None
        raise CalibError(f"{func}: {name} is None; give a number")
    kind = "an integer" if integer else "a number"
    if isinstance(x, (bool, np.bool_)) or not isinstance(x, numbers.Real):
        if isinstance(x, np.ndarray) and x.ndim == 0 and x.dtype.kind in "iuf":
            x = x.item()
        else:
            raise CalibError(f"{func}: {name} is {describe(x)}; give {kind}")
    if integer and not isinstance(x, numbers.Integral):
        raise CalibError(f"{func}: {name} = {x!r} is not an integer; give {kind}, e.g. {int(x)}")
    val = int(x) if integer else float(x)
    if math.isnan(val) or (finite and math.isinf(val)):
        raise CalibError(f"{func}: {name} is {val}; give a finite number")
    below = lo is not None and (val <= lo if lo_open else val < lo)
    above = hi is not None and (val >= hi if hi_open else val > hi)
    if below or above:
        need = []
        if lo is not None:
            need.append(f"{'>' if lo_open else '>='} {lo:g}")
        if hi is not None:
            need.append(f"{'<' if hi_open else '<='} {hi:g}")
        raise CalibError(
            f"{func}: {name} = {val:g} is out of range; give {kind} {' and '.join(need)}"
        )
    return val


def check_str(func: str, name: str, x: object, example: str = "") -> str:
    """``x`` if it is a str, else CalibError."""
    if not isinstance(x, str):
        eg = f", e.g. {example!r}" if example else ""
        raise CalibError(f"{func}: {name} is {describe(x)}; give a str{eg}")
    return x


def check_choice(func: str, name: str, x: object, choices: Iterable[str]) -> str:
    """``x`` if it is one of ``choices``, else CalibError with the closest one."""
    choices = tuple(choices)
    if not isinstance(x, str) or x not in choices:
        shown = _short(x) if isinstance(x, str) else describe(x)
        close = difflib.get_close_matches(x, choices, n=1) if isinstance(x, str) else []
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise CalibError(
            f"{func}: {name} {shown} is not one of {', '.join(map(repr, choices))}{hint}"
        )
    return x


def check_choices(
    func: str, name: str, x: object, choices: Iterable[str], example: str = ""
) -> tuple[str, ...]:
    """``x`` (a tuple or list of str) as a tuple, each one of ``choices``. A bare str is
    refused (it would be read letter by letter)."""
    choices = tuple(choices)
    eg = example or f"({choices[0]!r},)"
    if isinstance(x, str) or not isinstance(x, (tuple, list)):
        raise CalibError(f"{func}: {name} is {describe(x)}; give a tuple, e.g. {eg}")
    for i, item in enumerate(x):
        check_choice(func, f"{name}[{i}]", item, choices)
    return tuple(x)


def check_callable(func: str, name: str, x: object) -> None:
    """None or a callable (a progress callback), else CalibError."""
    if x is not None and not callable(x):
        raise CalibError(f"{func}: {name} is {describe(x)}; give a function or None")


def check_path(func: str, name: str, x: object, what: str, other: str = "") -> None:
    """``x`` is a str or path-like (not a DataFrame, list, ...); ``what`` is the file
    expected, ``other`` a hint for an in-memory object."""
    if isinstance(x, (str, os.PathLike)):
        if isinstance(x, str) and not x.strip():
            raise CalibError(f"{func}: {name} is an empty str; give the path of {what}")
        return
    tail = f" ({other})" if other and x is not None else ""
    raise CalibError(f"{func}: {name} is {describe(x)}; give the path of {what}{tail}")


# --------------------------------------------------------------------------- objects


def _required_params(f: Callable) -> list[str]:
    try:
        sig = inspect.signature(f)
    except (TypeError, ValueError):
        return []
    return [
        p.name
        for p in sig.parameters.values()
        if p.default is p.empty and p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)
    ]


def _call_hint(f: Callable) -> str:
    name = getattr(f, "__name__", "it")
    return f"{name}({', '.join(_required_params(f))})"


def check_instance(
    func: str,
    name: str,
    x: object,
    cls: type,
    *,
    none_ok: bool = False,
    hint: str = "",
):
    """``x`` if it is a ``cls`` (or None with ``none_ok``), else CalibError saying what
    it is: None, the class itself not called (``FitConfig`` for ``FitConfig()``), a
    function not called, a str, a DataFrame, ... ``hint`` is appended to the message."""
    if isinstance(x, cls) or (x is None and none_ok):
        return x
    want = cls.__name__
    tail = f" ({hint})" if hint else ""
    if isinstance(x, type) and issubclass(x, cls):
        raise CalibError(
            f"{func}: {name} is the class {x.__name__}, not a {want}; call it: {x.__name__}()"
        )
    if isinstance(x, (types.FunctionType, functools.partial)):
        raise CalibError(
            f"{func}: {name} is {describe(x)}, not a {want}; call it: {_call_hint(x)}{tail}"
        )
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        for f in dataclasses.fields(x):
            if isinstance(getattr(x, f.name, None), cls):
                raise CalibError(
                    f"{func}: {name} is {describe(x)}; give its {want} section: {name}.{f.name}"
                )
    raise CalibError(f"{func}: {name} is {describe(x)}; give a {want}{tail}")


_MODEL_ATTRS = ("parameters", "evaluate", "with_values")


def _is_model(x: object) -> bool:
    return not isinstance(x, type) and all(hasattr(x, a) for a in _MODEL_ATTRS)


def check_model(func: str, name: str, x: object, usage: str = "") -> None:
    """``x`` is a model (``parameters``, ``evaluate``, ``with_values``: a GPI/EGPI model
    or one extended by effects), else CalibError. A factory not called, a model class,
    a fit result, a diagnosis, a kind's name and a dataset in the model's place (the
    arguments swapped: ``usage`` shows the order) each get their own fix."""
    if _is_model(x):
        return
    if x is None:
        raise CalibError(f"{func}: {name} is None; give a model, e.g. i2ris_egpi_model()")
    head = f"{func}: {name} is {describe(x)}"
    if isinstance(x, (types.FunctionType, functools.partial)):
        fname = getattr(x, "__name__", getattr(getattr(x, "func", None), "__name__", ""))
        what = "the factory" if fname.endswith("_model") or fname == "model_for_kind" else None
        if what:
            raise CalibError(
                f"{func}: {name} is the factory {fname}, not a model; call it: {_call_hint(x)}"
            )
        raise CalibError(f"{head}, not a model; give a model, e.g. i2ris_egpi_model()")
    if isinstance(x, type):
        raise CalibError(
            f"{head}, not a model; build one with its factory, e.g. i2ris_egpi_model()"
        )
    if _is_model(getattr(x, "final_model", None)):
        raise CalibError(f"{head}, not a model; give its model: {name}.final_model")
    if _is_model(getattr(x, "model", None)):
        raise CalibError(f"{head}, not a model; give its fitted model: {name}.model")
    if isinstance(x, str):
        raise CalibError(
            f"{head}, not a model; build one: model_for_kind({x!r}) (kinds: gpi, egpi, egpi_c)"
        )
    if type(x).__name__ == "Dataset" and usage:
        raise CalibError(f"{head}, not a model; the arguments are swapped? the order is {usage}")
    raise CalibError(f"{head}, not a model; give a model, e.g. i2ris_egpi_model()")


# --------------------------------------------------------------------------- configs


@functools.cache
def _hints(cls: type) -> dict[str, object]:
    return typing.get_type_hints(cls)


def _type_error(value: object, tp: object) -> str | None:
    """Why ``value`` does not fit type hint ``tp`` (None when it fits or the hint is
    not one checked: str, bool, int, float, tuple, dict, Literal, unions, dataclasses)."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        return _union_error(value, args)
    if origin is typing.Literal:
        ok = value in args
        return None if ok else f"is {_short(value)}, not one of {', '.join(map(repr, args))}"
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        return _dataclass_error(value, tp)
    if tp in _SCALAR_CHECKS:
        return _SCALAR_CHECKS[tp](value)
    if origin is tuple or tp is tuple:
        return _tuple_error(value, args)
    if origin in (dict, Mapping) or tp is dict:
        return None if isinstance(value, Mapping) else f"is {describe(value)}; give a dict"
    return None


def _union_error(value: object, args: tuple) -> str | None:
    """:func:`_type_error` of a union: None when any member fits, else the first's reason."""
    if value is None and type(None) in args:
        return None
    errors = [_type_error(value, a) for a in args if a is not type(None)]
    return None if any(e is None for e in errors) else errors[0]


def _dataclass_error(value: object, tp: type) -> str | None:
    """:func:`_type_error` of a dataclass hint (the class itself given is named)."""
    if isinstance(value, tp):
        return None
    if value is tp:
        return f"is the class {tp.__name__}, not a {tp.__name__}; call it: {tp.__name__}()"
    return f"is {describe(value)}; give a {tp.__name__}"


def _is_bool(value: object) -> bool:
    return isinstance(value, (bool, np.bool_))


def _bool_error(value: object) -> str | None:
    return None if _is_bool(value) else f"is {describe(value)}; give True or False"


def _int_error(value: object) -> str | None:
    if isinstance(value, numbers.Integral) and not _is_bool(value):
        return None
    return f"is {describe(value)}; give an integer"


def _float_error(value: object) -> str | None:
    if isinstance(value, numbers.Real) and not _is_bool(value):
        return None if not math.isnan(float(value)) else "is NaN; give a number"
    return f"is {describe(value)}; give a number"


def _str_error(value: object) -> str | None:
    return None if isinstance(value, str) else f"is {describe(value)}; give a str"


#: scalar type hint -> its check (a reason, or None when the value fits)
_SCALAR_CHECKS = {bool: _bool_error, int: _int_error, float: _float_error, str: _str_error}


def _tuple_error(value: object, args: tuple) -> str | None:
    """:func:`_type_error` of a tuple hint: ``tuple[X, ...]``, ``tuple[X, Y]`` or bare
    ``tuple``; the first wrong member named by its index."""
    if isinstance(value, str) or not isinstance(value, (tuple, list)):
        eg = ", e.g. ('lam',)" if args[:1] == (str,) else ""
        return f"is {describe(value)}; give a tuple{eg}"
    if len(args) == 2 and args[1] is Ellipsis:
        inner = [args[0]] * len(value)
    elif args:
        if len(args) != len(value):
            return f"has {_count(len(value), 'value')}; give {len(args)}"
        inner = list(args)
    else:
        return None
    for i, (v, a) in enumerate(zip(value, inner, strict=True)):
        err = _type_error(v, a)
        if err:
            return f"[{i}] {err}"
    return None


def check_config_fields(obj: object) -> None:
    """CalibError when a field of the config dataclass ``obj`` has the wrong type:
    ``FitConfig(n_starts="3")``, ``PipelineConfig(fit=FitConfig)``, ``fixed_egpi="lam"``."""
    cls = type(obj)
    hints = _hints(cls)
    for f in dataclasses.fields(obj):
        err = _type_error(getattr(obj, f.name), hints.get(f.name))
        if err:
            sep = "" if err.startswith("[") else " "
            raise CalibError(f"{cls.__name__}: {f.name}{sep}{err}")


def validated_config(obj: object) -> None:
    """A config dataclass's ``__post_init__``: field types (:func:`check_config_fields`),
    then its own ``validate()`` whose ValueError / TypeError becomes a CalibError with
    the same message."""
    check_config_fields(obj)
    validate = getattr(obj, "validate", None)
    if validate is None:
        return
    try:
        validate()
    except CalibError:
        raise
    except (ValueError, TypeError) as exc:
        raise CalibError(str(exc)) from None
