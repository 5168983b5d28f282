"""GPI and EGPI hysteresis models implementing the :class:`~.model.Model` protocol.

* :class:`GPIModel` - generalized Prandtl-Ishlinskii model with linear envelopes
  (Eq1-3, Eq14-15): ``gamma_l = a1 v + a2``, ``gamma_r = a3 v + a4``.
* :class:`I2RISEGPIModel` - the 11-parameter EGPI fitted to I2RIS (Eq16-23), plus
  the flag point ``v_f`` as a 12th parameter (held fixed unless freed).
* :class:`EGPIModel` - the general N-stage EGPI (Eq4-8) with per-stage linear or
  tanh envelopes, magnitude regulators and flag points (used by ``paper-sim``).

Units (I2RIS): input v in encoder counts, output in deg; thresholds r in deg
(they are subtracted from envelope values, which are in deg); envelope slopes in
deg/count; ``sigma`` in 1/deg; ``lam`` and ``kappa`` dimensionless.

Choices the paper leaves open (documented in docs/models.md):

* operator initial state: ``w[-1] = 0`` clamped into the band at ``v[0]``;
* operator step direction: sign of ``v[k] - v[k-1]`` (Eq1-2 literally; holds keep state);
* ``v'`` for the output switch (Eq8, Eq21): direction of the last change larger than
  ``deadband_counts`` (:func:`~.kernel.motion_direction`); a hold keeps the direction,
  so a pause while loading does not switch to the unloading branch.
* ``n`` = number of uniformly spaced thresholds r_1..r_n; with r_0 = 0 there are
  n + 1 operators (Eq14).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from i2ris_calib.hysteresis.kernel import (
    continuous_egpi_output,
    family_outputs,
    gpi_output,
    i2ris_egpi_output,
    motion_direction,
    select_stage,
)
from i2ris_calib.hysteresis.model import Parameter, Signals

INF = np.inf


def thresholds(r1: float, rn: float, n: int) -> np.ndarray:
    """Thresholds ``[0, r_1, ..., r_n]`` (Eq14), shape (n + 1,), unit of the output."""
    if n < 1:
        raise ValueError("n must be >= 1")
    if n == 1:
        return np.array([0.0, r1])
    return np.concatenate(([0.0], np.linspace(r1, rn, n)))


def density(r: np.ndarray, lam: float, sigma: float) -> np.ndarray:
    """Operator weights ``p(r) = lam * exp(-sigma r)`` (Eq15), same shape as r."""
    return lam * np.exp(-sigma * np.asarray(r, dtype=float))


@dataclass(frozen=True)
class ParametricModel:
    """Common machinery: named parameters, ``with_values``, dict helpers.

    Subclasses implement ``evaluate(signals, values)``.
    """

    name: str
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
        return self.evaluate(as_signals(signals), self.vector(mapping))

    def __call__(self, signals: Signals | np.ndarray) -> np.ndarray:
        """Output at the model's current parameter values."""
        return self.evaluate(as_signals(signals), self.values)

    def evaluate(self, signals: Signals, values: np.ndarray) -> np.ndarray:  # pragma: no cover
        raise NotImplementedError

    def guess(
        self, v: np.ndarray, theta_deg: np.ndarray, deadband: float | None = None
    ) -> ParametricModel:
        """A new model whose values are the data-driven start for (v, theta) (GPI and
        EGPI models: envelope lines from the branches, shape from the angle range, the
        flag point from the unloading branches; docs/fit.md). Other models: unchanged.
        Fixed parameters keep their values (except the ``lam`` scale gauge).
        """
        from i2ris_calib.fitting.initial import initial_values
        from i2ris_calib.fitting.pipeline import _keep_fixed, deadband_for

        v = np.asarray(v, dtype=float)
        if deadband is None:
            from i2ris_calib.fitting.config import FitConfig

            deadband = deadband_for(v, FitConfig())
        x = initial_values(self, v, np.asarray(theta_deg, dtype=float), float(deadband))
        return self.with_values(_keep_fixed(self, x))


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
    new = np.empty(v.size, dtype=bool)
    if v.size == 0:
        return None
    new[0] = True
    np.not_equal(v[1:], v[:-1], out=new[1:])
    n_runs = int(new.sum())
    if n_runs > 0.9 * v.size:
        return None
    return np.ascontiguousarray(v[new]), np.cumsum(new) - 1


def _rate_independent(kernel, v: np.ndarray, *args) -> np.ndarray:
    """``kernel(v, *args)`` evaluated once per run of equal inputs (exact, see
    :func:`_held_runs`)."""
    runs = _held_runs(v)
    if runs is None:
        return kernel(v, *args)
    vc, idx = runs
    return kernel(vc, *args)[idx]


def _P(name, value, lower=-INF, upper=INF, unit="", doc="", fixed=False) -> Parameter:
    return Parameter(name, float(value), float(lower), float(upper), fixed, unit, doc)


# Default values are the "yaw+" paper-like preset (see presets.py); bounds are wide
# physical limits used by bounded fits and start sampling.
_SLOPE = dict(lower=0.0, upper=1.0, unit="deg/count")
_OFFSET = dict(lower=-500.0, upper=500.0, unit="deg")


def _density_params(lam, sigma, r1, rn) -> tuple[Parameter, ...]:
    return (
        _P(
            "lam",
            lam,
            1e-6,
            1e3,
            "1",
            "density scale lambda (Eq15); fixed: redundant with the envelope scale",
            True,
        ),
        _P("sigma", sigma, 0.0, 20.0, "1/deg", "density decay sigma (Eq15)"),
        _P("r1", r1, 0.0, 100.0, "deg", "smallest non-zero threshold r_1 (Eq14)"),
        _P("rn", rn, 0.0, 100.0, "deg", "largest threshold r_n (Eq14)"),
    )


@dataclass(frozen=True)
class GPIModel(ParametricModel):
    """GPI model with linear envelopes (Eq1-3, Eq14-15); 8 parameters.

    ``gamma_l = a1 v + a2`` (loading), ``gamma_r = a3 v + a4`` (unloading),
    ``y = sum_{i=0..n} p(r_i) G_{r_i}[v]``.
    """

    n: int = 30

    def evaluate(self, signals: Signals, values: np.ndarray) -> np.ndarray:
        """Output angle (deg), shape (n_samples,), for values (a1..a4, lam, sigma, r1, rn)."""
        x = np.ascontiguousarray(values, dtype=float)
        if x.size != 8:
            raise ValueError(f"gpi: expected 8 values, got {x.size}")
        return _rate_independent(gpi_output, _input(signals), x, int(self.n))


def gpi_model(n: int = 30, **values: float) -> GPIModel:
    """A GPI model with default (paper-like yaw+) values, overridden by ``values``."""
    params = (
        _P("a1", 7.0e-3, doc="loading envelope slope", **_SLOPE),
        _P("a2", 0.5, doc="loading envelope offset", **_OFFSET),
        _P("a3", 7.0e-3, doc="unloading envelope slope", **_SLOPE),
        _P("a4", -0.5, doc="unloading envelope offset", **_OFFSET),
        *_density_params(0.06, 0.2, 0.3, 3.0),
    )
    return GPIModel("gpi", params, n=n).with_values(values)


@dataclass(frozen=True)
class I2RISEGPIModel(ParametricModel):
    """The EGPI fitted to I2RIS (Eq16-23): 11 parameters + flag point ``v_f``.

    ``F_{r,1}``: loading ``gamma_l - r``, unloading ``gamma_r1 + r``;
    ``F_{r,2}``: loading ``gamma_l - r``, unloading ``gamma_r2 + kappa r``;
    ``gamma_l = a1 v + a2``, ``gamma_r1 = a3 v + a4``, ``gamma_r2 = a5 v + a6``;
    ``y = y1`` while loading or above ``v_f``, ``y = y2`` while unloading at ``v <= v_f``.
    ``v_f`` (counts) is free by default and fitted by a profile search from the
    data-driven start (``fitting.initial.flag_point``); ``with_fixed(fixed=("v_f",))``
    keeps the start. ``lam`` is fixed by default: it is exactly redundant with the
    envelope scale (docs/models.md).
    """

    n: int = 30
    deadband_counts: float = 2.0

    def families(self, v: np.ndarray, values: np.ndarray) -> np.ndarray:
        """Outputs y1, y2 of both operator families, shape (2, n_samples) (Eq18-19)."""
        a1, a2, a3, a4, a5, a6, lam, sigma, r1, rn, kappa = np.asarray(values, dtype=float)[:11]
        r = thresholds(r1, rn, self.n)
        p = density(r, lam, sigma)
        glv = a1 * v + a2
        gl = np.vstack((glv, glv))
        gr = np.vstack((a3 * v + a4, a5 * v + a6))
        return family_outputs(v, gl, gr, np.vstack((r, r)), np.vstack((r, kappa * r)), p)

    def evaluate(self, signals: Signals, values: np.ndarray) -> np.ndarray:
        """Output angle (deg), shape (n_samples,) (Eq21)."""
        x = np.ascontiguousarray(values, dtype=float)
        if x.size != 12:
            raise ValueError(f"egpi: expected 12 values, got {x.size}")
        return _rate_independent(
            i2ris_egpi_output, _input(signals), x, int(self.n), float(self.deadband_counts)
        )


def i2ris_egpi_model(n: int = 30, deadband_counts: float = 2.0, **values: float) -> I2RISEGPIModel:
    """An I2RIS EGPI with default (paper-like yaw+) values, overridden by ``values``."""
    params = (
        _P("a1", 7.0e-3, doc="loading envelope slope gamma_l", **_SLOPE),
        _P("a2", 0.5, doc="loading envelope offset gamma_l", **_OFFSET),
        _P("a3", 7.0e-3, doc="stage-1 unloading envelope slope gamma_r1", **_SLOPE),
        _P("a4", -0.5, doc="stage-1 unloading envelope offset gamma_r1", **_OFFSET),
        _P("a5", 7.0e-3, doc="stage-2 unloading envelope slope gamma_r2", **_SLOPE),
        _P("a6", -0.5, doc="stage-2 unloading envelope offset gamma_r2", **_OFFSET),
        *_density_params(0.06, 0.2, 0.3, 3.0),
        _P("kappa", 3.0, 0.0, 100.0, "1", "stage-2 backlash magnitude regulator (Eq17)"),
        _P(
            "v_f",
            2000.0,
            -1e7,
            1e7,
            "count",
            "flag point: unloading switches to y2 at v <= v_f (fitted by profile search)",
        ),
    )
    model = I2RISEGPIModel("egpi", params, n=n, deadband_counts=deadband_counts)
    return model.with_values(values)


@dataclass(frozen=True)
class ContinuousEGPIModel(I2RISEGPIModel):
    """Continuous I2RIS EGPI (``"egpi_c"``): the parameters of :class:`I2RISEGPIModel`,
    but the stage-2 operators take over the stage-1 state at the flag point.

    One operator family: loading ``gamma_l - r``; unloading ``gamma_r1 + r`` above
    ``v_f`` and ``gamma_r2 + kappa r`` at or below it
    (:func:`~.kernel.continuous_egpi_output`). The paper's EGPI runs both families
    from the start and switches the *output* at v_f, so the angle steps there by
    ``y2 - y1``; a bending angle cannot jump, so here the stage-2 family starts from
    the stage-1 state where the input crosses v_f. The dead zone S3 appears as a
    hold while ``gamma_r2 + kappa r`` lies above the state. No ``v'`` dead band is
    needed: the unloading update only acts on a falling input. ``deadband_counts``
    is kept for the interface and unused.
    """

    def evaluate(self, signals: Signals, values: np.ndarray) -> np.ndarray:
        """Output angle (deg), shape (n_samples,)."""
        x = np.ascontiguousarray(values, dtype=float)
        if x.size != 12:
            raise ValueError(f"egpi_c: expected 12 values, got {x.size}")
        return _rate_independent(continuous_egpi_output, _input(signals), x, int(self.n))


def continuous_egpi_model(
    n: int = 30, deadband_counts: float = 2.0, **values: float
) -> ContinuousEGPIModel:
    """A continuous I2RIS EGPI (:class:`ContinuousEGPIModel`) with default values."""
    base = i2ris_egpi_model(n=n, deadband_counts=deadband_counts)
    model = ContinuousEGPIModel("egpi_c", base.parameters, n=n, deadband_counts=deadband_counts)
    return model.with_values(values)


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
        """Outputs z_1..z_N of all families, shape (N, n_samples) (Eq6-7)."""
        val = dict(zip(self.names, np.asarray(values, dtype=float), strict=True))
        r = thresholds(val["r1"], val["rn"], self.n)
        p = density(r, val["lam"], val["sigma"])
        gl, gr, rl, rr = [], [], [], []
        for s, (el, er) in enumerate(self.envelopes, start=1):
            gl.append(el(v, np.array([val[f"l{s}_{x}"] for x in el.suffixes])))
            gr.append(er(v, np.array([val[f"r{s}_{x}"] for x in er.suffixes])))
            rl.append(val.get(f"kappa_l{s}", 1.0) * r)
            rr.append(val.get(f"kappa_r{s}", 1.0) * r)
        return family_outputs(v, np.vstack(gl), np.vstack(gr), np.vstack(rl), np.vstack(rr), p)

    def evaluate(self, signals: Signals, values: np.ndarray) -> np.ndarray:
        """EGPI output z, shape (n_samples,) (Eq8)."""
        v = _input(signals)
        values = np.asarray(values, dtype=float)
        z = self.families(v, values)
        val = dict(zip(self.names, values, strict=True))
        rise = np.array([val[f"vf_rise{j}"] for j in range(1, self.n_stages)])
        fall = np.array([val[f"vf_fall{j}"] for j in range(1, self.n_stages)])
        return select_stage(z, v, motion_direction(v, float(self.deadband)), rise, fall)


def egpi_model(
    envelopes: Sequence[tuple[str, str]],
    values: Mapping[str, float],
    n: int = 30,
    deadband: float = 0.0,
) -> EGPIModel:
    """General N-stage EGPI from envelope kinds per stage and a complete value dict.

    Parameters
    ----------
    envelopes : sequence of (kind_l, kind_r)
        Envelope kinds (``"linear"`` or ``"tanh"``) of each stage, N >= 1 stages.
    values : mapping
        Every parameter: ``l{s}_*``, ``r{s}_*``, ``kappa_l{s}``/``kappa_r{s}`` for
        s >= 2, ``vf_rise{j}``/``vf_fall{j}`` for j = 1..N-1, ``lam, sigma, r1, rn``.
    """
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
        raise KeyError(f"EGPI values: missing {missing}, unknown {sorted(extra)}")
    params = tuple(_P(x, values[x]) for x in names)
    return EGPIModel("egpi_general", params, envelopes=env, n=n, deadband=deadband)
