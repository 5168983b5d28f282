"""The catalogue of candidate effects: model extensions that wrap any base model.

An :class:`Effect` declares its own parameters and transforms the signals going
into the wrapped model (input-side effects: delay, dead zone, rate-dependent
backlash, an extra backlash stage) and/or the angle coming out of it
(output-side effects: coupling, creep, saturation). :class:`EffectModel` joins a
wrapped model and one effect into a new object that satisfies the
:class:`~i2ris_calib.hysteresis.model.Model` protocol, so effects stack
(``EffectModel(EffectModel(base, a), b)``) and the same fitter fits all of them.

Every effect has a *neutral* parameter vector for which the extended model equals
the wrapped one exactly (zero width, zero gain, zero delay, knee beyond the
range); the diagnosis starts candidates there or on a small grid around it.

The catalogue is not in the paper (Yue et al. list yaw-pitch coupling as future
work); each entry is the standard form the literature gives the effect's name,
with references in docs/design/diagnosis.md. Where a name covers two forms, both are
entries (``dead_zone`` and ``backlash``; ``rate_dependent_thresholds`` and
``rate_dependent_weights``; ``creep`` and ``creep_log``).
"""

from __future__ import annotations

import difflib
from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

import i2ris_calib._display as _display
from i2ris_calib._validate import as_real, check_model, check_signals, describe
from i2ris_calib.diagnosis._kernels import first_order_lag, play_varying, staged_backlash
from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.results import decode_model, encode_model, register_model_codec
from i2ris_calib.hysteresis.model import Model, NamedParameters, Parameter, Signals
from i2ris_calib.hysteresis.models import as_signals


@dataclass(frozen=True)
class Effect:
    """Base class of a catalogue entry. Subclasses override the transforms.

    Attributes
    ----------
    name : str
        Catalogue name, e.g. ``"time_delay"``.
    params : tuple of Parameter
        Declared parameters, in the order of the effect's value vector; each
        ``value`` is the neutral value (the effect does nothing there).
    meaning : str
        One-line physical meaning.
    needs : tuple of str
        Signals fields required (``"t_s"``, ``"other"``).
    """

    name: str = ""
    params: tuple[Parameter, ...] = ()
    meaning: str = ""
    needs: tuple[str, ...] = ()

    def neutral(self) -> np.ndarray:
        """Parameter vector for which the effect does nothing, shape (p,)."""
        return np.array([p.value for p in self.params], dtype=float)

    def transform_input(self, signals: Signals, p: np.ndarray) -> Signals:
        """Signals fed to the wrapped model (identity unless overridden)."""
        return signals

    def transform_output(self, y: np.ndarray, signals: Signals, p: np.ndarray) -> np.ndarray:
        """Angle (deg) returned by the extended model (identity unless overridden)."""
        return y

    def start_grid(self, signals: Signals, y_deg: np.ndarray) -> list[np.ndarray]:
        """Starting parameter vectors for the candidate fit, scaled to the data.

        Parameters
        ----------
        signals : Signals
            Data the candidate is fitted to.
        y_deg : ndarray, shape (n,)
            Current model output (deg), for output-side scales.
        """
        return [self.neutral()]

    def available(self, signals: Signals) -> str | None:
        """None when ``signals`` carry what the effect needs, else the reason."""
        if "t_s" in self.needs and signals.t_s is None:
            return "needs sample times (t_s)"
        if "other" in self.needs and not other_axis_moves(signals):
            return "needs the other axis's input or angle, and it does not move"
        return None


def other_axis_moves(signals: Signals, min_angle_range_deg: float = 1.0) -> bool:
    """True when the other axis moves: its input changes, or (input unknown) its
    measured angle spans more than ``min_angle_range_deg`` (1st-99th percentile),
    so that measurement noise alone does not count as motion."""
    if signals.v_other is not None:
        return bool(np.ptp(np.asarray(signals.v_other, float)) > 0)
    if signals.theta_other_deg is not None:
        th = np.asarray(signals.theta_other_deg, float)
        th = th[np.isfinite(th)]
        return th.size > 0 and float(np.subtract(*np.percentile(th, [99, 1]))) > min_angle_range_deg
    return False


def _span(a: np.ndarray) -> float:
    a = np.asarray(a, float)
    s = float(np.nanmax(a) - np.nanmin(a)) if a.size else 0.0
    return s if s > 0 else 1.0


@dataclass(frozen=True)
class MultiStageBacklash(Effect):
    """One more backlash stage engaged below a flag point on falling input."""

    name: str = "multi_stage_backlash"
    params: tuple[Parameter, ...] = (
        Parameter(
            "v_flag_counts",
            0.0,
            -1e9,
            1e9,
            unit="counts",
            doc="input below which the stage's slack is taken up on a falling branch",
        ),
        Parameter(
            "width_counts",
            0.0,
            0.0,
            1e9,
            unit="counts",
            doc="slack of the stage: input travel during which the output holds",
        ),
    )
    meaning: str = "a further backlash stage with its own flag point (EGPI-like switching)"

    def transform_input(self, signals, p):
        v = np.ascontiguousarray(signals.v, dtype=float)
        return replace(signals, v=staged_backlash(v, float(p[0]), float(p[1])))

    def start_grid(self, signals, y_deg):
        v = np.asarray(signals.v, float)
        span = _span(v)
        flags = np.nanmin(v) + span * np.linspace(0.1, 0.9, 9)
        return [np.array([f, w * span]) for f in flags for w in (0.03, 0.08)]


@dataclass(frozen=True)
class AxisCoupling(Effect):
    """Yaw-pitch coupling: the other axis's angle and its tendon input add linearly.

    ``y_c = y + k_theta theta_other + k_v v_other``: coupling through the other
    bending angle (the shared backbone bends both ways) and through the other
    tendon input (its pull loads this axis's sheath), the two paths Yue et al.
    name as future work. The fitted gains tell which path carries it.
    """

    name: str = "axis_coupling"
    params: tuple[Parameter, ...] = (
        Parameter(
            "gain_angle",
            0.0,
            -2.0,
            2.0,
            unit="deg/deg",
            doc="angle added per degree of the other axis's angle",
        ),
        Parameter(
            "gain_input_deg_per_count",
            0.0,
            -1.0,
            1.0,
            unit="deg/count",
            doc="angle added per count of the other axis's input",
        ),
    )
    meaning: str = "cross-talk: the other axis's bending or tendon pull moves this axis"
    needs: tuple[str, ...] = ("other",)

    def transform_output(self, y, signals, p):
        out = np.array(y, dtype=float)
        if signals.theta_other_deg is not None:
            th = np.asarray(signals.theta_other_deg, float)
            out = out + p[0] * np.where(np.isfinite(th), th, 0.0)
        if signals.v_other is not None:
            out = out + p[1] * np.asarray(signals.v_other, float)
        return out

    def start_grid(self, signals, y_deg):
        return [self.neutral()]


@dataclass(frozen=True)
class TimeDelay(Effect):
    """A pure delay between input and output."""

    name: str = "time_delay"
    params: tuple[Parameter, ...] = (
        Parameter("tau_s", 0.0, 0.0, 5.0, unit="s", doc="delay of the output behind the input"),
    )
    meaning: str = "transport delay (tendon wave, controller or logging latency)"
    needs: tuple[str, ...] = ("t_s",)

    def transform_input(self, signals, p):
        t = np.asarray(signals.t_s, float)
        v = np.asarray(signals.v, float)
        return replace(signals, v=np.interp(t - float(p[0]), t, v))

    def start_grid(self, signals, y_deg):
        return [np.array([tau]) for tau in (0.02, 0.05, 0.1, 0.15, 0.2, 0.3, 0.45, 0.7, 1.0, 1.5)]


@dataclass(frozen=True)
class RateDependentThresholds(Effect):
    """Play thresholds that grow with the input speed (rate-dependent PI).

    Al Janaideh and Krejci's rate-dependent Prandtl-Ishlinskii model raises every
    play threshold by the same speed term, ``r_i(t) = r_i + beta |dv/dt|``. A play
    of threshold ``r + c`` equals a play of ``c`` followed by a play of ``r``, so
    the common term is applied as a play on the input with half-width
    ``beta * |dv/dt|`` (the speed over the last ``RATE_WINDOW_S``), ahead of the
    base model's own rate-independent thresholds. The model's threshold-0 part
    (a linear term ``a v``) has no threshold to widen; as
    ``a v = a u + a (v - u)`` with ``u`` the played input, it is restored by the
    term ``linear_deg_per_count * (v - u)``. When the input stops, the thresholds
    fall back and the output catches up at once (a delay catches up over its delay
    instead).
    """

    name: str = "rate_dependent_thresholds"
    params: tuple[Parameter, ...] = (
        Parameter(
            "beta_s",
            0.0,
            0.0,
            5.0,
            unit="s",
            doc="threshold increase (input units) per input unit/s of speed",
        ),
        Parameter(
            "linear_deg_per_count",
            0.0,
            -1.0,
            1.0,
            unit="deg/count",
            doc="slope of the rate-independent (threshold-0) part, which does not widen",
        ),
    )
    meaning: str = (
        "rate-dependent hysteresis: the play thresholds widen with the input speed "
        "(viscous friction of the tendon in its sheath)"
    )
    needs: tuple[str, ...] = ("t_s",)

    def half_width(self, signals: Signals, p: np.ndarray) -> np.ndarray:
        """Half-width ``beta_s * |dv/dt|`` (input units), shape (n,)."""
        return float(p[0]) * _speed(signals, RATE_WINDOW_S)

    def _played(self, signals: Signals, p: np.ndarray) -> np.ndarray:
        v = np.ascontiguousarray(signals.v, dtype=float)
        return play_varying(v, self.half_width(signals, p))

    def transform_input(self, signals, p):
        return replace(signals, v=self._played(signals, p))

    def transform_output(self, y, signals, p):
        if p[1] == 0.0:
            return y
        v = np.asarray(signals.v, dtype=float)
        return np.asarray(y, float) + float(p[1]) * (v - self._played(signals, p))

    def start_grid(self, signals, y_deg):
        slope = _span(y_deg) / _span(signals.v)
        return [np.array([b, f * slope]) for b in (0.02, 0.05, 0.1, 0.2, 0.4) for f in (0.0, 0.4)]


@dataclass(frozen=True)
class RateDependentWeights(Effect):
    """Operator weights that grow (or shrink) with the input speed.

    The rate-dependent density of a Prandtl-Ishlinskii model (Al Janaideh, Rakheja
    and Su): ``y = sum_i w_i(dv/dt) F_ri[v]``. With a common speed factor,
    ``w_i(s) = w_i (1 + g s / S)``, the whole output scales:
    ``y (1 + g |dv/dt| / S)`` with ``S`` the 95th percentile of the input speed
    (so ``g`` is the relative gain at a typical fast stroke).
    """

    name: str = "rate_dependent_weights"
    params: tuple[Parameter, ...] = (
        Parameter(
            "gain",
            0.0,
            -0.5,
            1.0,
            unit="1",
            doc="relative change of the output at the 95th-percentile input speed",
        ),
    )
    meaning: str = "rate-dependent weights: the output gain changes with the input speed"
    needs: tuple[str, ...] = ("t_s",)

    def transform_output(self, y, signals, p):
        s = _speed(signals, RATE_WINDOW_S)
        ref = float(np.quantile(s, 0.95)) if s.size else 0.0
        if ref <= 0:
            return np.asarray(y, float)
        return np.asarray(y, float) * (1.0 + float(p[0]) * s / ref)

    def start_grid(self, signals, y_deg):
        return [np.array([g]) for g in (-0.1, 0.05, 0.15, 0.3)]


#: Window (s) of the input speed used by the rate-dependent effects.
RATE_WINDOW_S = 0.1


def _speed(signals: Signals, window_s: float) -> np.ndarray:
    """|dv/dt| (input units/s), shape (n,): the centred difference over ``window_s``,
    with ``v`` interpolated in time so the estimate does not depend on the sampling
    rate (the diagnosis may decimate the signal)."""
    t = np.asarray(signals.t_s, float)
    v = np.asarray(signals.v, float)
    if v.size < 2:
        return np.zeros_like(v)
    h = 0.5 * window_s
    hi = np.minimum(t + h, t[-1])
    lo = np.maximum(t - h, t[0])
    dt = np.where(hi > lo, hi - lo, 1.0)
    return np.ascontiguousarray(np.abs(np.interp(hi, t, v) - np.interp(lo, t, v)) / dt)


@dataclass(frozen=True)
class Creep(Effect):
    """Slow first-order relaxation of part of every output change.

    ``y_c = (1 - g) y + g L_tau[y]`` with ``L_tau`` a first-order lag: a fraction
    ``g`` of every output change arrives with time constant ``tau`` (one Kelvin-Voigt
    element, the standard linear solid of visco-elastic creep).
    """

    name: str = "creep"
    params: tuple[Parameter, ...] = (
        Parameter(
            "gain",
            0.0,
            0.0,
            0.6,
            unit="1",
            doc="fraction of an output change that arrives slowly",
        ),
        Parameter(
            "tau_s", 1.0, 0.3, 100.0, unit="s", doc="time constant of the slow part (>= 0.3 s)"
        ),
    )
    meaning: str = "first-order creep: part of every move arrives with one time constant"
    needs: tuple[str, ...] = ("t_s",)

    def transform_output(self, y, signals, p):
        y = np.ascontiguousarray(y, dtype=float)
        t = np.ascontiguousarray(signals.t_s, dtype=float)
        return (1.0 - p[0]) * y + p[0] * first_order_lag(y, t, float(p[1]))

    def start_grid(self, signals, y_deg):
        return [np.array([g, tau]) for g in (0.05, 0.15, 0.3) for tau in (0.4, 0.8, 1.5, 3.0, 6.0)]


#: Relaxation times of the logarithmic creep per decade, and its decades.
LOG_CREEP_PER_DECADE = 2
LOG_CREEP_DECADES = 4


@dataclass(frozen=True)
class LogCreep(Effect):
    """Logarithmic creep: after a step the output keeps drifting by a fixed
    fraction per decade of time.

    The creep law of piezo actuators and polymers (e.g. Jung and Gweon; Changhai
    and Lining): after an output step ``dy`` at ``t0``, ``y(t) = y1 +
    gamma dy log10((t - t0) / tau0)``. Written as relaxation times spread evenly
    in ``log tau`` (``LOG_CREEP_PER_DECADE`` per decade over
    ``LOG_CREEP_DECADES`` decades from ``tau0``), each carrying
    ``gamma / LOG_CREEP_PER_DECADE`` of the change:
    ``y_c = y - gamma / m * sum_j (y - L_tau_j[y])``, so between ``tau0`` and
    ``10^4 tau0`` the response to a step grows by ``gamma dy`` per decade.
    """

    name: str = "creep_log"
    params: tuple[Parameter, ...] = (
        Parameter(
            "gamma_per_decade",
            0.0,
            0.0,
            0.2,
            unit="1/decade",
            doc="fraction of an output change added per decade of time after it",
        ),
        Parameter(
            "tau0_s", 0.3, 0.05, 10.0, unit="s", doc="time from which the drift is logarithmic"
        ),
    )
    meaning: str = (
        "logarithmic creep: the angle keeps drifting after a move, by the same amount "
        "per decade of time"
    )
    needs: tuple[str, ...] = ("t_s",)

    def taus(self, tau0_s: float) -> np.ndarray:
        """Relaxation times (s), shape (m * decades + 1,)."""
        m = LOG_CREEP_PER_DECADE
        return tau0_s * 10.0 ** (np.arange(m * LOG_CREEP_DECADES + 1) / m)

    def transform_output(self, y, signals, p):
        y = np.ascontiguousarray(y, dtype=float)
        t = np.ascontiguousarray(signals.t_s, dtype=float)
        gam = float(p[0]) / LOG_CREEP_PER_DECADE
        if gam == 0.0:
            return y
        lagged = sum(first_order_lag(y, t, float(tau)) for tau in self.taus(float(p[1])))
        n = self.taus(float(p[1])).size
        return y - gam * (n * y - lagged)

    def start_grid(self, signals, y_deg):
        return [np.array([g, tau]) for g in (0.01, 0.03, 0.06) for tau in (0.1, 0.3, 1.0)]


@dataclass(frozen=True)
class DeadZone(Effect):
    """Dead zone (dead band) on the input: nothing moves until |v| exceeds ``d``.

    The dead-zone nonlinearity of Tao and Kokotovic: ``u = sign(v) max(|v| - d,
    0)`` (its slope beyond the break point is absorbed by the base model's
    gains), then the base model's hysteresis of ``u``. Unlike a backlash it
    depends on the input level, not on the last reversal.
    """

    name: str = "dead_zone"
    params: tuple[Parameter, ...] = (
        Parameter(
            "d_counts",
            0.0,
            0.0,
            1e9,
            unit="counts",
            doc="input magnitude below which the output does not move",
        ),
    )
    meaning: str = (
        "dead zone (Tao-Kokotovic): the tip does not move until the input exceeds a "
        "break point (tendon slack at the start of the pull)"
    )

    def transform_input(self, signals, p):
        v = np.asarray(signals.v, dtype=float)
        d = float(p[0])
        return replace(signals, v=np.sign(v) * np.maximum(np.abs(v) - d, 0.0))

    def start_grid(self, signals, y_deg):
        span = _span(signals.v)
        return [np.array([f * span]) for f in (0.02, 0.05, 0.1, 0.15, 0.25)]


@dataclass(frozen=True)
class Backlash(Effect):
    """Backlash (play): after each reversal the input travels ``width`` before the
    output follows (Tao and Kokotovic's backlash, a play operator on the input)."""

    name: str = "backlash"
    params: tuple[Parameter, ...] = (
        Parameter(
            "width_counts",
            0.0,
            0.0,
            1e9,
            unit="counts",
            doc="input travel after a reversal before the output moves",
        ),
    )
    meaning: str = "backlash (play): after a reversal the input moves, the tip does not"

    def transform_input(self, signals, p):
        v = np.ascontiguousarray(signals.v, dtype=float)
        h = np.full(v.shape, 0.5 * float(p[0]))
        return replace(signals, v=play_varying(v, h))

    def start_grid(self, signals, y_deg):
        span = _span(signals.v)
        return [np.array([f * span]) for f in (0.01, 0.02, 0.04, 0.06, 0.1)]


@dataclass(frozen=True)
class Saturation(Effect):
    """Output flattening beyond a knee (applied to |angle|, sign kept)."""

    name: str = "saturation"
    params: tuple[Parameter, ...] = (
        Parameter(
            "knee_deg",
            1e6,
            0.0,
            1e6,
            unit="deg",
            doc="|angle| above which the output starts to flatten",
        ),
        Parameter(
            "limit_deg",
            10.0,
            0.01,
            1e3,
            unit="deg",
            doc="largest |angle| reachable beyond the knee",
        ),
    )
    meaning: str = "the tip runs out of travel: tendon stretch or joint stops near the end"

    def transform_output(self, y, signals, p):
        y = np.asarray(y, dtype=float)
        knee, lim = float(p[0]), float(p[1])
        a = np.abs(y)
        over = np.maximum(a - knee, 0.0)
        sat = np.where(a > knee, knee + lim * np.tanh(over / lim), a)
        return np.sign(y) * sat

    def start_grid(self, signals, y_deg):
        a = np.abs(np.asarray(y_deg, float))
        top = float(np.nanmax(a)) if a.size else 1.0
        return [np.array([q * top, f * top]) for q in (0.6, 0.75, 0.9) for f in (0.05, 0.15, 0.4)]


#: The catalogue, by name, in documentation order.
CATALOGUE: dict[str, Effect] = {
    e.name: e
    for e in (
        MultiStageBacklash(),
        AxisCoupling(),
        TimeDelay(),
        RateDependentThresholds(),
        RateDependentWeights(),
        Creep(),
        LogCreep(),
        DeadZone(),
        Backlash(),
        Saturation(),
    )
}


def get_effect(name: str) -> Effect:
    """The catalogue entry ``name``; CalibError with the closest name otherwise."""
    if name in CATALOGUE:
        return CATALOGUE[name]
    close = difflib.get_close_matches(name, list(CATALOGUE), n=1, cutoff=0.5)
    hint = f"did you mean '{close[0]}'?" if close else f"valid: {', '.join(CATALOGUE)}"
    raise CalibError(f"unknown effect '{name}' ({hint})")


@dataclass(frozen=True)
class EffectModel(NamedParameters):
    """A model extended by one effect; satisfies the Model protocol.

    Parameters of the wrapped model come first, then the effect's, named
    ``"<label>.<param>"`` (e.g. ``"time_delay.tau_s"``). Like a
    :class:`~i2ris_calib.hysteresis.models.ParametricModel` it is callable
    (``model(signals)`` is the angle at its current values) and ``values`` is the
    current vector of *all* its parameters, shape (p,).

    Attributes
    ----------
    inner : Model
        The wrapped model (a base model or another EffectModel).
    effect : Effect
        The catalogue entry.
    effect_values : tuple of float
        The effect's own parameter values, shape (p_effect,).
    label : str
        Prefix of the effect's parameter names (the effect name, suffixed
        ``_2``, ``_3``... when the same effect is stacked twice).
    fixed : tuple of bool
        Fixed flags of the effect's parameters (default all free).
    """

    inner: Model
    effect: Effect
    effect_values: tuple[float, ...]
    label: str = ""
    fixed: tuple[bool, ...] = ()

    @property
    def name(self) -> str:
        return f"{self.inner.name}+{self.label or self.effect.name}"

    @property
    def n_inner(self) -> int:
        """Number of parameters of the wrapped model."""
        return len(self.inner.parameters)

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        label = self.label or self.effect.name
        fixed = self.fixed or (False,) * len(self.effect.params)
        own = tuple(
            replace(p, name=f"{label}.{p.name}", value=float(v), fixed=bool(f))
            for p, v, f in zip(self.effect.params, self.effect_values, fixed, strict=True)
        )
        return tuple(self.inner.parameters) + own

    def __call__(self, signals: Signals | np.ndarray) -> np.ndarray:
        """Angle (deg), shape (n,), at the model's current values."""
        check_signals(f"{self.name} model", "signals", signals)
        return self.evaluate(as_signals(signals), self.values)

    def evaluate(self, signals: Signals, values: np.ndarray) -> np.ndarray:
        """Angle (deg), shape (n,): the wrapped model on transformed signals, then
        the output transform."""
        values = np.asarray(values, dtype=float)
        m = self.n_inner
        pin, peff = values[:m], values[m:]
        y = self.inner.evaluate(self.effect.transform_input(signals, peff), pin)
        return self.effect.transform_output(y, signals, peff)

    def with_values(self, values: np.ndarray) -> EffectModel:
        """A new model whose parameter values are ``values``, shape (p,)."""
        values = np.asarray(values, dtype=float)
        m = self.n_inner
        return replace(
            self,
            inner=self.inner.with_values(values[:m]),
            effect_values=tuple(float(x) for x in values[m:]),
        )

    def __repr__(self) -> str:
        # the effects' values first (what a diagnosis added), then the base model's
        params = self.parameters
        m = len(base_of(self).parameters)
        n_fixed = sum(bool(p.fixed) for p in params)
        head = f"<EffectModel '{self.name}' ({len(params)} parameters, {n_fixed} fixed): "
        order = (*params[m:], *params[:m])
        return _display.name_values(((p.name, p.value) for p in order), head)

    def nested(self) -> tuple[Model, np.ndarray]:
        """The model this one extends and the values that switch the extension off.

        The fitter (:func:`~i2ris_calib.fitting.fit.fit_model`) fits the wrapped model
        first and also starts from ``(its fitted values, tail)``, so an extended fit
        is never worse than the fit without the effect.

        Returns
        -------
        inner : Model
            The wrapped model.
        tail : ndarray, shape (p_effect,)
            The effect's neutral values (its fixed parameters keep their values);
            at ``concatenate([x_inner, tail])`` this model equals ``inner`` at
            ``x_inner`` whenever no parameter is fixed away from neutral.
        """
        fixed = np.array(self.fixed or (False,) * len(self.effect.params), dtype=bool)
        tail = np.where(fixed, np.asarray(self.effect_values, float), self.effect.neutral())
        return self.inner, tail


def model_values(model: Model) -> np.ndarray:
    """Current parameter vector of ``model``, shape (p,)."""
    return np.array([p.value for p in model.parameters], dtype=float)


def base_of(model: Model) -> Model:
    """The innermost (base) model under any stack of effects."""
    while isinstance(model, EffectModel):
        model = model.inner
    return model


def effects_of(model: Model) -> list[tuple[str, str, dict[str, float]]]:
    """Effects of ``model`` innermost first, as (effect name, label, {param: value})."""
    out = []
    while isinstance(model, EffectModel):
        vals = {
            p.name: float(v) for p, v in zip(model.effect.params, model.effect_values, strict=True)
        }
        out.append((model.effect.name, model.label or model.effect.name, vals))
        model = model.inner
    return out[::-1]


def add_effect(model: Model, name: str, values: Mapping[str, float] | None = None) -> EffectModel:
    """``model`` extended by catalogue effect ``name``.

    Parameters
    ----------
    model : Model
        Model to wrap (unchanged).
    name : str
        Catalogue name (see :data:`CATALOGUE`).
    values : mapping, optional
        Effect parameter values by (unprefixed) name; missing ones take the
        effect's neutral default. Unknown names or values outside the declared
        bounds raise CalibError.
    """
    func = "add_effect"
    check_model(func, "model", model, usage="add_effect(model, name, values)")
    if not isinstance(name, str):
        raise CalibError(
            f"{func}: name is {describe(name)}; give an effect name: {', '.join(CATALOGUE)}"
        )
    effect = get_effect(name)
    if values is not None and not isinstance(values, Mapping):
        raise CalibError(
            f"{func}: values is {describe(values)}; give a dict {{parameter: value}}, e.g. "
            f"{{{effect.params[0].name!r}: {effect.params[0].value:g}}}"
        )
    values = dict(values or {})
    known = [p.name for p in effect.params]
    for key in values:
        if key not in known:
            close = difflib.get_close_matches(key, known, n=1, cutoff=0.5)
            hint = f"did you mean '{close[0]}'?" if close else f"valid: {', '.join(known)}"
            raise CalibError(f"effect '{name}': unknown parameter '{key}' ({hint})")
    vec = []
    for p in effect.params:
        v = float(as_real(func, f"values[{p.name!r}]", values.get(p.name, p.value)))
        if not (p.lower <= v <= p.upper) or not np.isfinite(v):
            raise CalibError(
                f"effect '{name}': {p.name} = {v} outside [{p.lower}, {p.upper}] {p.unit}"
            )
        vec.append(v)
    used = {lbl for _, lbl, _ in effects_of(model)}
    label, k = name, 2
    while label in used:
        label, k = f"{name}_{k}", k + 1
    return EffectModel(inner=model, effect=effect, effect_values=tuple(vec), label=label)


def build_model(base: Model, effects: Mapping[str, Mapping[str, float]]) -> Model:
    """``base`` extended by the given effects, applied in mapping order.

    This is the function the simulator uses to render truth data with hidden
    effects (``[simulate] effects`` config table). The first effect listed wraps
    the base model directly; each further one wraps the result (so input-side
    transforms of later effects act first, output-side ones last).

    Parameters
    ----------
    base : Model
        Base model with its parameter values (e.g. a fitted or truth EGPI).
    effects : mapping of str to mapping of str to float
        Effect name -> its parameter values (unprefixed names as declared in
        :data:`CATALOGUE`; omitted ones take the neutral default).

    Returns
    -------
    Model
        ``base`` itself when ``effects`` is empty, else an :class:`EffectModel`.

    Examples
    --------
    >>> m = build_model(egpi, {"time_delay": {"tau_s": 0.15}})  # doctest: +SKIP
    >>> theta = m.evaluate(Signals(v=v, t_s=t), model_values(m))  # doctest: +SKIP
    """
    model = base
    for name, values in effects.items():
        model = add_effect(model, name, values)
    return model


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


register_model_codec("effects", _encode_effects, _decode_effects)
