"""A fit as data beyond its fields: the parameter table and the saved-fit file.

* :class:`ParamTable` (``FitResult.parameters``): a frozen mapping name ->
  :class:`FittedParameter` (value, standard error, start, bounds, fixed, unit,
  meaning, why a standard error is missing), with the :class:`Correlations` of the
  parameters the covariance covers and a DataFrame view (``to_frame()``), as lmfit's
  ``Parameters``.
* :func:`fit_record` / :func:`fit_fields` (``FitResult.save`` / ``FitResult.load``): a
  fit as strict JSON (format :data:`SCHEMA`, ``i2ris-calib.fit-result/1``; files of
  the older id ``i2ris-calib.fit/1`` still load): the model's kind, settings and
  every parameter's declaration and value, the standard errors, covariance, residuals,
  metrics and messages. Loading rebuilds the same model, so ``predict`` gives the
  saved fit's output to the last bit.

The model is written by the model codec (:mod:`i2ris_calib.hysteresis.codec`: the
registry kinds, the general EGPI and models extended by any catalogue effect). How a
fit is shown (the text report, the notebook display, the figure) is
:mod:`i2ris_calib.fitting.present`.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

import i2ris_calib._display as _display
from i2ris_calib import __version__
from i2ris_calib._atomic import write_text
from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.metrics import Metrics
from i2ris_calib.hysteresis.codec import decode_model, encode_model

#: The format of a saved fit (``FitResult.save``); not the ``fit`` command's fit.json.
SCHEMA = "i2ris-calib.fit-result/1"
#: The formats :func:`fit_fields` reads: files saved before the two formats had their
#: own ids carry the fit.json's (they hold a ``model``, fit.json a ``datasets`` list).
SCHEMAS_READ = (SCHEMA, "i2ris-calib.fit/1")


# ----------------------------------------------------------------------- the table


@dataclass(frozen=True)
class FittedParameter:
    """One parameter of a fit.

    Attributes
    ----------
    name : str
    value : float
        Fitted value (the held value of a fixed parameter).
    stderr : float
        Standard error (0 for a fixed parameter; NaN: see ``stderr_reason``).
    start : float
        Value of the first start vector of the fit (the model's own value unless the
        caller gave starts); NaN when not recorded (a result from an older file).
    lower, upper : float
        Declared bounds.
    fixed : bool
        Held at ``value`` during the fit.
    unit, meaning : str
        From the model's declaration.
    stderr_reason : str
        Why ``stderr`` is NaN ("" when it is not).
    """

    name: str
    value: float
    stderr: float
    start: float
    lower: float
    upper: float
    fixed: bool
    unit: str = ""
    meaning: str = ""
    stderr_reason: str = ""

    def __repr__(self) -> str:
        se = "(fixed)" if self.fixed else f"+/- {_display.num(self.stderr, 3)}"
        unit = f" {self.unit}" if self.unit and self.unit != "1" else ""
        return f"<FittedParameter {self.name} = {self.value:.6g} {se}{unit}>"


class Correlations:
    """Correlation matrix of the fitted parameters the covariance covers (free, with a
    finite positive variance): symmetric, unit diagonal, labelled by ``names``.

    ``corr["a1", "a2"]`` is one coefficient; ``to_frame()`` the labelled DataFrame;
    ``pairs(min_abs)`` the off-diagonal ones, largest first.
    """

    __slots__ = ("names", "matrix")

    def __init__(self, names: Sequence[str], matrix: np.ndarray):
        m = np.array(matrix, dtype=float)
        m.flags.writeable = False
        object.__setattr__(self, "names", tuple(names))
        object.__setattr__(self, "matrix", m)

    def __setattr__(self, name, value):
        raise AttributeError("Correlations is immutable")

    def __getitem__(self, key: tuple[str, str]) -> float:
        a, b = key
        try:
            return float(self.matrix[self.names.index(a), self.names.index(b)])
        except ValueError:
            raise KeyError(
                f"{key!r}: correlations cover {', '.join(self.names) or 'no parameter'}"
            ) from None

    def __len__(self) -> int:
        return len(self.names)

    def pairs(self, min_abs: float = 0.0) -> list[tuple[tuple[str, str], float]]:
        """``((a, b), C)`` of every pair with ``|C| >= min_abs``, largest ``|C|`` first."""
        out = [
            ((a, b), float(self.matrix[i, j]))
            for i, a in enumerate(self.names)
            for j, b in enumerate(self.names)
            if j > i and abs(self.matrix[i, j]) >= min_abs
        ]
        return sorted(out, key=lambda kc: -abs(kc[1]))

    def to_frame(self):
        """The matrix as a pandas DataFrame indexed and labelled by parameter name."""
        import pandas as pd

        return pd.DataFrame(np.array(self.matrix), index=list(self.names), columns=list(self.names))

    def __repr__(self) -> str:
        top = self.pairs()[:3]
        text = ", ".join(f"C({a}, {b}) = {c:+.3f}" for (a, b), c in top)
        return _display.clip(
            f"<Correlations of {len(self.names)} parameters"
            + (f"; largest {text}" if text else "")
            + ">"
        )

    def _repr_html_(self) -> str:
        rows = [
            (a, *(float(x) for x in row)) for a, row in zip(self.names, self.matrix, strict=True)
        ]
        return _display.table(("", *self.names), rows, "<b>Correlations</b>")


class ParamTable(Mapping):
    """The parameters of a fit: a frozen mapping name -> :class:`FittedParameter`, in
    model order.

    ``table["a1"].stderr``, ``table.value_dict()`` (the same as ``FitResult.params``),
    ``table.stderr_dict()`` (``FitResult.stderr``), ``table.correlations``,
    ``table.covariance`` (every parameter, model order), ``table.to_frame()``.
    """

    __slots__ = ("_params", "_index", "_cov", "model_name")

    def __init__(self, params: Sequence[FittedParameter], covariance: np.ndarray, model_name=""):
        cov = np.array(covariance, dtype=float)
        cov.flags.writeable = False
        object.__setattr__(self, "_params", tuple(params))
        object.__setattr__(self, "_index", {p.name: i for i, p in enumerate(self._params)})
        object.__setattr__(self, "_cov", cov)
        object.__setattr__(self, "model_name", str(model_name))

    def __setattr__(self, name, value):
        raise AttributeError("ParamTable is immutable; fit again or use model.with_values")

    def __getitem__(self, name: str) -> FittedParameter:
        try:
            return self._params[self._index[name]]
        except KeyError:
            import difflib

            close = difflib.get_close_matches(str(name), list(self._index), n=1)
            hint = f"did you mean '{close[0]}'?" if close else f"valid: {', '.join(self._index)}"
            raise KeyError(f"no parameter {name!r} ({hint})") from None

    def __iter__(self) -> Iterator[str]:
        return iter(self._index)

    def __len__(self) -> int:
        return len(self._params)

    @property
    def free(self) -> tuple[str, ...]:
        """Names of the fitted (not fixed) parameters."""
        return tuple(p.name for p in self._params if not p.fixed)

    @property
    def covariance(self) -> np.ndarray:
        """Covariance of every parameter in model order, shape (p, p) (read-only; zero
        rows and columns for fixed and profiled ones)."""
        return self._cov

    def value_dict(self) -> dict[str, float]:
        """``{name: value}``."""
        return {p.name: p.value for p in self._params}

    def stderr_dict(self) -> dict[str, float]:
        """``{name: stderr}``."""
        return {p.name: p.stderr for p in self._params}

    @property
    def correlations(self) -> Correlations:
        """:class:`Correlations` of the free parameters with a finite positive variance."""
        d = np.diag(self._cov) if self._cov.shape == (len(self), len(self)) else np.zeros(len(self))
        idx = [
            i
            for i, p in enumerate(self._params)
            if not p.fixed and math.isfinite(p.stderr) and p.stderr > 0 and d[i] > 0
        ]
        sd = np.sqrt(d[idx])
        c = self._cov[np.ix_(idx, idx)] / np.outer(sd, sd)
        c = 0.5 * (c + c.T)
        np.fill_diagonal(c, 1.0)
        return Correlations([self._params[i].name for i in idx], c)

    def to_frame(self):
        """The table as a pandas DataFrame indexed by name (columns ``value``,
        ``stderr``, ``start``, ``lower``, ``upper``, ``fixed``, ``unit``, ``meaning``,
        ``stderr_reason``)."""
        import pandas as pd

        cols = ("value", "stderr", "start", "lower", "upper", "fixed", "unit", "meaning",
                "stderr_reason")  # fmt: skip
        frame = pd.DataFrame(
            [[getattr(p, c) for c in cols] for p in self._params],
            index=[p.name for p in self._params],
            columns=list(cols),
        )
        frame.index.name = "name"
        return frame

    def __repr__(self) -> str:
        head = f"<ParamTable {self.model_name}: {len(self)} parameters, {len(self.free)} free: "
        return _display.name_values(((p.name, p.value) for p in self._params), head)

    def _repr_html_(self) -> str:
        def se(p):
            if p.fixed:
                return "fixed"
            return _display.num(p.stderr, 3) if math.isfinite(p.stderr) else "nan"

        rows = [
            (p.name, p.value, se(p), p.start, p.lower, p.upper, p.unit, p.meaning)
            for p in self._params
        ]
        header = ("name", "value", "stderr", "start", "lower", "upper", "unit", "meaning")
        return _display.table(header, rows, f"<b>Parameters</b> {_display.esc(self.model_name)}")


def param_table(res) -> ParamTable:
    """The :class:`ParamTable` of a FitResult ``res`` (its ``params``, ``stderr``,
    ``start``, ``stderr_reasons`` and covariance with the model's declarations)."""
    start = getattr(res, "start", {}) or {}
    rows = [
        FittedParameter(
            name=p.name,
            value=float(res.params.get(p.name, p.value)),
            stderr=float(res.stderr.get(p.name, float("nan"))),
            start=float(start.get(p.name, float("nan"))),
            lower=float(p.lower),
            upper=float(p.upper),
            fixed=p.name not in res.free,
            unit=p.unit,
            meaning=p.doc,
            stderr_reason=res.stderr_reasons.get(p.name, ""),
        )
        for p in res.model.parameters
    ]
    return ParamTable(rows, res.covariance, res.model.name)


# ---------------------------------------------------------------------- the file


def _jsonable(x: Any) -> Any:
    """Strict JSON: NaN -> null, +-inf -> "inf"/"-inf", arrays -> lists."""
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None if math.isnan(x) else ("inf" if x > 0 else "-inf")
    return x


def _number(x: Any) -> float:
    """Inverse of :func:`_jsonable` for one number."""
    if x is None:
        return float("nan")
    return float(x)


def _array(x: Any) -> np.ndarray:
    if x is None:
        return np.zeros(0)
    return np.array(
        [[_number(v) for v in row] for row in x] if x and isinstance(x[0], list) else
        [_number(v) for v in x], dtype=float,
    )  # fmt: skip


def fit_record(res) -> dict:
    """The JSON-ready record of a FitResult (format :data:`SCHEMA`)."""
    return _jsonable(
        {
            "schema": SCHEMA,
            "written_by": f"i2ris-calib {__version__}",
            "model": encode_model(res.model),
            "params": dict(res.params),
            "stderr": dict(res.stderr),
            "start": dict(getattr(res, "start", {}) or {}),
            "stderr_reasons": dict(res.stderr_reasons),
            "free": list(res.free),
            "covariance": np.asarray(res.covariance, dtype=float),
            "residuals": np.asarray(res.residuals, dtype=float),
            "metrics": res.metrics.as_dict(),
            "holdout_metrics": res.holdout_metrics.as_dict(),
            "aic": res.aic,
            "bic": res.bic,
            "converged": bool(res.converged),
            "message": res.message,
            "nfev": int(res.nfev),
            "n_samples": int(res.n_samples),
            "starts_tried": int(res.starts_tried),
            "outside_bounds": list(res.extra.get("outside_bounds", [])),
            "notes": [
                {"code": n.code, "text": n.text, "params": list(n.params)} for n in res.notes
            ],
            "initial_state": None if res.initial_state is None else res.initial_state.as_dict(),
            "certificate": None if res.certificate is None else res.certificate.as_dict(),
        }
    )


def fit_fields(obj: Mapping, where: str = "fit file") -> dict:
    """The FitResult fields of a record :func:`fit_record` wrote (``notes`` as dicts,
    ``initial_state`` a dict or None: the caller builds them); CalibError naming
    ``where`` for a record of another format or a missing key."""
    if not isinstance(obj, Mapping) or obj.get("schema") not in SCHEMAS_READ:
        got = obj.get("schema") if isinstance(obj, Mapping) else type(obj).__name__
        raise CalibError(f"{where}: schema is {got!r}, expected '{SCHEMA}' (FitResult.save)")
    if "datasets" in obj and "model" not in obj:
        raise CalibError(
            f"{where}: this is the fit.json the 'fit' command writes (every dataset and model "
            "of a recording), not a file FitResult.save wrote; read it with "
            "i2ris_calib.io.fit.read_fit_json(path) (a checked dict; docs/fit.md), or "
            "compensate with Compensator.from_fit(path)"
        )
    try:
        model = decode_model(obj["model"])

        def metric(d):
            return Metrics(
                **{k: (int(v) if k == "n_samples" else _number(v)) for k, v in d.items()}
            )

        def numbers(d):
            return {k: _number(v) for k, v in d.items()}

        params = numbers(obj["params"])
        _check_saved_values(model, params, list(obj.get("outside_bounds", [])))
        return {
            "model": model,
            "params": params,
            "stderr": numbers(obj["stderr"]),
            "covariance": _array(obj["covariance"]).reshape(len(model.parameters), -1)
            if obj["covariance"]
            else np.zeros((0, 0)),
            "residuals": _array(obj["residuals"]),
            "metrics": metric(obj["metrics"]),
            "holdout_metrics": metric(obj["holdout_metrics"]),
            "aic": _number(obj["aic"]),
            "bic": _number(obj["bic"]),
            "converged": bool(obj["converged"]),
            "message": str(obj["message"]),
            "nfev": int(obj["nfev"]),
            "n_samples": int(obj["n_samples"]),
            "free": tuple(obj["free"]),
            "starts_tried": int(obj.get("starts_tried", 1)),
            "extra": {"outside_bounds": list(obj.get("outside_bounds", []))},
            "notes": list(obj.get("notes", [])),
            "stderr_reasons": dict(obj.get("stderr_reasons", {})),
            "initial_state": obj.get("initial_state"),
            "certificate": obj.get("certificate"),
            "start": numbers(obj.get("start", {})),
        }
    except CalibError as exc:
        raise CalibError(f"{where}: {exc}") from None
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise CalibError(f"{where}: bad fit record ({type(exc).__name__}: {exc})") from None


def _check_saved_values(model, params: Mapping[str, float], outside: list) -> None:
    """CalibError when a saved fit's numbers cannot be a fit's: a parameter of the model
    that is not finite or whose bounds are not ordered, a free one outside its bounds
    (unless the fit itself reported it: ``outside``, an unbounded method's result), or
    a ``params`` copy that is not the model's values (names and numbers)."""
    for p in model.parameters:
        value, lo, hi = float(p.value), float(p.lower), float(p.upper)
        if not math.isfinite(value):
            raise CalibError(
                f"parameter {p.name} is {value}; a saved fit's values are finite (the file "
                "was edited or damaged: fit again)"
            )
        if not lo <= hi:
            raise CalibError(f"parameter {p.name} has bounds {lo:g} > {hi:g}; give lower <= upper")
        if not p.fixed and not lo <= value <= hi and p.name not in outside:
            raise CalibError(
                f"parameter {p.name} = {value:g} is outside its bounds {lo:g}..{hi:g} (the fit "
                "reported no such value: the file was edited or damaged; fit again)"
            )
    values = {p.name: float(p.value) for p in model.parameters}
    if set(params) != set(values):
        extra = sorted(set(params) - set(values))
        missing = sorted(set(values) - set(params))
        raise CalibError(
            f"'params' does not name the model's parameters (extra: {', '.join(extra) or '-'}; "
            f"missing: {', '.join(missing) or '-'}); the two copies must agree"
        )
    for name, value in values.items():
        if not (params[name] == value or abs(params[name] - value) <= 1e-12 * abs(value)):
            raise CalibError(
                f"'params' says {name} = {params[name]:.10g} but the model {value:.10g}; the two "
                "copies must agree (the file was edited: fit again)"
            )


def write_record(path: str | os.PathLike, record: dict) -> Path:
    """Write ``record`` as strict JSON to ``path`` (replacing a file there) through a
    temporary file beside it (:func:`i2ris_calib._atomic.write_text`, the package's one
    atomic write), so a crash never leaves half a file; returns the path."""
    final = Path(path)
    if final.is_dir():
        raise CalibError(f"{final}: is a folder; give a file name, e.g. {final / 'fit.json'}")
    write_text(final, json.dumps(record, indent=1, allow_nan=False) + "\n")
    return final


def read_record(path: str | os.PathLike) -> dict:
    """The JSON object in ``path``; CalibError naming the file when unreadable."""
    p = Path(path)
    try:
        return json.loads(p.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise CalibError(f"{p}: cannot read a saved fit ({exc})") from None
