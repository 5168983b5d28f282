"""The catalogue of candidate effects: model extensions that wrap any base model.

An :class:`Effect` declares its own parameters and transforms the signals going
into the wrapped model (input-side effects: delay, dead zone, rate-dependent
backlash, an extra backlash stage) and/or the angle coming out of it
(output-side effects: coupling, creep, saturation). :class:`EffectModel` joins a
wrapped model and one effect into a new object that satisfies the
:class:`~i2ris_calib.model.Model` protocol, so effects stack
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
from typing import ClassVar

import numpy as np

import i2ris_calib._display as _display
from i2ris_calib._validate import as_real, check_model, check_signals, describe
from i2ris_calib.errors import CalibError
from i2ris_calib.hysteresis.effect_kernels import (
    lag_coefficients,
    lag_sum_with,
    play_varying,
    staged_backlash,
)
from i2ris_calib.hysteresis.models import as_signals
from i2ris_calib.model import Model, NamedParameters, Parameter, Signals
from i2ris_calib.model import analytic_method as _analytic_jacobian

#: Parameter sets of a hidden effect, by parameter name (:attr:`Effect.strengths`).
Strengths = tuple[Mapping[str, float], ...]


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

    The class attributes below are what the stages know of an effect (each read from
    here, nowhere else): ``strengths`` (synthetic cases, ``diagnosis.synthetic``),
    ``separating_from_base`` and ``separating`` (the diagnosis's advice,
    ``diagnosis.results``), ``rate`` (``diagnosis.stats``), ``compensated``
    (``compensation.inverse``).
    """

    name: str = ""
    params: tuple[Parameter, ...] = ()
    meaning: str = ""
    needs: tuple[str, ...] = ()
    #: Parameter sets of a hidden effect in synthetic data (input 0..6000 counts, angle
    #: ~0..37 deg, speeds 300-2000 counts/s), weakest first.
    strengths: ClassVar[Strengths] = ()
    #: A recording that shows the effect where the start model absorbs it ("": none known).
    separating_from_base: ClassVar[str] = ""
    #: Recordings that separate it from another effect, by that effect's name; a pair is
    #: written once, on the later of the two in :data:`CATALOGUE`.
    separating: ClassVar[Mapping[str, str]] = {}
    #: The input speed is its only signature (a rate effect: on a recording whose speed
    #: is a function of the input level it fits as well as a static shape).
    rate: ClassVar[bool] = False
    #: ``compensate`` inverts a model extended by it.
    compensated: ClassVar[bool] = False

    def neutral(self) -> np.ndarray:
        """Parameter vector for which the effect does nothing, shape (p,)."""
        return np.array([p.value for p in self.params], dtype=float)

    def transform_input(self, signals: Signals, p: np.ndarray) -> Signals:
        """Signals fed to the wrapped model (identity unless overridden)."""
        return signals

    def transform_output(self, y: np.ndarray, signals: Signals, p: np.ndarray) -> np.ndarray:
        """Angle (deg) returned by the extended model (identity unless overridden)."""
        return y

    def input_side(self) -> bool:
        """True when the effect transforms the input (then its parameters move the
        wrapped model's output and every derivative by them re-runs the model)."""
        return type(self).transform_input is not Effect.transform_input

    def output_pointwise(self) -> bool:
        """True when output sample k depends on the wrapped model's output at sample
        k alone (then :meth:`output_jacobian` is only given the rows asked for)."""
        return type(self).transform_output is Effect.transform_output

    def output_jacobian(
        self,
        jac: np.ndarray,
        y: np.ndarray | None,
        signals: Signals,
        p: np.ndarray,
        rows: np.ndarray | None = None,
    ) -> np.ndarray:
        """Columns of the wrapped model's Jacobian pushed through :meth:`transform_output`.

        The default is exact for the identity and, for any other transform,
        central differences along each column (exact for a transform linear in
        ``y``; no re-run of the wrapped model). Catalogue entries with an output
        transform override it with its exact derivative.

        Parameters
        ----------
        jac : ndarray, shape (k, m)
            d y / d x (deg per unit) of the wrapped model's output at the samples
            ``rows`` (every sample, k = n, when ``rows`` is None).
        y : ndarray, shape (n,), or None
            The wrapped model's output (deg) at every sample (None when
            :meth:`transform_output` is not overridden).
        signals : Signals
            Signals of the extended model, shape (n,) each.
        p : ndarray, shape (p_effect,)
            The effect's parameter values.
        rows : ndarray of int, shape (k,), optional
            Sample indices of ``jac``'s rows; given only when
            :meth:`output_pointwise` is True.

        Returns
        -------
        ndarray, shape (k, m)
            d transform_output / d x (deg per unit).
        """
        if type(self).transform_output is Effect.transform_output:
            return jac
        return _central_output_columns(self, jac, y, signals, p)

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


def _central_output_columns(effect: Effect, jac, y, signals, p) -> np.ndarray:
    """``(T(y + h c) - T(y - h c)) / 2h`` for every column ``c`` of ``jac``, shape
    (n, m), with ``T`` the effect's output transform (every sample)."""
    y = np.asarray(y, float)
    out = np.empty(jac.shape, order="F")
    size = 1.0 + float(np.max(np.abs(y))) if y.size else 1.0
    for j in range(jac.shape[1]):
        c = np.asarray(jac[:, j], float)
        top = float(np.max(np.abs(c))) if c.size else 0.0
        if not np.isfinite(top) or top == 0.0:
            out[:, j] = c
            continue
        h = 1e-5 * size / top
        up = effect.transform_output(y + h * c, signals, p)
        down = effect.transform_output(y - h * c, signals, p)
        out[:, j] = (up - down) / (2.0 * h)
    return out


def _lagged_columns(jac: np.ndarray, t: np.ndarray, taus: np.ndarray) -> np.ndarray:
    """Sum over ``taus`` (s) of :func:`~.effect_kernels.first_order_lag` of every column of
    ``jac`` (shape (n, m)), shape (n, m), to the last bit as the lags one by one."""
    return lag_sum_with(np.asarray(jac, dtype=float), _coefficients(t, taus))


#: The last few lag coefficient tables, by (id(t), taus): a fit holds the creep's time
#: constants for many evaluations, and the exponentials are most of a lag's cost.
_COEFFICIENTS: dict = {}


def _coefficients(t: np.ndarray, taus) -> np.ndarray:
    """:func:`~.effect_kernels.lag_coefficients` of ``t`` (s, shape (n,)) and ``taus`` (s),
    shape (n, q), cached for the same ``t`` object and values."""
    t = np.ascontiguousarray(t, dtype=float)
    taus = np.ascontiguousarray(taus, dtype=float)
    key = (id(t), t.size, taus.tobytes())
    hit = _COEFFICIENTS.get(key)
    # the entry holds t itself (so its id is not reused) and a copy to see a change
    if hit is not None and hit[0] is t and np.array_equal(hit[1], t):
        return hit[2]
    a = lag_coefficients(t, taus)
    if len(_COEFFICIENTS) >= 8:
        _COEFFICIENTS.pop(next(iter(_COEFFICIENTS)), None)
    _COEFFICIENTS[key] = (t, t.copy(), a)
    return a


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


_LONG_HOLDS = (
    "long holds (10 s or more) after fast ramps: creep keeps moving over seconds, a "
    "delay settles within its delay"
)
_PARTIAL_UNLOADING = (
    "partial unloading cycles that reverse above and below mid-range: a further "
    "backlash stage holds on falling input below its flag point, a dead zone holds "
    "only below its break point, rising or falling"
)


@dataclass(frozen=True)
class MultiStageBacklash(Effect):
    """One more backlash stage engaged below a flag point on falling input."""

    name: str = "multi_stage_backlash"
    params: tuple[Parameter, ...] = (
        Parameter(
            "v_flag_counts",
            value=0.0,
            lower=-1e9,
            upper=1e9,
            unit="counts",
            doc="input below which the stage's slack is taken up on a falling branch",
        ),
        Parameter(
            "width_counts",
            value=0.0,
            lower=0.0,
            upper=1e9,
            unit="counts",
            doc="slack of the stage: input travel during which the output holds",
        ),
    )
    meaning: str = "a further backlash stage with its own flag point (EGPI-like switching)"
    strengths: ClassVar[Strengths] = (
        {"v_flag_counts": 2500.0, "width_counts": 300.0},
        {"v_flag_counts": 3000.0, "width_counts": 450.0},
        {"v_flag_counts": 2000.0, "width_counts": 600.0},
    )
    separating_from_base: ClassVar[str] = _PARTIAL_UNLOADING

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
            value=0.0,
            lower=-2.0,
            upper=2.0,
            unit="deg/deg",
            doc="angle added per degree of the other axis's angle",
        ),
        Parameter(
            "gain_input_deg_per_count",
            value=0.0,
            lower=-1.0,
            upper=1.0,
            unit="deg/count",
            doc="angle added per count of the other axis's input",
        ),
    )
    meaning: str = "cross-talk: the other axis's bending or tendon pull moves this axis"
    needs: tuple[str, ...] = ("other",)
    strengths: ClassVar[Strengths] = (
        {"gain_angle": 0.05},
        {"gain_angle": 0.1},
        {"gain_angle": -0.15},
    )
    separating_from_base: ClassVar[str] = "move the other axis alone while this one holds its input"

    def transform_output(self, y, signals, p):
        out = np.array(y, dtype=float)
        if signals.theta_other_deg is not None:
            th = np.asarray(signals.theta_other_deg, float)
            out = out + p[0] * np.where(np.isfinite(th), th, 0.0)
        if signals.v_other is not None:
            out = out + p[1] * np.asarray(signals.v_other, float)
        return out

    def output_pointwise(self):
        return True

    def output_jacobian(self, jac, y, signals, p, rows=None):
        return jac  # y enters with slope 1

    def start_grid(self, signals, y_deg):
        return [self.neutral()]


@dataclass(frozen=True)
class TimeDelay(Effect):
    """A pure delay between input and output."""

    name: str = "time_delay"
    params: tuple[Parameter, ...] = (
        Parameter(
            "tau_s",
            value=0.0,
            lower=0.0,
            upper=5.0,
            unit="s",
            doc="delay of the output behind the input",
        ),
    )
    meaning: str = "transport delay (tendon wave, controller or logging latency)"
    needs: tuple[str, ...] = ("t_s",)
    strengths: ClassVar[Strengths] = ({"tau_s": 0.06}, {"tau_s": 0.12}, {"tau_s": 0.25})
    separating_from_base: ClassVar[str] = (
        "a fast ramp that stops without a hold-in: a delay keeps the angle moving for "
        "its delay after the input stops"
    )
    compensated: ClassVar[bool] = True

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
            value=0.0,
            lower=0.0,
            upper=5.0,
            unit="s",
            doc="threshold increase (input units) per input unit/s of speed",
        ),
        Parameter(
            "linear_deg_per_count",
            value=0.0,
            lower=-1.0,
            upper=1.0,
            unit="deg/count",
            doc="slope of the rate-independent (threshold-0) part, which does not widen",
        ),
    )
    meaning: str = (
        "rate-dependent hysteresis: the play thresholds widen with the input speed "
        "(viscous friction of the tendon in its sheath)"
    )
    needs: tuple[str, ...] = ("t_s",)
    strengths: ClassVar[Strengths] = ({"beta_s": 0.08}, {"beta_s": 0.15}, {"beta_s": 0.3})
    separating_from_base: ClassVar[str] = (
        "ramps at three speeds to the same level with holds: the loop widens with speed"
    )
    separating: ClassVar[Mapping[str, str]] = {
        "time_delay": (
            "a slow and a fast ramp to the same level, and a triangle without a hold at the "
            "top: a delay overshoots a reversal taken at speed and lags by the same time at "
            "every speed, rate-dependent thresholds hold flat at the reversal"
        ),
    }
    rate: ClassVar[bool] = True

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

    def output_pointwise(self):
        return True

    def output_jacobian(self, jac, y, signals, p, rows=None):
        return jac  # y enters with slope 1

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
            value=0.0,
            lower=-0.5,
            upper=1.0,
            unit="1",
            doc="relative change of the output at the 95th-percentile input speed",
        ),
    )
    meaning: str = "rate-dependent weights: the output gain changes with the input speed"
    needs: tuple[str, ...] = ("t_s",)
    strengths: ClassVar[Strengths] = ({"gain": 0.08}, {"gain": 0.15}, {"gain": -0.15})
    separating_from_base: ClassVar[str] = (
        "ramps at three speeds to the same level with holds: the loop's slope changes with speed"
    )
    separating: ClassVar[Mapping[str, str]] = {
        "rate_dependent_thresholds": (
            "ramps at three speeds to the same level with holds: rate-dependent weights "
            "change the slope of the loop while moving, rate-dependent thresholds its width"
        ),
        "time_delay": (
            "ramps at three speeds to the same level with holds: a delay shifts the loop in "
            "time, rate-dependent weights scale it with speed"
        ),
    }
    rate: ClassVar[bool] = True

    def factor(self, signals: Signals, p: np.ndarray) -> np.ndarray | None:
        """Output factor ``1 + g |dv/dt| / S``, shape (n,); None when the input
        does not move (then the output is unchanged)."""
        s = _speed(signals, RATE_WINDOW_S)
        ref = float(np.quantile(s, 0.95)) if s.size else 0.0
        if ref <= 0:
            return None
        return 1.0 + float(p[0]) * s / ref

    def transform_output(self, y, signals, p):
        f = self.factor(signals, p)
        return np.asarray(y, float) if f is None else np.asarray(y, float) * f

    def output_pointwise(self):
        return True

    def output_jacobian(self, jac, y, signals, p, rows=None):
        f = self.factor(signals, p)
        if f is None:
            return jac
        return jac * (f if rows is None else f[np.asarray(rows)])[:, None]

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
            value=0.0,
            lower=0.0,
            upper=0.6,
            unit="1",
            doc="fraction of an output change that arrives slowly",
        ),
        Parameter(
            "tau_s",
            value=1.0,
            lower=0.3,
            upper=100.0,
            unit="s",
            doc="time constant of the slow part (>= 0.3 s)",
        ),
    )
    meaning: str = "first-order creep: part of every move arrives with one time constant"
    needs: tuple[str, ...] = ("t_s",)
    strengths: ClassVar[Strengths] = (
        {"gain": 0.1, "tau_s": 0.7},
        {"gain": 0.2, "tau_s": 1.0},
        {"gain": 0.3, "tau_s": 1.5},
    )
    separating_from_base: ClassVar[str] = _LONG_HOLDS
    separating: ClassVar[Mapping[str, str]] = {"time_delay": _LONG_HOLDS}

    def transform_output(self, y, signals, p):
        y = np.ascontiguousarray(y, dtype=float)
        t = np.ascontiguousarray(signals.t_s, dtype=float)
        lag = _lagged_columns(y[:, None], t, np.array([float(p[1])]))[:, 0]
        return (1.0 - p[0]) * y + p[0] * lag

    def output_jacobian(self, jac, y, signals, p, rows=None):
        t = np.ascontiguousarray(signals.t_s, dtype=float)
        return (1.0 - p[0]) * jac + p[0] * _lagged_columns(jac, t, np.array([float(p[1])]))

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
            value=0.0,
            lower=0.0,
            upper=0.2,
            unit="1/decade",
            doc="fraction of an output change added per decade of time after it",
        ),
        Parameter(
            "tau0_s",
            value=0.3,
            lower=0.05,
            upper=10.0,
            unit="s",
            doc="time from which the drift is logarithmic",
        ),
    )
    meaning: str = (
        "logarithmic creep: the angle keeps drifting after a move, by the same amount "
        "per decade of time"
    )
    needs: tuple[str, ...] = ("t_s",)
    strengths: ClassVar[Strengths] = (
        {"gamma_per_decade": 0.03, "tau0_s": 0.2},
        {"gamma_per_decade": 0.05, "tau0_s": 0.3},
        {"gamma_per_decade": 0.08, "tau0_s": 0.5},
    )
    separating_from_base: ClassVar[str] = _LONG_HOLDS
    separating: ClassVar[Mapping[str, str]] = {
        "creep": (
            "holds of 30-60 s: first-order creep settles after a few time constants, "
            "logarithmic creep gains the same amount every decade of time"
        ),
        "time_delay": _LONG_HOLDS,
    }

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
        taus = self.taus(float(p[1]))
        lagged = _lagged_columns(y[:, None], t, taus)[:, 0]  # in the order of taus
        n = taus.size
        return y - gam * (n * y - lagged)

    def output_jacobian(self, jac, y, signals, p, rows=None):
        gam = float(p[0]) / LOG_CREEP_PER_DECADE
        if gam == 0.0:
            return jac
        t = np.ascontiguousarray(signals.t_s, dtype=float)
        taus = self.taus(float(p[1]))
        return jac - gam * (taus.size * jac - _lagged_columns(jac, t, taus))

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
            value=0.0,
            lower=0.0,
            upper=1e9,
            unit="counts",
            doc="input magnitude below which the output does not move",
        ),
    )
    meaning: str = (
        "dead zone (Tao-Kokotovic): the tip does not move until the input exceeds a "
        "break point (tendon slack at the start of the pull)"
    )
    strengths: ClassVar[Strengths] = ({"d_counts": 300.0}, {"d_counts": 500.0}, {"d_counts": 800.0})
    separating_from_base: ClassVar[str] = (
        "returns to zero input and small moves near zero: a dead zone holds the angle "
        "only below its break point"
    )
    separating: ClassVar[Mapping[str, str]] = {"multi_stage_backlash": _PARTIAL_UNLOADING}

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
            value=0.0,
            lower=0.0,
            upper=1e9,
            unit="counts",
            doc="input travel after a reversal before the output moves",
        ),
    )
    meaning: str = "backlash (play): after a reversal the input moves, the tip does not"
    strengths: ClassVar[Strengths] = (
        {"width_counts": 200.0},
        {"width_counts": 350.0},
        {"width_counts": 550.0},
    )
    separating_from_base: ClassVar[str] = (
        "no input-angle recording while the model's operator bands are not inverted: a "
        "play of half-width h on the input of a GPI/EGPI with linear envelopes is again "
        "one, its envelope offsets moved by slope x h (a2 - a1 h, a4 + a3 h, a6 + a5 h); "
        "measure the slack itself (motor travel after a reversal before the tendon "
        "tension changes)"
    )
    separating: ClassVar[Mapping[str, str]] = {
        "dead_zone": (
            "a ramp that reverses mid-range and a return to zero: backlash holds the "
            "output after every reversal, a dead zone only near zero input"
        ),
        "multi_stage_backlash": (
            "small reversals at several input levels: backlash holds at every reversal, a "
            "further stage only below its flag point"
        ),
    }

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
            value=1e6,
            lower=0.0,
            upper=1e6,
            unit="deg",
            doc="|angle| above which the output starts to flatten",
        ),
        Parameter(
            "limit_deg",
            value=10.0,
            lower=0.01,
            upper=1e3,
            unit="deg",
            doc="largest |angle| reachable beyond the knee",
        ),
    )
    meaning: str = "the tip runs out of travel: tendon stretch or joint stops near the end"
    strengths: ClassVar[Strengths] = (
        {"knee_deg": 28.0, "limit_deg": 6.0},
        {"knee_deg": 25.0, "limit_deg": 5.0},
        {"knee_deg": 22.0, "limit_deg": 4.0},
    )
    separating_from_base: ClassVar[str] = (
        "slow ramps to the largest safe input: saturation flattens the top"
    )
    separating: ClassVar[Mapping[str, str]] = {
        "rate_dependent_weights": "slow ramps to full scale: saturation flattens the top at any speed"
    }

    def transform_output(self, y, signals, p):
        y = np.asarray(y, dtype=float)
        knee, lim = float(p[0]), float(p[1])
        a = np.abs(y)
        over = np.maximum(a - knee, 0.0)
        sat = np.where(a > knee, knee + lim * np.tanh(over / lim), a)
        return np.sign(y) * sat

    def output_pointwise(self):
        return True

    def output_jacobian(self, jac, y, signals, p, rows=None):
        y = np.asarray(y, dtype=float)
        if rows is not None:
            y = y[np.asarray(rows)]
        knee, lim = float(p[0]), float(p[1])
        a = np.abs(y)
        slope = np.where(a > knee, 1.0 - np.tanh(np.maximum(a - knee, 0.0) / lim) ** 2, 1.0)
        return jac * slope[:, None]

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
        if self.effect.input_side():
            y = self.inner.evaluate(self.effect.transform_input(signals, peff), pin)
        else:
            y = np.asarray(self.inner.evaluate(signals, pin))
            _remember_inner(self.inner, signals, pin, y)
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

    @property
    def jacobian(self):
        """The exact Jacobian (:meth:`exact_jacobian`, called as
        ``jacobian(signals, values, rows=None)``) when the wrapped model has one,
        else None.

        A property, so that the fitter (:func:`~i2ris_calib.fitting.fit.fit_model`,
        which takes a model's ``jacobian`` when its class defines it) falls back to
        finite differences over a base model without an exact Jacobian (e.g. the
        general EGPI, Bouc-Wen).
        """
        return self.exact_jacobian if _analytic_jacobian(self.inner) is not None else None

    def exact_jacobian(
        self,
        signals: Signals,
        values: np.ndarray,
        rows: np.ndarray | None = None,
        cols: np.ndarray | None = None,
    ) -> np.ndarray:
        """d output / d parameters (deg per unit), shape (n, p), or (len(rows),
        len(cols)) with ``rows`` / ``cols`` given.

        The wrapped model's columns are its own exact Jacobian on the transformed
        input, pushed through the output transform
        (:meth:`Effect.output_jacobian`); the effect's columns are central
        differences (an input-side effect re-runs the wrapped model twice per
        parameter, an output-side one only its transform). The wrapped model
        always runs over the whole signal (its state needs the history).

        Parameters
        ----------
        signals : Signals
            Shape (n,) each.
        values : ndarray, shape (p,)
            Parameter vector (wrapped model's, then the effect's).
        rows : ndarray of int, shape (k,), optional
            Sample indices to return (default all n).
        cols : ndarray of int, shape (c,), optional
            Parameter indices to return, in that order (default all p); the
            others are not computed.

        Raises
        ------
        CalibError
            When the wrapped model has no exact Jacobian (:attr:`jacobian` is None).
        """
        values = np.asarray(values, dtype=float)
        m = self.n_inner
        pin, peff = values[:m], values[m:]
        cols = np.arange(values.size) if cols is None else np.asarray(cols, dtype=int)
        sel = None if rows is None else np.asarray(rows)
        k = np.asarray(signals.v).size if sel is None else sel.size
        out = np.empty((k, cols.size), order="F")
        sig_in = self.effect.transform_input(signals, peff)
        y_in = None
        if type(self.effect).transform_output is not Effect.transform_output:
            y_in = _recalled_inner(self.inner, sig_in, pin)
            if y_in is None:
                y_in = np.asarray(self.inner.evaluate(sig_in, pin), dtype=float)
        base = np.flatnonzero(cols < m)
        if base.size:
            out[:, base] = self._inner_columns(sig_in, y_in, signals, values, sel, cols[base])
        for pos in np.flatnonzero(cols >= m):
            out[:, pos] = self._effect_column(signals, values, y_in, int(cols[pos]), sel)
        return out

    def _inner_columns(self, sig_in, y_in, signals, values, sel, cols) -> np.ndarray:
        """The wrapped model's columns ``cols`` (all < n_inner) at the rows ``sel``,
        through the output transform, shape (k, len(cols))."""
        m = self.n_inner
        pin, peff = values[:m], values[m:]
        pointwise = self.effect.output_pointwise()
        rows_in = sel if pointwise else None
        if isinstance(self.inner, EffectModel):
            jac = self.inner.exact_jacobian(sig_in, pin, rows=rows_in, cols=cols)
        else:
            jac_fn = _analytic_jacobian(self.inner)
            if jac_fn is None:
                raise CalibError(f"{self.name}: the wrapped model has no exact Jacobian")
            jac = np.asarray(jac_fn(sig_in, pin, rows=rows_in), dtype=float)
            if not (cols.size == jac.shape[1] and np.array_equal(cols, np.arange(cols.size))):
                jac = jac[:, cols]
        jac = self.effect.output_jacobian(jac, y_in, signals, peff, rows_in)
        return jac if pointwise or sel is None else jac[sel]

    def _effect_column(self, signals, values, y_in, col, sel) -> np.ndarray:
        """Central difference of the output by parameter ``col`` (an effect
        parameter), kept inside its declared bounds, at the rows ``sel``."""
        par = self.parameters[col]
        x = float(values[col])
        h = _FD_STEP * max(1.0, abs(x))
        hi = x + h if x + h <= par.upper else x
        lo = x - h if x - h >= par.lower else x
        if hi == lo:  # bounds narrower than the step: step out of them
            hi, lo = x + h, x - h
        up, down = values.copy(), values.copy()
        up[col], down[col] = hi, lo
        d = (self._output_at(signals, up, y_in) - self._output_at(signals, down, y_in)) / (hi - lo)
        return d if sel is None else d[sel]

    def _output_at(self, signals, values, y_in) -> np.ndarray:
        """Output (deg), shape (n,), at ``values`` differing from the Jacobian's
        point only in effect parameters (an output-side effect reuses ``y_in``)."""
        if self.effect.input_side() or y_in is None:
            return self.evaluate(signals, values)
        return self.effect.transform_output(y_in, signals, values[self.n_inner :])

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


#: The wrapped models' last few outputs under output-side effects, by (id(inner),
#: id(signals), values): a least-squares solver asks for the Jacobian where it has just
#: evaluated the model, and the Jacobian of an output-side effect needs that output.
_INNER_OUTPUTS: dict = {}


def _remember_inner(inner: Model, signals: Signals, pin: np.ndarray, y: np.ndarray) -> None:
    """Keep a copy of ``inner``'s output ``y`` (deg, shape (n,)) at ``pin`` on ``signals``."""
    if len(_INNER_OUTPUTS) >= 4:
        _INNER_OUTPUTS.pop(next(iter(_INNER_OUTPUTS)), None)
    # the entry holds inner and signals themselves, so that their ids are not reused
    _INNER_OUTPUTS[(id(inner), id(signals), pin.tobytes())] = (inner, signals, np.array(y, float))


def _recalled_inner(inner: Model, signals: Signals, pin: np.ndarray) -> np.ndarray | None:
    """The output kept by :func:`_remember_inner` for these objects and values, or None."""
    hit = _INNER_OUTPUTS.get((id(inner), id(signals), pin.tobytes()))
    if hit is None or hit[0] is not inner or hit[1] is not signals:
        return None
    return hit[2]


#: Relative step of the central differences by effect parameters (eps^(1/3)).
_FD_STEP = float(np.finfo(float).eps ** (1.0 / 3.0))


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
