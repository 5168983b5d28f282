"""The Prandtl-Ishlinskii / Maxwell-slip model over the signed input (kind ``"maxwell_slip"``, ours).

A bank of elasto-slip elements (Goldfarb and Celanovic 1997, the "Maxwell resistive
capacitor" model of a piezo stack; the Maxwell-slip model of friction): element ``j``
is a spring that slips once its deflection reaches ``r_j``, so it adds a play operator
of threshold ``r_j`` to the output (docs/models.md, "The Prandtl-Ishlinskii model")::

    theta = theta0 + sum_{j=0..n} w_j P_{r_j}[v],   r_j = j r_max / n

``P_r`` is the play operator on the signed input (``P_r[v]`` rises as ``v - r``, falls as
``v + r``, holds in between; ``P_0[v] = v``); ``w_j`` (deg per input unit) are free, one
per threshold: the density of slip thresholds is whatever the data say (GPI ties it to
``lam exp(-sigma r)``). An element's stiffness ``w_j`` (j >= 1) is bounded below by 0
(a free sign lets a fit cancel rarely excited operators against each other, which
generalises badly); the linear part ``w0`` has either sign. ``r_max`` (input unit) is
the largest threshold, set by the start recipe to 0.45 of the input's range and held (a
grid, not a fitted value), so the output is linear in every fitted parameter: the
start is the bounded least-squares optimum, and the Jacobian is exact (the operator
outputs). The registry row fits it by the bounded ``trf`` method.

Like every play-operator model it has wiping-out memory and closed, congruent minor
loops; it has no output jump (every operator is continuous in the input) and is rate
independent (a hold keeps every operator). Initial state: every operator relaxed at
0 and clamped into its band at the first sample (the kernel's rule); a recording that
starts mid-loop gets a pre-history from the fitter, as every model.

Units (I2RIS): input v in encoder counts, output in deg; ``w_j`` in deg/count,
``r_max`` in counts, ``theta0`` in deg.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.optimize import lsq_linear

from i2ris_calib.hysteresis.models import (
    ParametricModel,
    _input,
    check_settings,
    checked_values,
    guessed_model,
)
from i2ris_calib.hysteresis.start import _line
from i2ris_calib.model import Parameter, Signals

__all__ = ["SlipModel", "slip_fixed", "slip_model", "slip_operators", "slip_starts"]


@njit(cache=True)
def slip_operators(v, r, rows_out, drdr):  # pragma: no cover - compiled
    """Play-operator outputs ``P_{r_j}[v]`` at every sample, shape (n_samples, m), and
    (when ``drdr`` has m entries) their derivative with respect to ``r_max``, shape
    (n_samples,) summed with weights ``drdr`` (``dr_j/dr_max * w_j``) into
    ``rows_out[:, m]``. ``rows_out``: shape (n_samples, m + 1), written in place."""
    m = r.size
    ns = v.size
    w = np.empty(m)
    sgn = np.zeros(m)  # d w_j / d r_j: -1 on the loading boundary, +1 unloading, 0 initial
    for j in range(m):
        lo, hi = v[0] - r[j], v[0] + r[j]
        if 0.0 < lo:
            w[j], sgn[j] = lo, -1.0
        elif 0.0 > hi:
            w[j], sgn[j] = hi, 1.0
        else:
            w[j], sgn[j] = 0.0, 0.0
    use_d = drdr.size == m
    for k in range(ns):
        if k > 0:
            if v[k] > v[k - 1]:
                for j in range(m):
                    g = v[k] - r[j]
                    if g > w[j]:
                        w[j], sgn[j] = g, -1.0
            elif v[k] < v[k - 1]:
                for j in range(m):
                    g = v[k] + r[j]
                    if g < w[j]:
                        w[j], sgn[j] = g, 1.0
        acc = 0.0
        for j in range(m):
            rows_out[k, j] = w[j]
            if use_d:
                acc += drdr[j] * sgn[j]
        if use_d:
            rows_out[k, m] = acc
    return rows_out


@njit(cache=True, fastmath=True)
def slip_output(v, theta0, r, weights):  # pragma: no cover - compiled
    """``theta0 + sum_j w_j P_{r_j}[v]`` (deg), shape (len(v),)."""
    m = r.size
    ns = v.size
    out = np.empty(ns)
    if ns == 0:
        return out
    w = np.empty(m)
    acc = theta0
    for j in range(m):
        w[j] = min(max(0.0, v[0] - r[j]), v[0] + r[j])
        acc += weights[j] * w[j]
    out[0] = acc
    for k in range(1, ns):
        if v[k] > v[k - 1]:
            acc = theta0
            for j in range(m):
                wj = max(v[k] - r[j], w[j])
                w[j] = wj
                acc += weights[j] * wj
            out[k] = acc
        elif v[k] < v[k - 1]:
            acc = theta0
            for j in range(m):
                wj = min(v[k] + r[j], w[j])
                w[j] = wj
                acc += weights[j] * wj
            out[k] = acc
        else:
            out[k] = out[k - 1]
    return out


def _weights(n: int) -> tuple[str, ...]:
    return tuple(f"w{j}" for j in range(n + 1))


@dataclass(frozen=True)
class SlipModel(ParametricModel):
    """Prandtl-Ishlinskii / Maxwell slip over the signed input (kind ``"maxwell_slip"``):
    ``theta0``, ``w0..wn`` (one weight per threshold ``r_j = j r_max / n``), ``r_max``
    (module docstring); ``n + 3`` parameters."""

    n: int = 30

    def thresholds(self, r_max: float) -> np.ndarray:
        """``r_j = j r_max / n``, shape (n + 1,) (input unit)."""
        return np.linspace(0.0, abs(float(r_max)), self.n + 1)

    def evaluate(self, signals: Signals, values: np.ndarray) -> np.ndarray:
        """Output angle (deg), shape (n_samples,)."""
        x = np.asarray(values, dtype=float)
        theta0, w, r_max = x[0], np.ascontiguousarray(x[1:-1]), x[-1]
        return slip_output(_input(signals), float(theta0), self.thresholds(r_max), w)

    def jacobian(
        self, signals: Signals, values: np.ndarray, rows: np.ndarray | None = None
    ) -> np.ndarray:
        """d output / d parameters, shape (n_samples, n + 3) (or (len(rows), n + 3)),
        exact: 1 for ``theta0``, the operator outputs for the weights, and
        ``sum_j w_j (j / n) dP/dr`` for ``r_max`` (dP/dr = -1 on a loading boundary,
        +1 on an unloading one, 0 in the initial state)."""
        v = _input(signals)
        x = np.asarray(values, dtype=float)
        w, r_max = x[1:-1], float(x[-1])
        m = self.n + 1
        jac = np.empty((v.size, m + 2))
        jac[:, 0] = 1.0
        scale = np.linspace(0.0, 1.0, m) * (1.0 if r_max >= 0 else -1.0)
        slip_operators(v, self.thresholds(r_max), jac[:, 1:], np.ascontiguousarray(w * scale))
        return jac if rows is None else jac[np.asarray(rows)]

    def guess(
        self, v: np.ndarray, theta_deg: np.ndarray, deadband: float | None = None
    ) -> SlipModel:
        """A new model whose values are the data-driven start for (v, theta)
        (:func:`slip_starts`); fixed parameters keep their values (but ``r_max``)."""
        return guessed_model(self, slip_starts, v, theta_deg, deadband)


def slip_model(n: int = 30, **values: float) -> SlipModel:
    """A signed Prandtl-Ishlinskii / Maxwell-slip model (:class:`SlipModel`) with ``n``
    non-zero thresholds (``n + 1`` operators), default values overridden by ``values``."""
    check_settings("slip_model", n)
    params = [
        Parameter("theta0", value=0.0, lower=-500.0, upper=500.0, unit="deg",
                  doc="output at zero input with every element relaxed"),
    ]  # fmt: skip
    for j, name in enumerate(_weights(n)):
        what = (
            "linear (elastic) part: weight of P_0[v] = v"
            if j == 0
            else (f"stiffness of the element slipping at r_{j} = {j}/{n} r_max (>= 0)")
        )
        # an element's stiffness is >= 0 (the linear part w0 may have either sign)
        params.append(Parameter(name, value=7.0e-3 if j == 0 else 0.0,
                                lower=-1.0 if j == 0 else 0.0, upper=1.0, unit="deg/count",
                                doc=what))  # fmt: skip
    params.append(
        Parameter("r_max", value=1000.0, lower=0.0, upper=1e7, fixed=True, unit="count",
                  doc="largest slip threshold (the grid; 0.45 of the input range)")
    )  # fmt: skip
    return checked_values("slip_model", SlipModel("maxwell_slip", tuple(params), n=n), values)


def slip_fixed(config) -> tuple[str, ...]:
    """Parameters a fit holds: the threshold grid ``r_max`` (set from the input range)."""
    return ("r_max",)


def slip_starts(
    model: SlipModel,
    v: np.ndarray,
    theta: np.ndarray,
    n_starts: int,
    rng: np.random.Generator,
    deadband: float = 0.0,
) -> list[np.ndarray]:
    """One data-driven start (shape (n + 3,)): ``r_max`` 0.45 of the input's range (an
    element slipping at half the range or later slips only at the extremes, if at all:
    its weight would trade with ``theta0``); ``theta0`` and the
    weights their bounded least-squares optimum on the finite angles (operators relaxed
    at the first sample; the output is linear in them), every element at least 1e-3 of
    the mean stiffness (strictly inside its bound). Without enough samples ``theta0``
    and ``w0`` are a straight line through the angle and the elements 0. One start
    (``n_starts`` is ignored)."""
    v = np.asarray(v, dtype=float)
    theta = np.asarray(theta, dtype=float)
    span = float(np.ptp(v)) if v.size else 0.0
    vals = model.value_dict()
    if span > 0:
        vals["r_max"] = 0.45 * span
    line = _line(v, theta, np.isfinite(theta))
    if line is not None:
        vals["w0"], vals["theta0"] = line
    x = model.vector(vals)
    ok = np.isfinite(theta)
    if ok.sum() > len(x) and span > 0:
        # the output is linear in theta0 and the weights: their bounded least-squares
        # optimum on these samples (operators relaxed at the first sample) is the start
        free = np.array([not p.fixed or p.name == "r_max" for p in model.parameters])
        free[-1] = False
        jac = model.jacobian(Signals(v=v), x)[ok][:, free]
        lo = np.array([p.lower for p in model.parameters])[free]
        hi = np.array([p.upper for p in model.parameters])[free]
        fixed_part = model.evaluate(Signals(v=v), np.where(free, 0.0, x))[ok]
        # the same problem on the QR-reduced system (p x p instead of n x p)
        q, r = np.linalg.qr(jac)
        sol = lsq_linear(r, q.T @ (theta[ok] - fixed_part), bounds=(lo, hi), method="bvls")
        if np.all(np.isfinite(sol.x)):
            x[free] = sol.x
            # strictly inside the bounds (1e-3 of the mean stiffness): the bounded fit
            # moves a start on a bound inside it, which would cost more than the start
            k = [i for i, p in enumerate(model.parameters) if p.name[1:].isdigit()][1:]
            x[k] = np.maximum(x[k], 1e-3 * max(float(np.mean(x[k])), 1e-12))
    return [x]
