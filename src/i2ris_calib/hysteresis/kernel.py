"""Compiled play-operator loops (numba) and a straightforward numpy reference.

The operator recursion (Eq1-2) is sequential in time, so it is compiled: the loop
over time runs in machine code and the inner loop over operators is branch-free
(``max``/``min`` over contiguous arrays), which LLVM vectorises.

Conventions shared by every function here:

* ``v`` : input, shape (n,), any unit (encoder counts for I2RIS).
* ``gl``, ``gr`` : ascending / descending envelope values at every sample,
  shape (S, n), one row per operator family (stage).
* ``rl``, ``rr`` : effective thresholds of each family, shape (S, m): the ascending
  branch is ``gl - rl`` and the descending one ``gr + rr`` (``rl = kappa_l * r``,
  ``rr = kappa_r * r``; Eq4-5, Eq16-17).
* ``p`` : operator weights p(r_i), shape (m,) (Eq15).
* Direction of an operator step: sign of ``v[k] - v[k-1]`` exactly as Eq1-2
  (a hold keeps the state).
* Initial state (the paper is silent; our choice, docs/models.md): ``w[-1] = 0`` clamped
  into ``[gl[0] - rl, gr[0] + rr]``, i.e. ``w = min(max(0, gl - rl), gr + rr)``.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, fastmath=True)
def family_outputs(v, gl, gr, rl, rr, p):  # pragma: no cover - compiled
    """Weighted sums of play operators, one per family: array (S, n) (Eq3/Eq6-7)."""
    n_fam, n = gl.shape
    m = p.size
    out = np.empty((n_fam, n))
    w = np.empty(m)
    for s in range(n_fam):
        acc = 0.0
        for i in range(m):
            wi = min(max(0.0, gl[s, 0] - rl[s, i]), gr[s, 0] + rr[s, i])
            w[i] = wi
            acc += p[i] * wi
        out[s, 0] = acc
        for k in range(1, n):
            if v[k] > v[k - 1]:
                g = gl[s, k]
                acc = 0.0
                for i in range(m):
                    wi = max(g - rl[s, i], w[i])
                    w[i] = wi
                    acc += p[i] * wi
                out[s, k] = acc
            elif v[k] < v[k - 1]:
                g = gr[s, k]
                acc = 0.0
                for i in range(m):
                    wi = min(g + rr[s, i], w[i])
                    w[i] = wi
                    acc += p[i] * wi
                out[s, k] = acc
            else:
                out[s, k] = out[s, k - 1]
    return out


@njit(cache=True, fastmath=True)
def linear_family_outputs(v, al, bl, ar, br, rl, rr, p):  # pragma: no cover - compiled
    """:func:`family_outputs` for linear envelopes ``gl = al v + bl``, ``gr = ar v + br``
    (al, bl, ar, br: shape (S,)), computed inline: no envelope arrays are built."""
    n = v.size
    n_fam = al.size
    out = np.empty((n_fam, n))
    m = p.size
    w = np.empty(m)
    for s in range(n_fam):
        acc = 0.0
        g_l = al[s] * v[0] + bl[s]
        g_r = ar[s] * v[0] + br[s]
        for i in range(m):
            wi = min(max(0.0, g_l - rl[s, i]), g_r + rr[s, i])
            w[i] = wi
            acc += p[i] * wi
        out[s, 0] = acc
        for k in range(1, n):
            if v[k] > v[k - 1]:
                g = al[s] * v[k] + bl[s]
                acc = 0.0
                for i in range(m):
                    wi = max(g - rl[s, i], w[i])
                    w[i] = wi
                    acc += p[i] * wi
                out[s, k] = acc
            elif v[k] < v[k - 1]:
                g = ar[s] * v[k] + br[s]
                acc = 0.0
                for i in range(m):
                    wi = min(g + rr[s, i], w[i])
                    w[i] = wi
                    acc += p[i] * wi
                out[s, k] = acc
            else:
                out[s, k] = out[s, k - 1]
    return out


@njit(cache=True)
def thresholds_and_weights(r1, rn, n, lam, sigma):  # pragma: no cover - compiled
    """Thresholds [0, r1..rn] (Eq14) and weights lam exp(-sigma r) (Eq15), shape (n+1,)."""
    r = np.empty(n + 1)
    r[0] = 0.0
    for i in range(1, n + 1):
        r[i] = r1 + (i - 1) * (rn - r1) / (n - 1) if n > 1 else r1
    return r, lam * np.exp(-sigma * r)


@njit(cache=True)
def i2ris_egpi_output(v, x, n, deadband):  # pragma: no cover - compiled
    """I2RIS EGPI output (Eq16-23), shape (n_samples,); x = (a1..a6, lam, sigma, r1, rn, kappa, v_f)."""
    r, p = thresholds_and_weights(x[8], x[9], n, x[6], x[7])
    rl = np.empty((2, n + 1))
    rr = np.empty((2, n + 1))
    rl[0] = r
    rl[1] = r
    rr[0] = r
    rr[1] = x[10] * r
    al = np.array([x[0], x[0]])
    bl = np.array([x[1], x[1]])
    ar = np.array([x[2], x[4]])
    br = np.array([x[3], x[5]])
    z = linear_family_outputs(v, al, bl, ar, br, rl, rr, p)
    d = motion_direction(v, deadband)
    return select_stage(z, v, d, np.empty(0), np.array([x[11]]))


@njit(cache=True)
def gpi_output(v, x, n):  # pragma: no cover - compiled
    """GPI output (Eq3), shape (n_samples,); x = (a1, a2, a3, a4, lam, sigma, r1, rn)."""
    r, p = thresholds_and_weights(x[6], x[7], n, x[4], x[5])
    rr = np.empty((1, n + 1))
    rr[0] = r
    z = linear_family_outputs(
        v, np.array([x[0]]), np.array([x[1]]), np.array([x[2]]), np.array([x[3]]), rr, rr, p
    )
    return z[0]


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
    """EGPI output switching (Eq8, Eq21): pick a family's output per sample, (n,).

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


def family_outputs_numpy(v, gl, gr, rl, rr, p):
    """Reference implementation of :func:`family_outputs`: python loop over time,
    numpy over operators. Used by tests and by the speed benchmark."""
    v = np.asarray(v, dtype=float)
    n_fam, n = gl.shape
    out = np.empty((n_fam, n))
    w = np.minimum(np.maximum(0.0, gl[:, :1] - rl), gr[:, :1] + rr)
    out[:, 0] = w @ p
    for k in range(1, n):
        if v[k] > v[k - 1]:
            w = np.maximum(gl[:, k : k + 1] - rl, w)
        elif v[k] < v[k - 1]:
            w = np.minimum(gr[:, k : k + 1] + rr, w)
        out[:, k] = w @ p
    return out


@njit(cache=True, fastmath=True)
def continuous_egpi_output(v, x, n):  # pragma: no cover - compiled
    """Continuous I2RIS EGPI output, shape (n_samples,); x as :func:`i2ris_egpi_output`.

    One family of play operators whose *unloading* boundary is piecewise in the input:
    ``gamma_r1(v) + r`` above the flag point v_f, ``gamma_r2(v) + kappa r`` at or
    below it; loading is ``gamma_l(v) - r`` throughout (Eq16-17's envelopes and
    thresholds). The stage-2 operators thus take over the stage-1 state where the
    input crosses v_f instead of running from the start with a state of their own,
    so the output never steps at v_f: while the stage-2 boundary lies above the
    state the operators hold (the S3 dead zone), then follow ``gamma_r2 + kappa r``.
    """
    r, p = thresholds_and_weights(x[8], x[9], n, x[6], x[7])
    m = p.size
    a1, a2, a3, a4, a5, a6, kappa, vf = x[0], x[1], x[2], x[3], x[4], x[5], x[10], x[11]
    ns = v.size
    out = np.empty(ns)
    w = np.empty(m)
    if ns == 0:
        return out
    gl = a1 * v[0] + a2
    if v[0] > vf:
        g, kr = a3 * v[0] + a4, 1.0
    else:
        g, kr = a5 * v[0] + a6, kappa
    acc = 0.0
    for i in range(m):
        wi = min(max(0.0, gl - r[i]), g + kr * r[i])
        w[i] = wi
        acc += p[i] * wi
    out[0] = acc
    for k in range(1, ns):
        if v[k] > v[k - 1]:
            g = a1 * v[k] + a2
            acc = 0.0
            for i in range(m):
                wi = max(g - r[i], w[i])
                w[i] = wi
                acc += p[i] * wi
            out[k] = acc
        elif v[k] < v[k - 1]:
            if v[k] > vf:
                g, kr = a3 * v[k] + a4, 1.0
            else:
                g, kr = a5 * v[k] + a6, kappa
            # a step that crosses v_f passes the stage-1 boundary at v_f first (as a
            # continuous input would): the output does not depend on the sampling
            g1 = a3 * vf + a4 if v[k - 1] > vf >= v[k] else np.inf
            acc = 0.0
            for i in range(m):
                wi = min(g + kr * r[i], min(g1 + r[i], w[i]))
                w[i] = wi
                acc += p[i] * wi
            out[k] = acc
        else:
            out[k] = out[k - 1]
    return out
