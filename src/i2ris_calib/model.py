"""The model contract shared by hysteresis models, fitters and the diagnosis workflow.

A model declares its parameters (name, initial value, bounds, fixed flag, unit,
one-line meaning) and has a pure ``evaluate``. A model is immutable: fitting never
changes it; ``with_values`` returns a new model.

Design follows astropy.modeling / lmfit: parameters are data, evaluation is a pure
function of (signals, parameter vector).
"""

from __future__ import annotations

from dataclasses import KW_ONLY, dataclass, field, replace
from typing import Protocol, runtime_checkable

import numpy as np

import i2ris_calib._display as _display


@dataclass(frozen=True)
class Parameter:
    """One model parameter: ``Parameter("a1", value=0.01, lower=0.0, unit="deg/count")``
    (every field after the name by keyword).

    Attributes
    ----------
    name : str
        Identifier, unique within a model (e.g. ``"a1"``, ``"kappa"``).
    value : float
        Initial (or fitted) value.
    lower, upper : float
        Bounds used by bounded fits and by start-point sampling.
    fixed : bool
        Held at ``value`` during fitting when True.
    unit : str
        Unit string, e.g. ``"deg/count"``.
    doc : str
        One-line meaning.
    """

    name: str
    _: KW_ONLY
    value: float
    lower: float = -np.inf
    upper: float = np.inf
    fixed: bool = False
    unit: str = ""
    doc: str = ""


class NamedParameters:
    """``names``, ``values`` and ``value_dict`` of anything with a ``parameters``
    tuple (hysteresis models, models extended by diagnosed effects)."""

    parameters: tuple[Parameter, ...]

    @property
    def names(self) -> tuple[str, ...]:
        """Parameter names in vector order."""
        return tuple(p.name for p in self.parameters)

    @property
    def values(self) -> np.ndarray:
        """Current parameter values, shape (p,)."""
        return np.array([p.value for p in self.parameters], dtype=float)

    def value_dict(self) -> dict[str, float]:
        """``{name: value}`` of the current parameters."""
        return {p.name: float(p.value) for p in self.parameters}

    # Display: one line (name, parameter values) and, in a notebook, a table of the
    # declared parameters. A dataclass subclass would get a generated repr (a dump of
    # every field, 1-2k characters): every subclass keeps this one unless it defines
    # its own.
    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        for name in ("__repr__", "_repr_html_"):
            if name not in cls.__dict__:
                setattr(cls, name, getattr(NamedParameters, name))

    def __repr__(self) -> str:
        params = self.parameters
        n_fixed = sum(bool(p.fixed) for p in params)
        head = f"<{type(self).__name__} '{self.name}' ({len(params)} parameters, {n_fixed} fixed): "
        return _display.name_values(((p.name, p.value) for p in params), head)

    def _repr_html_(self) -> str:
        """Notebook display: every declared parameter (value, bounds, fixed, unit, meaning)."""
        rows = [
            (p.name, float(p.value), float(p.lower), float(p.upper), "yes" if p.fixed else "",
             p.unit, p.doc)
            for p in self.parameters
        ]  # fmt: skip
        title = f"<b>{_display.esc(type(self).__name__)}</b> {_display.esc(self.name)}"
        header = ("name", "value", "lower", "upper", "fixed", "unit", "meaning")
        return _display.table(header, rows, title)


@dataclass(frozen=True)
class Signals:
    """Everything a model may read, all arrays of shape (n,) in time order.

    Attributes
    ----------
    v : ndarray, shape (n,)
        This axis's input (encoder counts; |counts| for a negative-input dataset).
    t_s : ndarray, shape (n,), optional
        Sample times in seconds (controller clock). Needed by time-dependent
        effects (delay, creep, rate dependence).
    v_other : ndarray, shape (n,), optional
        The other axis's input (counts), for coupling effects.
    theta_other_deg : ndarray, shape (n,), optional
        The other axis's measured angle (deg), for coupling effects.
    """

    v: np.ndarray
    t_s: np.ndarray | None = None
    v_other: np.ndarray | None = None
    theta_other_deg: np.ndarray | None = None
    extra: dict = field(default_factory=dict)

    def take(self, idx: np.ndarray) -> Signals:
        """Signals restricted to index array or slice ``idx``."""

        def sub(a):
            return None if a is None else np.asarray(a)[idx]

        return replace(
            self,
            v=np.asarray(self.v)[idx],
            t_s=sub(self.t_s),
            v_other=sub(self.v_other),
            theta_other_deg=sub(self.theta_other_deg),
        )


@runtime_checkable
class Model(Protocol):
    """A hysteresis (or extended) model: parameters plus a pure evaluate."""

    name: str

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        """Declared parameters, in the order of the value vector."""
        ...

    def evaluate(self, signals: Signals, values: np.ndarray) -> np.ndarray:
        """Output angle in deg, shape (n,), for parameter vector ``values`` (shape (p,))."""
        ...

    def with_values(self, values: np.ndarray) -> Model:
        """A new model whose parameter values are ``values``."""
        ...


def analytic_method(model, method: str = "jacobian"):
    """``model.<method>`` (``jacobian``, ``flag_point_families``) when the model's class
    defines it together with the ``evaluate`` it stands for (a subclass overriding only
    ``evaluate`` falls back to finite differences / plain evaluations), else None."""
    cls = type(model)

    def owner(name):
        return next((c for c in cls.__mro__ if name in c.__dict__), None)

    if owner(method) is None or owner(method) is not owner("evaluate"):
        return None
    return getattr(model, method)
