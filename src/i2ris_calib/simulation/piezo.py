"""Piezo-stack-like actuators that are not the project's model forms (truths for tests
and benchmarks of one loop through zero).

Both map an input ``u`` (V-like units, shape (n,)) to an output ``y`` (um, shape (n,))
starting relaxed at ``u[0]``; written independently of the fitted kinds
(:mod:`i2ris_calib.hysteresis.bouc_wen`, :mod:`i2ris_calib.hysteresis.slip`), so a fit
that recovers them says something about the physics, not about shared code.
"""

from __future__ import annotations

import numpy as np


def bouc_wen_actuator(
    u: np.ndarray, d: float, a: float, beta: float, gamma: float, sub: int = 20
) -> np.ndarray:
    """``y = d u - h``, ``dh = a du - beta |du| h - gamma du |h|`` (the classic Bouc-Wen
    form, n = 1), integrated by explicit Euler in ``sub`` sub-steps of each input step."""
    u = np.asarray(u, dtype=float)
    y = np.empty(u.size)
    h = 0.0
    y[0] = d * u[0]
    for k in range(1, u.size):
        du = (u[k] - u[k - 1]) / sub
        for _ in range(sub):
            h += a * du - beta * abs(du) * h - gamma * du * abs(h)
        y[k] = d * u[k] - h
    return y


def maxwell_slip_actuator(u: np.ndarray, d: float, k, r) -> np.ndarray:
    """``y = d u - sum_i k_i F_i`` of a bank of elasto-slip elements, each deflection
    ``F_i = clip(F_i + du, -r_i, r_i)`` (relaxed at the start); ``k``, ``r`` shape (m,)."""
    u = np.asarray(u, dtype=float)
    k, r = np.asarray(k, dtype=float), np.asarray(r, dtype=float)
    f = np.zeros(r.size)
    y = np.empty(u.size)
    y[0] = d * u[0]
    for t in range(1, u.size):
        f = np.clip(f + (u[t] - u[t - 1]), -r, r)
        y[t] = d * u[t] - k @ f
    return y
