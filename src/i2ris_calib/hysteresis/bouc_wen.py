"""The Bouc-Wen model over the signed input (model kind ``"bouc_wen"``, ours).

A smooth, single-loop hysteresis through zero: the form used for piezoelectric stacks
(Low and Guo 1995; Rakotondrabe 2011) and, more generally, for any element that is
elastic right after a reversal and slides (saturates) after some travel - one
elasto-plastic element with a smooth yield (docs/models.md, "The Bouc-Wen model")::

    theta = theta0 + d v - h
    dh = k hs (dv - b |dv| |z|^(n-1) z - g dv |z|^n),   z = h / hs,
    b = (1 + phi) / 2,  g = (1 - phi) / 2

``d`` is the slope far from a reversal (``h`` saturated at ``+-hs``), ``hs`` the
saturated hysteretic part (half the loop's height, deg), ``k`` how fast ``h`` saturates
(per input unit: after a travel of about ``3 / k`` the branch is on its asymptote),
``phi`` the loop's shape (the slope of ``h`` right after a reversal is ``1 + phi``
times its slope at ``h = 0``: ``phi > 0`` a PI-like branch that is steepest at the
reversal, ``phi < 0`` one that steepens first) and ``n`` the sharpness of the yield
(large ``n``: a sharp corner, an elastic-perfectly-plastic element). The classic
parameters are ``A = k hs``, ``beta = k b / hs^(n-1)``, ``gamma = k g / hs^(n-1)``.

Unlike the play-operator models (GPI, EGPI) a Bouc-Wen element has no wiping-out
memory: minor loops inside the major loop do not close, as measured on piezo stacks.
It is rate independent: ``h`` depends on the path of ``v``, not on time (a hold keeps
it). Between two samples the input is taken as a straight line and the state equation
is solved along it: exactly for ``n = 1`` (the default, held by a fit: piecewise
exponential, with the switch where ``h`` crosses 0), by classical Runge-Kutta in
sub-steps of at most :data:`MAX_STEP` in ``k |dv|`` (1/50 of it near ``h = 0``, where
the rate has a kink) otherwise; either way the output
does not depend on the sampling (to the Runge-Kutta error).
``h`` starts at 0 (relaxed) at the first sample; a recording that starts mid-loop gets
its initial state from the fitter (a pre-history, like every model).

Units (I2RIS): input v in encoder counts, output in deg; ``d`` in deg/count, ``k`` in
1/count, ``hs`` and ``theta0`` in deg, ``phi`` and ``n`` dimensionless.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from i2ris_calib.hysteresis.kernel import motion_direction
from i2ris_calib.hysteresis.models import (
    ParametricModel,
    _input,
    check_settings,
    checked_values,
    guessed_model,
)
from i2ris_calib.hysteresis.start import _line, reversal_distance
from i2ris_calib.model import Parameter, Signals

__all__ = ["BoucWenModel", "MAX_STEP", "bouc_wen_model", "bouc_wen_output", "bouc_wen_starts"]

#: Largest Runge-Kutta sub-step, in units of ``k |dv|`` (the state's relaxation length)
MAX_STEP = 0.05


@njit(cache=True)
def _rate(z, s, phi, nexp):  # pragma: no cover - compiled
    """dz/dx, x = k |v - v_start| along a stretch moving in direction ``s`` (+1/-1)."""
    az = abs(z)
    zn = az**nexp if az > 0.0 else 0.0
    b = 0.5 * (1.0 + phi)
    g = 0.5 * (1.0 - phi)
    sz = 1.0 if z > 0.0 else (-1.0 if z < 0.0 else 0.0)
    return s * (1.0 - (b * s * sz + g) * zn)


@njit(cache=True)
def _exact_step(z, s, x, phi):  # pragma: no cover - compiled
    """``z`` after a travel ``x`` (= k |dv|) in direction ``s``, exponent n = 1, exact.

    ``dz/dx = s - c z`` with ``c = phi`` while ``z`` has the sign opposite to the motion
    (it reaches 0 after ``x* = log(1 + phi |z|) / phi``) and ``c = 1`` from there on."""
    if s * z < 0.0:
        a = abs(z)
        if abs(phi) > 1e-9:
            x0 = math.log1p(phi * a) / phi
        else:
            x0 = a
        if x < x0:
            if abs(phi) > 1e-9:
                return z * math.exp(-phi * x) - s * math.expm1(-phi * x) / phi
            return z + s * x
        x -= x0
        z = 0.0
    return s + (z - s) * math.exp(-x)


@njit(cache=True)
def bouc_wen_state(v, k, phi, nexp):  # pragma: no cover - compiled
    """Normalised Bouc-Wen state ``z = h / hs``, shape (len(v),), starting at 0."""
    out = np.empty(v.size)
    if v.size == 0:
        return out
    # keep the evaluation finite whatever values an unbounded optimiser tries
    k = abs(k)
    phi = min(max(phi, -0.99), 1.0)
    nexp = min(max(nexp, 0.1), 50.0)
    z = 0.0
    out[0] = 0.0
    for i in range(1, v.size):
        dv = v[i] - v[i - 1]
        if dv != 0.0 and nexp == 1.0:
            z = _exact_step(z, 1.0 if dv > 0.0 else -1.0, k * abs(dv), phi)
        elif dv != 0.0:
            s = 1.0 if dv > 0.0 else -1.0
            x = k * abs(dv)
            # sub-steps of MAX_STEP, 1/50 of it near z = 0 (the rate's kink there)
            for _ in range(1000000):
                if x <= 0.0:
                    break
                h = MAX_STEP if abs(z) > 2.0 * MAX_STEP else MAX_STEP / 50.0
                if h > x:
                    h = x
                k1 = _rate(z, s, phi, nexp)
                k2 = _rate(z + 0.5 * h * k1, s, phi, nexp)
                k3 = _rate(z + 0.5 * h * k2, s, phi, nexp)
                k4 = _rate(z + h * k3, s, phi, nexp)
                z += h * (k1 + 2.0 * k2 + 2.0 * k3 + k4) / 6.0
                x -= h
        out[i] = z
    return out


@njit(cache=True)
def bouc_wen_output(v, theta0, d, hs, k, phi, nexp):  # pragma: no cover - compiled
    """Output ``theta0 + d v - hs z`` (deg), shape (len(v),)."""
    z = bouc_wen_state(v, k, phi, nexp)
    return theta0 + d * v - hs * z


@dataclass(frozen=True)
class BoucWenModel(ParametricModel):
    """Bouc-Wen over the signed input (model kind ``"bouc_wen"``), 6 parameters
    (``theta0, d, hs, k, phi, n_bw``; module docstring). ``n`` (the dataclass field) is
    the number of operators of the registry's interface: a Bouc-Wen model has none
    and ignores it."""

    n: int = 30

    def evaluate(self, signals: Signals, values: np.ndarray) -> np.ndarray:
        """Output angle (deg), shape (n_samples,)."""
        val = self.named(values)
        return bouc_wen_output(
            _input(signals), val["theta0"], val["d"], val["hs"], val["k"], val["phi"],
            val["n_bw"],
        )  # fmt: skip

    def guess(
        self, v: np.ndarray, theta_deg: np.ndarray, deadband: float | None = None
    ) -> BoucWenModel:
        """A new model whose values are the data-driven start for (v, theta)
        (:func:`bouc_wen_starts`); fixed parameters keep their values."""
        return guessed_model(self, bouc_wen_starts, v, theta_deg, deadband)


def bouc_wen_model(n: int = 30, **values: float) -> BoucWenModel:
    """A Bouc-Wen model (:class:`BoucWenModel`) with default values, overridden by
    ``values``; ``n`` (operators) is accepted for the registry's interface and unused."""
    check_settings("bouc_wen_model", n)
    params = (
        Parameter("theta0", value=0.0, lower=-500.0, upper=500.0, unit="deg",
                  doc="output at zero input with the hysteretic part h = 0"),
        Parameter("d", value=7.0e-3, lower=-1.0, upper=1.0, unit="deg/count",
                  doc="slope far from a reversal (h saturated)"),
        Parameter("hs", value=1.0, lower=-500.0, upper=500.0, unit="deg",
                  doc="saturated hysteretic part: half the loop's height"),
        Parameter("k", value=1e-3, lower=1e-9, upper=10.0, unit="1/count",
                  doc="saturation rate: h is on its asymptote after a travel of ~3/k"),
        Parameter("phi", value=0.0, lower=-0.9, upper=1.0, unit="1",
                  doc="loop shape (beta-gamma)/(beta+gamma): slope of h at a reversal is "
                  "(1 + phi) x its slope at h = 0"),
        Parameter("n_bw", value=1.0, lower=0.3, upper=8.0, unit="1",
                  doc="Bouc-Wen exponent n: sharpness of the yield (large: a sharp corner)"),
    )  # fmt: skip
    return checked_values("bouc_wen_model", BoucWenModel("bouc_wen", params, n=n), values)


def bouc_wen_fixed(config) -> tuple[str, ...]:
    """Parameters a fit holds by default: the exponent ``n_bw`` at 1 (the classic
    piezo form; integrated exactly, so a fit is fast; free it through the API:
    ``model.with_fixed(free=("n_bw",))``)."""
    return ("n_bw",)


def bouc_wen_starts(
    model: BoucWenModel,
    v: np.ndarray,
    theta: np.ndarray,
    n_starts: int,
    rng: np.random.Generator,
    deadband: float = 0.0,
) -> list[np.ndarray]:
    """``n_starts`` data-driven start vectors (shape (6,) each) for a Bouc-Wen model.

    Far (>= 30 % of the input range) from the last reversal ``h`` is saturated: the
    loading branch is the line ``theta0 + d v - hs``, the unloading one ``theta0 + d v
    + hs``. Straight-line fits on those samples give ``d`` (their mean slope),
    ``theta0`` and ``hs`` (the intercepts' mean and half difference); without such
    samples one line through everything and ``hs`` from the spread about it. ``k``:
    saturation after 1/5 of the input range (``k = 15 / range``), ``phi = 0``,
    ``n = 1``. Further starts: ``k`` scaled by a log-uniform factor in [1/4, 4] and
    ``phi`` drawn in [-0.5, 0.8] (seeded).
    """
    v = np.asarray(v, dtype=float)
    theta = np.asarray(theta, dtype=float)
    ok = np.isfinite(theta)
    span = float(np.ptp(v)) if v.size else 0.0
    base = model.value_dict()
    if ok.sum() < 5 or span <= 0:
        return [model.values.copy() for _ in range(max(1, n_starts))]
    direction = motion_direction(np.ascontiguousarray(v), float(deadband))
    far = reversal_distance(v, direction) > 0.3 * span
    up = _line(v, theta, (direction > 0) & far)
    down = _line(v, theta, (direction < 0) & far)
    if up is not None and down is not None:
        d = 0.5 * (up[0] + down[0])
        theta0 = 0.5 * (up[1] + down[1])
        hs = 0.5 * (down[1] - up[1])
    else:
        line = _line(v, theta, ok) or (0.0, float(np.nanmedian(theta)))
        d, theta0 = line
        hs = float(np.nanstd(theta[ok] - (d * v[ok] + theta0)))
    vals = {"theta0": theta0, "d": d, "hs": hs, "k": 15.0 / span, "phi": 0.0, "n_bw": 1.0}
    starts = [model.vector({k: x for k, x in vals.items() if k in base})]
    for _ in range(max(0, n_starts - 1)):
        f = float(np.exp(rng.uniform(np.log(0.25), np.log(4.0))))
        more = vals | {"k": vals["k"] * f, "phi": float(rng.uniform(-0.5, 0.8))}
        starts.append(model.vector(more))
    return starts
