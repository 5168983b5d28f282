"""GPI and EGPI hysteresis models implementing the :class:`~.model.Model` protocol.

* :class:`GPIModel` - generalized Prandtl-Ishlinskii model with linear envelopes
  (Eq1-3, Eq14-15): ``gamma_l = a1 v + a2``, ``gamma_r = a3 v + a4``.
* :class:`I2RISEGPIModel` - the 11-parameter EGPI fitted to I2RIS (Eq16-23), plus
  the flag point ``v_f`` as a 12th parameter (free by default, profiled by the fit).
* :class:`ContinuousEGPIModel` - the same parameters without the output step (ours).
* :class:`EGPIModel` - the general N-stage EGPI (Eq4-8) with per-stage linear or
  tanh envelopes, magnitude regulators and flag points (used by ``paper-sim``).

Each model's ``evaluate(signals, values)`` names the parameter vector
(:meth:`ParametricModel.named`) and calls its output function with keyword arguments
(:func:`gpi_output`, :func:`egpi_output`, :func:`continuous_egpi_output`: compiled,
written as the paper's equations with the blocks of :mod:`.kernel`: thresholds,
density, the play-operator loop, ``v'``).

Units (I2RIS): input v in encoder counts, output in deg; thresholds r in deg
(they are subtracted from envelope values, which are in deg); envelope slopes in
deg/count; ``sigma`` in 1/deg; ``lam`` and ``kappa`` dimensionless.

Choices the paper leaves open (documented in docs/models.md):

* operator initial state: ``w[-1] = 0`` clamped into the band at ``v[0]``;
* operator step direction: sign of ``v[k] - v[k-1]`` (Eq1-2 literally; holds keep state);
* ``v'`` for the output switch (Eq8, Eq20): direction of the last change larger than
  ``deadband_counts`` (:func:`~.kernel.motion_direction`); a hold keeps the direction,
  so a pause while loading does not switch to the unloading branch.
* ``n`` = number of uniformly spaced thresholds r_1..r_n; with r_0 = 0 there are
  n + 1 operators (Eq14).
"""

from __future__ import annotations

import difflib
import weakref
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
from numba import njit

from i2ris_calib._validate import (
    as_1d_float,
    as_real,
    check_choice,
    check_signals,
    describe,
    same_length,
)
from i2ris_calib.errors import CalibError
from i2ris_calib.hysteresis.kernel import (
    density,
    motion_direction,
    play_jacobian,
    play_numpy,
    play_operators,
    play_switched,
    run_index,
    select_stage,
    thresholds,
)
from i2ris_calib.hysteresis.start import default_deadband, initial_values, keep_fixed
from i2ris_calib.model import NamedParameters, Parameter, Signals

__all__ = [
    "ContinuousEGPIModel",
    "EGPIModel",
    "Envelope",
    "GPIModel",
    "I2RISEGPIModel",
    "ParametricModel",
    "as_signals",
    "continuous_egpi_model",
    "density",
    "egpi_model",
    "gpi_model",
    "i2ris_egpi_model",
    "thresholds",
]


@dataclass(frozen=True)
class ParametricModel(NamedParameters):
    """Common machinery: named parameters, ``with_values``, dict helpers.

    Subclasses implement ``evaluate(signals, values)``.
    """

    name: str
    parameters: tuple[Parameter, ...]

    def named(self, values: np.ndarray) -> dict[str, float]:
        """``{name: value}`` of a parameter vector (shape (p,), model order)."""
        x = np.asarray(values, dtype=float).ravel()
        if x.size != len(self.parameters):
            raise ValueError(f"{self.name}: expected {len(self.parameters)} values, got {x.size}")
        return dict(zip(self.names, x.tolist(), strict=True))

    def with_values(self, values: np.ndarray | Mapping[str, float]) -> ParametricModel:
        """A new model whose parameter values are ``values`` (vector or name->value)."""
        if isinstance(values, Mapping):
            unknown = set(values) - set(self.names)
            if unknown:
                raise KeyError(f"unknown parameter(s) {sorted(unknown)} for {self.name}")
            new = tuple(
                replace(p, value=float(values[p.name])) if p.name in values else p
                for p in self.parameters
            )
        else:
            vals = np.asarray(values, dtype=float).ravel()
            if vals.size != len(self.parameters):
                raise ValueError(
                    f"{self.name}: expected {len(self.parameters)} values, got {vals.size}"
                )
            new = tuple(
                replace(p, value=float(x)) for p, x in zip(self.parameters, vals, strict=True)
            )
        return replace(self, parameters=new)

    def with_fixed(self, fixed: Sequence[str] = (), free: Sequence[str] = ()) -> ParametricModel:
        """A new model with the named parameters held fixed / freed."""
        unknown = (set(fixed) | set(free)) - set(self.names)
        if unknown:
            raise KeyError(f"unknown parameter(s) {sorted(unknown)} for {self.name}")
        new = tuple(
            replace(p, fixed=True)
            if p.name in fixed
            else replace(p, fixed=False)
            if p.name in free
            else p
            for p in self.parameters
        )
        return replace(self, parameters=new)

    def with_bounds(self, **bounds: tuple[float, float]) -> ParametricModel:
        """A new model with ``name=(lower, upper)`` bounds replaced."""
        new = tuple(
            replace(p, lower=float(bounds[p.name][0]), upper=float(bounds[p.name][1]))
            if p.name in bounds
            else p
            for p in self.parameters
        )
        return replace(self, parameters=new)

    def vector(self, mapping: Mapping[str, float]) -> np.ndarray:
        """Parameter vector from a dict; missing names take the model's current value."""
        unknown = set(mapping) - set(self.names)
        if unknown:
            raise KeyError(f"unknown parameter(s) {sorted(unknown)} for {self.name}")
        return np.array([float(mapping.get(p.name, p.value)) for p in self.parameters])

    def evaluate_dict(
        self, signals: Signals | np.ndarray, mapping: Mapping[str, float]
    ) -> np.ndarray:
        """Output (deg), shape (n,), from a dict of parameter values (see :meth:`vector`)."""
        check_signals(f"{self.name}.evaluate_dict", "signals", signals)
        if not isinstance(mapping, Mapping):
            raise CalibError(
                f"{self.name}.evaluate_dict: mapping is {describe(mapping)}; give a dict "
                "{parameter name: value}"
            )
        check_values(f"{self.name}.evaluate_dict", self, mapping)
        return self.evaluate(as_signals(signals), self.vector(mapping))

    def __call__(self, signals: Signals | np.ndarray) -> np.ndarray:
        """Output at the model's current parameter values."""
        check_signals(f"{self.name} model", "signals", signals)
        return self.evaluate(as_signals(signals), self.values)

    def evaluate(self, signals: Signals, values: np.ndarray) -> np.ndarray:  # pragma: no cover
        raise NotImplementedError

    def guess(
        self, v: np.ndarray, theta_deg: np.ndarray, deadband: float | None = None
    ) -> ParametricModel:
        """A new model whose values are the data-driven start for (v, theta) (GPI and
        EGPI models: envelope lines from the branches, shape from the angle range, the
        flag point from the unloading branches; :mod:`.start`, docs/fit.md). Other
        models: unchanged. Fixed parameters keep their values (except the ``lam``
        scale gauge). ``deadband``: the ``v'`` dead band (input unit), default derived
        from the input as the fit does.
        """
        v, theta, db = guess_arguments(f"{self.name}.guess", v, theta_deg, deadband)
        x = initial_values(self, v, theta, db)
        return self.with_values(keep_fixed(self, x))


def guessed_model(model, starts, v, theta_deg, deadband: float | None):
    """The ``guess`` of a model with a start recipe ``starts`` (the registry's
    ``starts(model, v, theta, n_starts, rng, deadband) -> list of vectors``): a new model
    whose values are the recipe's first start for (v, theta_deg), fixed parameters
    keeping their values; arguments checked by :func:`guess_arguments`."""
    v, theta, db = guess_arguments(f"{model.name}.guess", v, theta_deg, deadband)
    x = starts(model, v, theta, 1, np.random.default_rng(0), db)[0]
    return model.with_values(keep_fixed(model, x))


def guess_arguments(
    func: str, v: np.ndarray, theta_deg: np.ndarray, deadband: float | None
) -> tuple[np.ndarray, np.ndarray, float]:
    """The checked arguments of a model's ``guess``: (v, theta_deg, dead band), the
    input and angle as float arrays of one length (NaN angles allowed: unmeasured),
    the ``v'`` dead band derived from the input when None."""
    v = as_1d_float(func, "v", v, min_size=2)
    theta = as_1d_float(
        func, "theta_deg", theta_deg, nan_ok=True,
        hint="mark an unmeasured angle with NaN, never inf",
    )  # fmt: skip
    same_length(func, v=v, theta_deg=theta)
    deadband = as_real(func, "deadband", deadband, none_ok=True, lo=0.0)
    return v, theta, default_deadband(v) if deadband is None else float(deadband)


def check_settings(func: str, n: object, deadband_counts: object = None) -> None:
    """CalibError unless ``n`` is an integer >= 1 and ``deadband_counts`` (when given)
    a finite number >= 0 (the arguments of the model factories)."""
    as_real(func, "n", n, integer=True, lo=1)
    if deadband_counts is not None:
        as_real(func, "deadband_counts", deadband_counts, lo=0.0)


def check_values(func: str, model: NamedParameters, values: Mapping[str, object]) -> None:
    """CalibError unless every key of ``values`` is a parameter of ``model`` (the closest
    name suggested) and every value a finite number."""
    names = model.names
    for key, x in values.items():
        if key not in names:
            close = difflib.get_close_matches(str(key), names, n=1)
            hint = f"did you mean '{close[0]}'?" if close else f"valid: {', '.join(names)}"
            raise CalibError(f"{func}: unknown parameter {key!r} for model '{model.name}' ({hint})")
        as_real(func, str(key), x)


def checked_values(func: str, model: ParametricModel, values: Mapping[str, object]):
    """``model.with_values(values)`` after :func:`check_values`."""
    check_values(func, model, values)
    return model.with_values(values)


def as_signals(signals: Signals | np.ndarray) -> Signals:
    """Wrap a bare input array as :class:`Signals`."""
    return signals if isinstance(signals, Signals) else Signals(v=np.asarray(signals, dtype=float))


def _input(signals: Signals | np.ndarray) -> np.ndarray:
    v = np.ascontiguousarray(signals.v if isinstance(signals, Signals) else signals, dtype=float)
    if v.ndim != 1:
        raise ValueError("signals.v must be 1-D")
    return v


def _held_runs(v: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """(input without repeated samples, run index of every sample), or None when less
    than 10 % of the samples repeat the previous one.

    Rate-independent models (GPI, EGPI: a hold keeps every operator state and the
    motion direction) give the same output on every sample of a hold, so they are
    evaluated once per run of equal inputs. A direction dataset's input rests at 0
    while the motor is on the other side of zero: about half of a recording.
    """
    # a read-only array owning its data (the fitter's copy of the input) cannot change:
    # its runs are kept (a fit evaluates the model thousands of times on one input)
    frozen = not v.flags.writeable and v.base is None
    if frozen:
        for key, runs in _RUNS_CACHE:
            if key() is v:
                return runs
    runs = _find_runs(v)
    if frozen:
        _RUNS_CACHE.insert(0, (weakref.ref(v), runs))
        del _RUNS_CACHE[2:]
    return runs


#: (weak reference to the input, its runs) of the last two read-only inputs seen by
#: :func:`_held_runs` (a fit uses one; the input itself is not kept alive).
_RUNS_CACHE: list = []


def _find_runs(v: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """:func:`_held_runs` without the cache (one compiled pass,
    :func:`~.kernel.run_index`)."""
    if v.size == 0:
        return None
    vals, idx = run_index(np.ascontiguousarray(v, dtype=float))
    if vals.size > 0.9 * v.size:
        return None
    return vals, idx


def _per_run(output, v: np.ndarray, **params) -> np.ndarray:
    """``output(v, **params)`` evaluated once per run of equal inputs (exact for a
    rate-independent model, see :func:`_held_runs`)."""
    runs = _held_runs(v)
    if runs is None:
        return output(v, **params)
    vc, idx = runs
    return output(vc, **params)[idx]


def _jac_blocks(r1, rn, lam, sigma, n):
    """(r, p, dp/dr, dr/dr1, dr/drn), shape (n + 1,) each, for :func:`~.kernel.play_jacobian`."""
    r = thresholds(r1, rn, n)
    p = density(r, lam, sigma)
    i = np.arange(n + 1, dtype=float)
    if n > 1:
        dr_drn = np.where(i >= 1, (i - 1) / (n - 1), 0.0)
        dr_dr1 = np.where(i >= 1, 1.0 - dr_drn, 0.0)
    else:
        dr_dr1, dr_drn = (i >= 1).astype(float), np.zeros(n + 1)
    return r, p, -sigma * p, dr_dr1, dr_drn


def _jacobian(model, signals, values, columns, rows):
    """d output / d parameters, shape (n_samples, p) or (len(rows), p), of a
    linear-envelope model: ``columns(v, n, **named values)`` on the input without
    held samples (shape (n_runs, p)), spread back to the samples ``rows``."""
    v = _input(signals)
    runs = _held_runs(v)
    vc, idx = (v, None) if runs is None else runs
    jac = columns(vc, model.n, **model.named(values))
    if rows is None:
        return jac if idx is None else jac[idx]
    rows = np.asarray(rows)
    return jac[rows] if idx is None else jac[idx[rows]]


#: play_jacobian's quantities (kernel.JAC_QUANTITIES) -> GPI / EGPI parameter columns
_GPI_COLS = np.array([0, 1, 2, 3, -1, -1, 6, 7, -1, 5, 4])
_EGPI_COLS = np.array([0, 1, 2, 3, 4, 5, 8, 9, 10, 7, 6])


def _gpi_columns(v, n, a1, a2, a3, a4, lam, sigma, r1, rn):
    r, p, dp, d1, dn = _jac_blocks(r1, rn, lam, sigma, n)
    jac = np.zeros((v.size, 8))
    play_jacobian(v, a1, a2, a3, a4, 0.0, 0.0, r, 1.0, 0.0, 0, p, dp, d1, dn, lam, _GPI_COLS, jac)
    return jac


# ------------------------------------------------------------- the equations, compiled
# Each model's evaluate names its parameter vector and calls one of these with keyword
# arguments; they are compiled (numba) so the envelopes, both families and the output
# switch run without Python overhead (a fit evaluates a model thousands of times).


@njit(cache=True)
def gpi_output(v, a1, a2, a3, a4, lam, sigma, r1, rn, n):  # pragma: no cover - compiled
    """GPI output y (deg), shape (len(v),), for input ``v`` (counts); ``n`` thresholds."""
    r = thresholds(r1, rn, n)  # Eq14: r_0 = 0, r_1..r_n uniform
    p = density(r, lam, sigma)  # Eq15: p(r_i) = lam exp(-sigma r_i)
    # Eq1-3: y = sum_i p(r_i) G_{r_i}[v]; G on gamma_l - r while v rises and on
    # gamma_r + r while v falls, gamma_l = a1 v + a2, gamma_r = a3 v + a4 (the form of Eq21-22)
    return play_operators(v, a_l=a1, b_l=a2, r_l=r, a_r=a3, b_r=a4, r_r=r, p=p)


@njit(cache=True)
def egpi_families(
    v, a1, a2, a3, a4, a5, a6, lam, sigma, r1, rn, kappa, n, deadband
):  # pragma: no cover
    """The I2RIS EGPI's two family outputs y1, y2, shape (2, len(v)) (Eq16-19, Eq21-23),
    and the motion direction ``v'``, int8 (len(v),) (:func:`~.kernel.motion_direction`)."""
    r = thresholds(r1, rn, n)  # Eq14
    p = density(r, lam, sigma)  # Eq15
    y = np.empty((2, v.size))  # y1, y2 (one buffer: fewer fresh memory pages)
    # Eq16, Eq18: F_{r,1} on gamma_l = a1 v + a2 (Eq21), gamma_r1 = a3 v + a4 (Eq22); y1
    play_operators(v, a_l=a1, b_l=a2, r_l=r, a_r=a3, b_r=a4, r_r=r, p=p, out=y[0])
    # Eq17, Eq19: F_{r,2} on gamma_l, gamma_r2 = a5 v + a6 (Eq23) with kappa r; y2
    play_operators(v, a_l=a1, b_l=a2, r_l=r, a_r=a5, b_r=a6, r_r=kappa * r, p=p, out=y[1])
    return y, motion_direction(v, deadband)  # v' (a hold keeps the direction)


@njit(cache=True)
def egpi_output(
    v, a1, a2, a3, a4, a5, a6, lam, sigma, r1, rn, kappa, v_f, n, deadband
):  # pragma: no cover
    """The paper's I2RIS EGPI output y (deg), shape (len(v),) (Eq14-23); ``deadband``:
    the ``v'`` dead band (counts, :func:`~.kernel.motion_direction`)."""
    y, direction = egpi_families(v, a1, a2, a3, a4, a5, a6, lam, sigma, r1, rn, kappa, n, deadband)
    # Eq20: y1 while loading (v' > 0) or above v_f, y2 while unloading (v' <= 0) at v <= v_f
    return np.where((direction < 0) & (v <= v_f), y[1], y[0])


@njit(cache=True)
def continuous_egpi_output(
    v, a1, a2, a3, a4, a5, a6, lam, sigma, r1, rn, kappa, v_f, n
):  # pragma: no cover
    """Continuous EGPI output y (deg), shape (len(v),) (docs/models.md): one family,
    loading as Eq16-17, unloading as F_{r,1} (Eq16) above v_f and as F_{r,2} (Eq17) at
    or below it, from the state the operators have there; envelopes Eq21-23."""
    r = thresholds(r1, rn, n)  # Eq14
    p = density(r, lam, sigma)  # Eq15
    return play_switched(
        v, a_l=a1, b_l=a2, a_r1=a3, b_r1=a4, a_r2=a5, b_r2=a6, r=r, kappa=kappa, v_f=v_f, p=p
    )


# Default values are the "yaw+" paper-like preset (see presets.py); bounds are wide
# physical limits used by bounded fits and start sampling.
_SLOPE = dict(lower=0.0, upper=1.0, unit="deg/count")
_OFFSET = dict(lower=-500.0, upper=500.0, unit="deg")


def _density_params(lam, sigma, r1, rn) -> tuple[Parameter, ...]:
    return (
        Parameter(
            "lam", value=lam, lower=1e-6, upper=1e3, fixed=True, unit="1",
            doc="density scale lambda (Eq15); fixed: redundant with the envelope scale",
        ),
        Parameter("sigma", value=sigma, lower=0.0, upper=20.0, unit="1/deg",
                  doc="density decay sigma (Eq15)"),
        Parameter("r1", value=r1, lower=0.0, upper=100.0, unit="deg",
                  doc="smallest non-zero threshold r_1 (Eq14)"),
        Parameter("rn", value=rn, lower=0.0, upper=100.0, unit="deg",
                  doc="largest threshold r_n (Eq14)"),
    )  # fmt: skip


@dataclass(frozen=True)
class GPIModel(ParametricModel):
    """GPI model with linear envelopes (Eq1-3, Eq14-15); 8 parameters.

    ``gamma_l = a1 v + a2`` (loading), ``gamma_r = a3 v + a4`` (unloading),
    ``y = sum_{i=0..n} p(r_i) G_{r_i}[v]``.
    """

    n: int = 30

    def evaluate(self, signals: Signals, values: np.ndarray) -> np.ndarray:
        """Output angle (deg), shape (n_samples,), for values (a1..a4, lam, sigma, r1, rn)."""
        return _per_run(gpi_output, _input(signals), n=self.n, **self.named(values))

    def jacobian(
        self, signals: Signals, values: np.ndarray, rows: np.ndarray | None = None
    ) -> np.ndarray:
        """d output / d parameters (deg per unit), shape (n_samples, p), exact (the
        output is piecewise linear in the envelopes and thresholds); ``rows``: sample
        indices, shape (k,), to return only those rows."""
        return _jacobian(self, signals, values, _gpi_columns, rows)


def gpi_model(n: int = 30, **values: float) -> GPIModel:
    """A GPI model with default (paper-like yaw+) values, overridden by ``values``."""
    check_settings("gpi_model", n)
    params = (
        Parameter("a1", value=7.0e-3, doc="loading envelope slope", **_SLOPE),
        Parameter("a2", value=0.5, doc="loading envelope offset", **_OFFSET),
        Parameter("a3", value=7.0e-3, doc="unloading envelope slope", **_SLOPE),
        Parameter("a4", value=-0.5, doc="unloading envelope offset", **_OFFSET),
        *_density_params(0.06, 0.2, 0.3, 3.0),
    )
    return checked_values("gpi_model", GPIModel("gpi", params, n=n), values)


@dataclass(frozen=True)
class I2RISEGPIModel(ParametricModel):
    """The EGPI fitted to I2RIS (Eq16-23): 11 parameters + flag point ``v_f``.

    ``F_{r,1}``: loading ``gamma_l - r``, unloading ``gamma_r1 + r`` (Eq16);
    ``F_{r,2}``: loading ``gamma_l - r``, unloading ``gamma_r2 + kappa r`` (Eq17);
    ``y1``, ``y2`` their weighted sums (Eq18-19);
    ``y = y1`` while loading or above ``v_f``, ``y = y2`` while unloading at ``v <= v_f``
    (Eq20); ``gamma_l = a1 v + a2``, ``gamma_r1 = a3 v + a4``, ``gamma_r2 = a5 v + a6``
    (Eq21-23). ``v_f`` (counts) is free by default and fitted by a profile search from
    the data-driven start (:func:`.start.flag_point`); ``with_fixed(fixed=("v_f",))``
    keeps the start. ``lam`` is fixed by default: it is exactly redundant with the
    envelope scale (docs/models.md).
    """

    n: int = 30
    deadband_counts: float = 2.0

    def evaluate(self, signals: Signals, values: np.ndarray) -> np.ndarray:
        """Output angle (deg), shape (n_samples,), for values (a1..a6, lam, sigma, r1,
        rn, kappa, v_f)."""
        return _per_run(
            egpi_output,
            _input(signals),
            n=self.n,
            deadband=float(self.deadband_counts),
            **self.named(values),
        )

    def jacobian(
        self, signals: Signals, values: np.ndarray, rows: np.ndarray | None = None
    ) -> np.ndarray:
        """d output / d parameters (deg per unit), shape (n_samples, p), exact (the
        output is piecewise linear in the envelopes and thresholds); 0 for ``v_f``
        (the output steps in it: profiled); ``rows``: sample indices, shape (k,), to
        return only those rows."""
        db = float(self.deadband_counts)

        def columns(v, n, a1, a2, a3, a4, a5, a6, lam, sigma, r1, rn, kappa, v_f):
            r, p, dp, d1, dn = _jac_blocks(r1, rn, lam, sigma, n)
            args = (a1, a2, a3, a4, a5, a6, r, kappa, v_f)
            j1, j2 = np.zeros((v.size, 12)), np.zeros((v.size, 12))
            play_jacobian(v, *args, 0, p, dp, d1, dn, lam, _EGPI_COLS, j1)
            play_jacobian(v, *args, 1, p, dp, d1, dn, lam, _EGPI_COLS, j2)
            sel = (motion_direction(v, db) < 0) & (v <= v_f)  # Eq20
            j1[sel] = j2[sel]
            return j1

        return _jacobian(self, signals, values, columns, rows)

    def flag_point_families(
        self, signals: Signals, values: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(y1, y2, unloading), shape (n_samples,) each: the output for ANY flag point
        ``v_f`` is ``where(unloading & (v <= v_f), y2, y1)`` (Eq20), equal to
        :meth:`evaluate` with that ``v_f`` to the last bit (the fitter's flag-point
        profile: one model run for every candidate v_f)."""
        v = _input(signals)
        val = self.named(values)
        del val["v_f"]
        runs = _held_runs(v)
        vc, idx = (v, None) if runs is None else runs
        y, direction = egpi_families(vc, n=self.n, deadband=float(self.deadband_counts), **val)
        y1, y2, unloading = y[0], y[1], direction < 0
        if idx is None:
            return y1, y2, unloading
        return y1[idx], y2[idx], unloading[idx]


def i2ris_egpi_model(n: int = 30, deadband_counts: float = 2.0, **values: float) -> I2RISEGPIModel:
    """An I2RIS EGPI with default (paper-like yaw+) values, overridden by ``values``."""
    check_settings("i2ris_egpi_model", n, deadband_counts)
    params = (
        Parameter("a1", value=7.0e-3, doc="loading envelope slope gamma_l", **_SLOPE),
        Parameter("a2", value=0.5, doc="loading envelope offset gamma_l", **_OFFSET),
        Parameter("a3", value=7.0e-3, doc="stage-1 unloading envelope slope gamma_r1", **_SLOPE),
        Parameter("a4", value=-0.5, doc="stage-1 unloading envelope offset gamma_r1", **_OFFSET),
        Parameter("a5", value=7.0e-3, doc="stage-2 unloading envelope slope gamma_r2", **_SLOPE),
        Parameter("a6", value=-0.5, doc="stage-2 unloading envelope offset gamma_r2", **_OFFSET),
        *_density_params(0.06, 0.2, 0.3, 3.0),
        Parameter(
            "kappa", value=3.0, lower=0.0, upper=100.0, unit="1",
            doc="stage-2 backlash magnitude regulator (Eq17)",
        ),
        Parameter(
            "v_f", value=2000.0, lower=-1e7, upper=1e7, unit="count",
            doc="flag point: unloading switches to y2 at v <= v_f (fitted by profile search)",
        ),
    )  # fmt: skip
    model = I2RISEGPIModel("egpi", params, n=n, deadband_counts=deadband_counts)
    return checked_values("i2ris_egpi_model", model, values)


@dataclass(frozen=True)
class ContinuousEGPIModel(I2RISEGPIModel):
    """Continuous I2RIS EGPI (``"egpi_c"``): the parameters of :class:`I2RISEGPIModel`,
    but the stage-2 operators take over the stage-1 state at the flag point.

    One operator family: loading ``gamma_l - r``; unloading ``gamma_r1 + r`` above
    ``v_f`` and ``gamma_r2 + kappa r`` at or below it. The paper's EGPI runs both
    families from the start and switches the *output* at v_f, so the angle steps there
    by ``y2 - y1``; a bending angle cannot jump, so here the stage-2 family starts from
    the stage-1 state where the input crosses v_f. The dead zone S3 appears as a hold
    while ``gamma_r2 + kappa r`` lies above the state. No ``v'`` dead band is needed:
    the unloading update only acts on a falling input. ``deadband_counts`` is kept for
    the interface and unused.

    The output is continuous in ``v_f`` (a step that crosses it meets the stage-1
    boundary at ``v_f`` itself), so the fitter moves ``v_f`` with the other parameters
    (a finite-difference column, :data:`CONTINUOUS_FLAG_POINT`) besides profiling it.
    """

    #: The output is continuous (piecewise smooth) in the flag point ``v_f``.
    CONTINUOUS_FLAG_POINT = True

    def evaluate(self, signals: Signals, values: np.ndarray) -> np.ndarray:
        """Output angle (deg), shape (n_samples,)."""
        return _per_run(continuous_egpi_output, _input(signals), n=self.n, **self.named(values))

    def jacobian(
        self, signals: Signals, values: np.ndarray, rows: np.ndarray | None = None
    ) -> np.ndarray:
        """d output / d parameters, shape (n_samples, p) (or (len(rows), p)), exact;
        0 for ``v_f``."""

        def columns(v, n, a1, a2, a3, a4, a5, a6, lam, sigma, r1, rn, kappa, v_f):
            r, p, dp, d1, dn = _jac_blocks(r1, rn, lam, sigma, n)
            jac = np.zeros((v.size, 12))
            args = (a1, a2, a3, a4, a5, a6, r, kappa, v_f)
            play_jacobian(v, *args, 2, p, dp, d1, dn, lam, _EGPI_COLS, jac)
            return jac

        return _jacobian(self, signals, values, columns, rows)


def continuous_egpi_model(
    n: int = 30, deadband_counts: float = 2.0, **values: float
) -> ContinuousEGPIModel:
    """A continuous I2RIS EGPI (:class:`ContinuousEGPIModel`) with default values."""
    check_settings("continuous_egpi_model", n, deadband_counts)
    base = i2ris_egpi_model(n=n, deadband_counts=deadband_counts)
    model = ContinuousEGPIModel("egpi_c", base.parameters, n=n, deadband_counts=deadband_counts)
    return checked_values("continuous_egpi_model", model, values)


# --------------------------------------------------------------------------- general EGPI


@dataclass(frozen=True)
class Envelope:
    """A monotone envelope family: ``"linear"`` (slope v + offset) or ``"tanh"``
    (amp tanh(gain v + shift) + offset). Parameter names are the suffixes below."""

    kind: str = "linear"

    @property
    def suffixes(self) -> tuple[str, ...]:
        """Names of this envelope's parameters (without the stage prefix)."""
        if self.kind == "linear":
            return ("slope", "offset")
        if self.kind == "tanh":
            return ("amp", "gain", "shift", "offset")
        raise ValueError(f"unknown envelope kind {self.kind!r} (use 'linear' or 'tanh')")

    def __call__(self, v: np.ndarray, coef: np.ndarray) -> np.ndarray:
        """Envelope values at v, shape of v."""
        if self.kind == "linear":
            return coef[0] * v + coef[1]
        return coef[0] * np.tanh(coef[1] * v + coef[2]) + coef[3]


@dataclass(frozen=True)
class EGPIModel(ParametricModel):
    """General N-stage EGPI (Eq4-8).

    Stage s (1-based) has ascending envelope ``l{s}_*`` and descending ``r{s}_*``
    (kinds in ``envelopes``), magnitude regulators ``kappa_l{s}``, ``kappa_r{s}``
    (stage 1 has none: they are 1), and stages are switched at flag points
    ``vf_rise{j}`` (loading: stage = number of rising flags <= v) and
    ``vf_fall{j}`` (unloading: stage = number of falling flags >= v), j = 1..N-1.
    Shared density ``lam, sigma, r1, rn``.
    """

    envelopes: tuple[tuple[Envelope, Envelope], ...] = ()
    n: int = 30
    deadband: float = 0.0

    @property
    def n_stages(self) -> int:
        """Number of stages (operator families)."""
        return len(self.envelopes)

    def families(self, v: np.ndarray, values: np.ndarray) -> np.ndarray:
        """Outputs z_1..z_N of all families, shape (N, n_samples) (Eq4-7)."""
        v = _input(v)
        val = self.named(values)
        r = thresholds(val["r1"], val["rn"], self.n)  # Eq14
        p = density(r, val["lam"], val["sigma"])  # Eq15
        z = np.empty((self.n_stages, v.size))
        for s, (el, er) in enumerate(self.envelopes, start=1):
            gamma_l = el(v, np.array([val[f"l{s}_{x}"] for x in el.suffixes]))
            gamma_r = er(v, np.array([val[f"r{s}_{x}"] for x in er.suffixes]))
            kappa_l, kappa_r = val.get(f"kappa_l{s}", 1.0), val.get(f"kappa_r{s}", 1.0)
            # Eq4-7: H_{r,s} on gamma_l,s - kappa_l r (v rises), gamma_r,s + kappa_r r (v falls)
            z[s - 1] = play_numpy(v, gamma_l, kappa_l * r, gamma_r, kappa_r * r, p)
        return z

    def evaluate(self, signals: Signals, values: np.ndarray) -> np.ndarray:
        """EGPI output z, shape (n_samples,) (Eq8)."""
        v = _input(signals)
        z = self.families(v, values)
        val = self.named(values)
        rise = np.array([val[f"vf_rise{j}"] for j in range(1, self.n_stages)])
        fall = np.array([val[f"vf_fall{j}"] for j in range(1, self.n_stages)])
        return select_stage(z, v, motion_direction(v, float(self.deadband)), rise, fall)


def egpi_model(
    envelopes: Sequence[tuple[str, str]] | None = None,
    values: Mapping[str, float] | None = None,
    n: int = 30,
    deadband: float = 0.0,
) -> EGPIModel:
    """General N-stage EGPI from envelope kinds per stage and a complete value dict.

    For the paper's I2RIS EGPI (Eq16-23) call :func:`i2ris_egpi_model`; the continuous
    EGPI is :func:`continuous_egpi_model`, the GPI :func:`gpi_model`. This factory is
    for a model of your own stages.

    Parameters
    ----------
    envelopes : sequence of (kind_l, kind_r)
        Envelope kinds (``"linear"`` or ``"tanh"``) of each stage, N >= 1 stages.
    values : mapping
        Every parameter: ``l{s}_*``, ``r{s}_*``, ``kappa_l{s}``/``kappa_r{s}`` for
        s >= 2, ``vf_rise{j}``/``vf_fall{j}`` for j = 1..N-1, ``lam, sigma, r1, rn``.
    """
    func = "egpi_model"
    if envelopes is None or values is None:
        missing = " and ".join(
            k for k, x in (("envelopes", envelopes), ("values", values)) if x is None
        )
        raise CalibError(
            f"{func}: {missing} not given; this is the general N-stage EGPI (your own "
            "stages: envelopes and every parameter's value). For the paper's I2RIS EGPI "
            "call i2ris_egpi_model() (continuous_egpi_model() for the continuous EGPI, "
            "gpi_model() for the GPI)"
        )
    if isinstance(envelopes, str) or not isinstance(envelopes, Sequence) or not envelopes:
        raise CalibError(
            f"{func}: envelopes is {describe(envelopes)}; give one (kind_l, kind_r) pair per "
            "stage, e.g. [('linear', 'linear'), ('linear', 'tanh')]"
        )
    for s, pair in enumerate(envelopes, start=1):
        if isinstance(pair, str) or not isinstance(pair, Sequence) or len(pair) != 2:
            raise CalibError(
                f"{func}: envelopes[{s - 1}] is {describe(pair)}; give a (kind_l, kind_r) "
                "pair, e.g. ('linear', 'tanh')"
            )
        for side, kind in zip("lr", pair, strict=True):
            check_choice(func, f"envelopes[{s - 1}] kind_{side}", kind, ("linear", "tanh"))
    if not isinstance(values, Mapping):
        raise CalibError(
            f"{func}: values is {describe(values)}; give a dict {{parameter name: value}}"
        )
    as_real(func, "n", n, integer=True, lo=1)
    as_real(func, "deadband", deadband, lo=0.0)
    env = tuple((Envelope(a), Envelope(b)) for a, b in envelopes)
    names: list[str] = []
    for s, (el, er) in enumerate(env, start=1):
        names += [f"l{s}_{x}" for x in el.suffixes] + [f"r{s}_{x}" for x in er.suffixes]
        if s >= 2:
            names += [f"kappa_l{s}", f"kappa_r{s}"]
    names += [f"vf_rise{j}" for j in range(1, len(env))]
    names += [f"vf_fall{j}" for j in range(1, len(env))]
    names += ["lam", "sigma", "r1", "rn"]
    missing = [x for x in names if x not in values]
    extra = set(values) - set(names)
    if missing or extra:
        raise CalibError(
            f"{func}: values missing {missing}, unknown {sorted(extra)}; give every "
            f"parameter of these stages: {', '.join(names)}"
        )
    for x in names:
        as_real(func, f"values[{x!r}]", values[x])
    params = tuple(Parameter(x, value=float(values[x])) for x in names)
    return EGPIModel("egpi_general", params, envelopes=env, n=n, deadband=deadband)
