"""Compiled building blocks of the hysteresis models (numba) and a numpy reference.

The models (:mod:`.models`) write the paper's equations with these:

* :func:`thresholds` (Eq14) and :func:`density` (Eq15): the operators' thresholds
  ``r_i`` and weights ``p(r_i)``, written once (callable from Python and from compiled
  code);
* :func:`play_operators`: THE play-operator loop (Eq1-2 / Eq16-17) and the weighted
  sum (Eq3 / Eq18-19) - the operators of GPI, of both paper-EGPI families and of the
  general EGPI run through it; :func:`play_switched` is the same loop with the
  continuous EGPI's unloading law, which switches at the flag point;
* :func:`motion_direction`: what ``v'`` means on sampled data (Eq8, Eq20);
* :func:`select_stage`: the general EGPI's output switching (Eq8).

The operator recursion is sequential in time, so it is compiled: the loop over time
runs in machine code and the loop over operators is branch-free (``max``/``min`` over
contiguous arrays), which LLVM vectorises.

Conventions:

* ``v`` : input, shape (n,), any unit (encoder counts for I2RIS).
* ``gamma_l``, ``gamma_r`` : loading / unloading envelope at every sample, shape (n,).
* ``r_l``, ``r_r`` : effective thresholds of the loading and unloading boundaries,
  shape (m,): the loading boundary is ``gamma_l - r_l``, the unloading one
  ``gamma_r + r_r`` (``r_r = kappa r`` for the paper's second family, Eq17).
* ``p`` : operator weights p(r_i), shape (m,) (Eq15).
* Direction of an operator step: sign of ``v[k] - v[k-1]`` exactly as Eq1-2
  (a hold keeps the state).
* Initial state (the paper is silent; our choice, docs/models.md): ``w[-1] = 0`` clamped
  into the band at ``v[0]``: ``w = min(max(0, gamma_l - r_l), gamma_r + r_r)``.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def thresholds(r1, rn, n):  # pragma: no cover - compiled
    """Thresholds ``r_0 = 0``, ``r_i = r1 + (i - 1)(rn - r1)/(n - 1)`` (Eq14).

    Parameters
    ----------
    r1, rn : float
        Smallest and largest non-zero threshold (unit of the output, deg).
    n : int
        Number of non-zero thresholds (>= 1; with n = 1 only r1 is used).

    Returns
    -------
    ndarray, shape (n + 1,)
    """
    if n < 1:
        raise ValueError("thresholds: n must be >= 1")
    r = np.empty(n + 1)
    r[0] = 0.0
    step = (rn - r1) / (n - 1) if n > 1 else 0.0
    for i in range(1, n + 1):
        r[i] = r1 + (i - 1) * step
    return r


@njit(cache=True)
def density(r, lam, sigma):  # pragma: no cover - compiled
    """Operator weights ``p(r) = lam exp(-sigma r)`` (Eq15), shape of ``r`` (1-D)."""
    return lam * np.exp(-sigma * r)


@njit(cache=True, fastmath=True)
def play_operators(v, gamma_l, r_l, gamma_r, r_r, p):  # pragma: no cover - compiled
    """Weighted sum of play operators ``sum_i p_i w_i`` at every sample, shape (n,).

    THE play-operator loop (Eq1-3; each family of Eq4-7 and Eq16-19): v rises
    ``w_i = max(gamma_l - r_l[i], w_i)``, v falls ``w_i = min(gamma_r + r_r[i], w_i)``,
    a hold keeps ``w``.

    Parameters
    ----------
    v : ndarray, shape (n,)
        Input (counts).
    gamma_l, gamma_r : ndarray, shape (n,)
        Loading / unloading envelope at every sample (deg).
    r_l, r_r : ndarray, shape (m,)
        Thresholds of the loading / unloading boundary (deg).
    p : ndarray, shape (m,)
        Weights p(r_i).
    """
    ns = v.size
    m = p.size
    out = np.empty(ns)
    if ns == 0:
        return out
    w = np.empty(m)
    acc = 0.0
    for i in range(m):
        wi = min(max(0.0, gamma_l[0] - r_l[i]), gamma_r[0] + r_r[i])
        w[i] = wi
        acc += p[i] * wi
    out[0] = acc
    for k in range(1, ns):
        if v[k] > v[k - 1]:  # Eq1, v' > 0
            g = gamma_l[k]
            acc = 0.0
            for i in range(m):
                wi = max(g - r_l[i], w[i])
                w[i] = wi
                acc += p[i] * wi
            out[k] = acc
        elif v[k] < v[k - 1]:  # Eq1, v' < 0
            g = gamma_r[k]
            acc = 0.0
            for i in range(m):
                wi = min(g + r_r[i], w[i])
                w[i] = wi
                acc += p[i] * wi
            out[k] = acc
        else:  # Eq1, v' = 0
            out[k] = out[k - 1]
    return out


@njit(cache=True, fastmath=True)
def play_switched(
    v, gamma_l, gamma_r1, gamma_r2, r, kappa, v_f, gamma_r1_at_vf, p
):  # pragma: no cover
    """:func:`play_operators` whose unloading law switches at ``v_f`` (continuous EGPI).

    Loading ``w_i = max(gamma_l - r_i, w_i)``; unloading ``w_i = min(gamma_r1 + r_i, w_i)``
    above ``v_f`` and ``min(gamma_r2 + kappa r_i, w_i)`` at or below it, from whatever
    state the operators have there (docs/models.md). An unloading step that crosses
    ``v_f`` first meets the first boundary at ``v_f`` (``gamma_r1_at_vf + r_i``, as a
    continuous input would), so the output does not depend on the sampling. Shapes as
    :func:`play_operators` (``r``: thresholds, shape (m,)); ``kappa``, ``v_f``,
    ``gamma_r1_at_vf`` are scalars. (A loop of its own: a switch inside
    :func:`play_operators` costs that loop ~30 % of its speed.)
    """
    ns = v.size
    m = p.size
    out = np.empty(ns)
    if ns == 0:
        return out
    w = np.empty(m)
    g, kr = (gamma_r1[0], 1.0) if v[0] > v_f else (gamma_r2[0], kappa)
    acc = 0.0
    for i in range(m):
        wi = min(max(0.0, gamma_l[0] - r[i]), g + kr * r[i])
        w[i] = wi
        acc += p[i] * wi
    out[0] = acc
    for k in range(1, ns):
        if v[k] > v[k - 1]:
            g = gamma_l[k]
            acc = 0.0
            for i in range(m):
                wi = max(g - r[i], w[i])
                w[i] = wi
                acc += p[i] * wi
            out[k] = acc
        elif v[k] < v[k - 1]:
            g, kr = (gamma_r1[k], 1.0) if v[k] > v_f else (gamma_r2[k], kappa)
            # a step that crossed v_f meets the first boundary at v_f first
            g1 = gamma_r1_at_vf if v[k - 1] > v_f >= v[k] else np.inf
            acc = 0.0
            for i in range(m):
                wi = min(g + kr * r[i], min(g1 + r[i], w[i]))
                w[i] = wi
                acc += p[i] * wi
            out[k] = acc
        else:
            out[k] = out[k - 1]
    return out


@njit(cache=True)
def motion_direction(v, deadband):  # pragma: no cover - compiled
    """What ``v'`` means on a sampled signal: +1 loading, -1 unloading, int8 (n,).

    The direction of the last change larger than ``deadband`` (same unit as v)
    measured from the latest extreme; holds keep the direction; the signal starts
    as loading (+1). With ``deadband = 0`` this is the direction of the last
    non-zero change. Our choice: the paper does not define v' on sampled data.
    """
    n = v.size
    d = np.empty(n, dtype=np.int8)
    if n == 0:
        return d
    state = 1
    anchor = v[0]
    for k in range(n):
        x = v[k]
        if state > 0:
            if x > anchor:
                anchor = x
            elif anchor - x > deadband:
                state = -1
                anchor = x
        else:
            if x < anchor:
                anchor = x
            elif x - anchor > deadband:
                state = 1
                anchor = x
        d[k] = state
    return d


@njit(cache=True)
def select_stage(z, v, direction, rising_flags, falling_flags):  # pragma: no cover
    """General EGPI output switching (Eq8): pick a family's output per sample, (n,).

    Loading (direction > 0): stage = number of ``rising_flags`` <= v.
    Unloading: stage = number of ``falling_flags`` >= v.
    With one rising flag v_f1 and one falling flag v_f2 this is
    ``z = z1 if v < v_f1 else z2`` (loading), ``z = z1 if v > v_f2 else z2`` (unloading).
    """
    n_fam, n = z.shape
    out = np.empty(n)
    for k in range(n):
        s = 0
        if direction[k] > 0:
            for j in range(rising_flags.size):
                if v[k] >= rising_flags[j]:
                    s += 1
        else:
            for j in range(falling_flags.size):
                if v[k] <= falling_flags[j]:
                    s += 1
        if s > n_fam - 1:
            s = n_fam - 1
        out[k] = z[s, k]
    return out


def play_numpy(v, gamma_l, r_l, gamma_r, r_r, p):
    """Reference for :func:`play_operators`: Python loop over time, numpy over operators
    (tests and the speed benchmark)."""
    v = np.asarray(v, dtype=float)
    out = np.empty(v.size)
    w = np.minimum(np.maximum(0.0, gamma_l[0] - r_l), gamma_r[0] + r_r)
    out[0] = w @ p
    for k in range(1, v.size):
        if v[k] > v[k - 1]:
            w = np.maximum(gamma_l[k] - r_l, w)
        elif v[k] < v[k - 1]:
            w = np.minimum(gamma_r[k] + r_r, w)
        out[k] = w @ p
    return out
