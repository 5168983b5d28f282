"""Compiled building blocks of the hysteresis models (numba) and a numpy reference.

The models (:mod:`.models`) write the paper's equations with these:

* :func:`thresholds` (Eq14) and :func:`density` (Eq15): the operators' thresholds
  ``r_i`` and weights ``p(r_i)``, written once (callable from Python and from compiled
  code);
* :func:`play_operators`: THE compiled play-operator loop (Eq1-2 / Eq16-17) and the
  weighted sum (Eq3 / Eq18-19) on linear envelopes - the operators of GPI and of both
  paper-EGPI families run through it; :func:`play_switched` is the same loop with the
  continuous EGPI's unloading law, which switches at the flag point;
  :func:`play_numpy` the plain reference on envelope arrays (also the general EGPI's);
* :func:`motion_direction`: what ``v'`` means on sampled data (Eq8, Eq20);
* :func:`select_stage`: the general EGPI's output switching (Eq8).

The operator recursion is sequential in time, so it is compiled: the loop over time
runs in machine code and the loop over operators is branch-free (``max``/``min`` over
contiguous arrays), which LLVM vectorises.

Conventions:

* ``v`` : input, shape (n,), any unit (encoder counts for I2RIS).
* envelopes: ``gamma_l = a_l v + b_l``, ``gamma_r = a_r v + b_r`` (compiled loops;
  scalars), or values at every sample, shape (n,) (:func:`play_numpy`).
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
    for i in range(1, n + 1):
        r[i] = r1 + (i - 1) * (rn - r1) / (n - 1) if n > 1 else r1
    return r


@njit(cache=True)
def density(r, lam, sigma):  # pragma: no cover - compiled
    """Operator weights ``p(r) = lam exp(-sigma r)`` (Eq15), shape of ``r`` (1-D)."""
    return lam * np.exp(-sigma * r)


@njit(cache=True, fastmath=True)
def play_operators(v, a_l, b_l, r_l, a_r, b_r, r_r, p, out=None):  # pragma: no cover - compiled
    """Weighted sum of play operators ``sum_i p_i w_i`` at every sample, shape (n,).

    THE compiled play-operator loop (Eq1-3; each family of Eq16-19), on linear
    envelopes ``gamma_l = a_l v + b_l`` and ``gamma_r = a_r v + b_r`` (Eq21-23),
    evaluated inside the loop (envelope arrays of a long record would cost more than
    the loop: fresh memory pages). v rises ``w_i = max(gamma_l - r_l[i], w_i)``, v falls
    ``w_i = min(gamma_r + r_r[i], w_i)``, a hold keeps ``w``.

    Parameters
    ----------
    v : ndarray, shape (n,)
        Input (counts).
    a_l, b_l, a_r, b_r : float
        Envelope slopes (deg/count) and offsets (deg).
    r_l, r_r : ndarray, shape (m,)
        Thresholds of the loading / unloading boundary (deg).
    p : ndarray, shape (m,)
        Weights p(r_i).
    out : ndarray, shape (n,), optional
        Written in place and returned (default: a new array).
    """
    ns = v.size
    m = p.size
    if out is None:
        out = np.empty(ns)
    if ns == 0:
        return out
    w = np.empty(m)
    g_l, g_r = a_l * v[0] + b_l, a_r * v[0] + b_r
    acc = 0.0
    for i in range(m):
        wi = min(max(0.0, g_l - r_l[i]), g_r + r_r[i])
        w[i] = wi
        acc += p[i] * wi
    out[0] = acc
    for k in range(1, ns):
        if v[k] > v[k - 1]:  # Eq1, v' > 0
            g = a_l * v[k] + b_l
            acc = 0.0
            for i in range(m):
                wi = max(g - r_l[i], w[i])
                w[i] = wi
                acc += p[i] * wi
            out[k] = acc
        elif v[k] < v[k - 1]:  # Eq1, v' < 0
            g = a_r * v[k] + b_r
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
def play_switched(v, a_l, b_l, a_r1, b_r1, a_r2, b_r2, r, kappa, v_f, p):  # pragma: no cover
    """:func:`play_operators` whose unloading law switches at ``v_f`` (continuous EGPI).

    Loading ``w_i = max(gamma_l - r_i, w_i)``; unloading ``w_i = min(gamma_r1 + r_i, w_i)``
    above ``v_f`` and ``min(gamma_r2 + kappa r_i, w_i)`` at or below it, from whatever
    state the operators have there (docs/models.md); ``gamma_l = a_l v + b_l``,
    ``gamma_r1 = a_r1 v + b_r1``, ``gamma_r2 = a_r2 v + b_r2``. An unloading step that
    crosses ``v_f`` first meets the first boundary at ``v_f`` (as a continuous input
    would), so the output does not depend on the sampling. ``r``: thresholds, shape
    (m,). (A loop of its own: a switch inside :func:`play_operators` costs that loop
    ~30 % of its speed.)
    """
    ns = v.size
    m = p.size
    out = np.empty(ns)
    if ns == 0:
        return out
    w = np.empty(m)
    g_l = a_l * v[0] + b_l
    g, kr = (a_r1 * v[0] + b_r1, 1.0) if v[0] > v_f else (a_r2 * v[0] + b_r2, kappa)
    acc = 0.0
    for i in range(m):
        wi = min(max(0.0, g_l - r[i]), g + kr * r[i])
        w[i] = wi
        acc += p[i] * wi
    out[0] = acc
    for k in range(1, ns):
        if v[k] > v[k - 1]:
            g = a_l * v[k] + b_l
            acc = 0.0
            for i in range(m):
                wi = max(g - r[i], w[i])
                w[i] = wi
                acc += p[i] * wi
            out[k] = acc
        elif v[k] < v[k - 1]:
            if v[k] > v_f:
                g, kr = a_r1 * v[k] + b_r1, 1.0
            else:
                g, kr = a_r2 * v[k] + b_r2, kappa
            # a step that crossed v_f meets the first boundary at v_f first
            g1 = a_r1 * v_f + b_r1 if v[k - 1] > v_f >= v[k] else np.inf
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
    """The play-operator loop on envelope values, plainly: Python loop over time, numpy
    over operators.

    The reference of :func:`play_operators` (tests, the speed benchmark) and the loop
    of the general EGPI (any envelope, e.g. the paper's tanh ones of Section 3.1; about
    50 ms for 10,000 samples).

    Parameters
    ----------
    v : ndarray, shape (n,)
    gamma_l, gamma_r : ndarray, shape (n,) or (n, S)
        Envelopes at every sample (S families at once).
    r_l, r_r : ndarray, shape (m,) or (S, m)
    p : ndarray, shape (m,)

    Returns
    -------
    ndarray, shape (n,) or (n, S)
    """
    v = np.asarray(v, dtype=float)
    gl = np.asarray(gamma_l, dtype=float)[..., None]
    gr = np.asarray(gamma_r, dtype=float)[..., None]
    out = np.empty(gl.shape[:-1])
    if v.size == 0:
        return out
    w = np.minimum(np.maximum(0.0, gl[0] - r_l), gr[0] + r_r)
    out[0] = w @ p
    for k in range(1, v.size):
        if v[k] > v[k - 1]:
            w = np.maximum(gl[k] - r_l, w)
        elif v[k] < v[k - 1]:
            w = np.minimum(gr[k] + r_r, w)
        out[k] = w @ p
    return out


#: What :func:`play_jacobian` differentiates by, in the order of its ``cols`` argument.
JAC_QUANTITIES = ("a_l", "b_l", "a_r1", "b_r1", "a_r2", "b_r2", "r1", "rn", "kappa", "sigma", "lam")


@njit(cache=True, fastmath=True)
def play_jacobian(
    v,
    a_l,
    b_l,
    a_r1,
    b_r1,
    a_r2,
    b_r2,
    r,
    kappa,
    v_f,
    mode,
    p,
    dp_dr,
    dr_dr1,
    dr_drn,
    lam,
    cols,
    jac,
):  # pragma: no cover - compiled
    """Output of one play-operator family and its derivatives, in one pass.

    The output is piecewise linear in the envelope parameters and thresholds: every
    operator state ``w_i`` is the boundary that last moved it, evaluated at the input
    where it did (``a v_j + b -/+ k r_i``) or 0 (the clamped initial state). The loop
    tracks, per operator, which boundary that was and at which input, and sums the
    exact derivatives (the one-sided derivatives a small finite-difference step sees,
    except where two boundaries tie).

    Parameters
    ----------
    v : ndarray, shape (n,)
    a_l, b_l, a_r1, b_r1, a_r2, b_r2 : float
        Loading, stage-1 and stage-2 unloading envelopes (slope, offset).
    r : ndarray, shape (m,)
        Thresholds (Eq14).
    kappa, v_f : float
        Stage-2 threshold factor and flag point (``mode`` 2).
    mode : int
        0: unloading always on stage 1 (GPI, the EGPI's first family); 1: always on
        stage 2 with ``kappa r`` (the EGPI's second family); 2: stage 1 above ``v_f``,
        stage 2 at or below it (:func:`play_switched`).
    p, dp_dr, dr_dr1, dr_drn : ndarray, shape (m,)
        Weights, their derivative in ``r_i``, and the derivatives of ``r_i`` in r1, rn.
    lam : float
        Density scale (``d y / d lam = y / lam``).
    cols : ndarray of int, shape (11,)
        Column of ``jac`` receiving the derivative in each of :data:`JAC_QUANTITIES`
        (-1: not written).
    jac : ndarray, shape (n, q)
        Written in place (columns not named in ``cols`` are left as they are).

    Returns
    -------
    y : ndarray, shape (n,)
    """
    ns = v.size
    m = p.size
    y = np.empty(ns)
    if ns == 0:
        return y
    d = np.zeros(11)
    w = np.empty(m)
    # per operator, which boundary set w_i (as 0/1 weights: loading, stage-1, stage-2
    # unloading; all 0 for the clamped zero), the input where it did, and d w_i / d r_i
    on_l, on_1, on_2 = np.zeros(m), np.zeros(m), np.zeros(m)
    vs, dwdr = np.zeros(m), np.zeros(m)
    stage2 = mode == 1 or (mode == 2 and not v[0] > v_f)
    g_l = a_l * v[0] + b_l
    g_r, kr = (a_r2 * v[0] + b_r2, kappa) if stage2 else (a_r1 * v[0] + b_r1, 1.0)
    for i in range(m):
        lo = g_l - r[i]
        hi = g_r + kr * r[i]
        vs[i] = v[0]
        if hi < max(0.0, lo):
            w[i], dwdr[i] = hi, kr
            if stage2:
                on_2[i] = 1.0
            else:
                on_1[i] = 1.0
        elif lo > 0.0:
            w[i], dwdr[i], on_l[i] = lo, -1.0, 1.0
        else:
            w[i] = 0.0
    pr = p * r
    for k in range(ns):
        if k > 0:
            vk = v[k]
            if vk > v[k - 1]:
                g = a_l * vk + b_l
                for i in range(m):  # branch-free selects: vectorised
                    c = g - r[i]
                    up = c > w[i]
                    w[i] = c if up else w[i]
                    vs[i] = vk if up else vs[i]
                    dwdr[i] = -1.0 if up else dwdr[i]
                    on_l[i] = 1.0 if up else on_l[i]
                    on_1[i] = 0.0 if up else on_1[i]
                    on_2[i] = 0.0 if up else on_2[i]
            elif vk < v[k - 1]:
                stage2 = mode == 1 or (mode == 2 and not vk > v_f)
                if stage2:
                    g, kr, f1, f2 = a_r2 * vk + b_r2, kappa, 0.0, 1.0
                else:
                    g, kr, f1, f2 = a_r1 * vk + b_r1, 1.0, 1.0, 0.0
                if mode == 2 and v[k - 1] > v_f and v_f >= vk:
                    # the step crossed v_f: the stage-1 boundary at v_f comes first
                    g1 = a_r1 * v_f + b_r1
                    for i in range(m):
                        c1 = g1 + r[i]
                        if c1 < w[i]:
                            w[i], vs[i], dwdr[i] = c1, v_f, 1.0
                            on_l[i], on_1[i], on_2[i] = 0.0, 1.0, 0.0
                for i in range(m):
                    c = g + kr * r[i]
                    dn = c < w[i]
                    w[i] = c if dn else w[i]
                    vs[i] = vk if dn else vs[i]
                    dwdr[i] = kr if dn else dwdr[i]
                    on_l[i] = 0.0 if dn else on_l[i]
                    on_1[i] = f1 if dn else on_1[i]
                    on_2[i] = f2 if dn else on_2[i]
        acc = j0 = j1 = j2 = j3 = j4 = j5 = j6 = j7 = j8 = j9 = 0.0
        for i in range(m):  # branch-free: vectorised
            pi = p[i]
            wi = w[i]
            acc += pi * wi
            pv = pi * vs[i]
            j0 += pv * on_l[i]
            j1 += pi * on_l[i]
            j2 += pv * on_1[i]
            j3 += pi * on_1[i]
            j4 += pv * on_2[i]
            j5 += pi * on_2[i]
            j8 += pr[i] * on_2[i]
            t = dp_dr[i] * wi + pi * dwdr[i]
            j6 += t * dr_dr1[i]
            j7 += t * dr_drn[i]
            j9 -= pr[i] * wi
        y[k] = acc
        d[0], d[1], d[2], d[3], d[4], d[5] = j0, j1, j2, j3, j4, j5
        d[6], d[7], d[8], d[9], d[10] = j6, j7, j8, j9, acc / lam
        for c in range(11):
            if cols[c] >= 0:
                jac[k, cols[c]] = d[c]
    return y


@njit(cache=True)
def gather_rows(jac, first, sign, cols, at):  # pragma: no cover - compiled
    """``jac[:, first:first + q] = sign * cols[at]`` in one pass over ``at`` (``cols``
    shape (m, q), row-major: each source row read once; ``jac`` any layout, e.g. the
    column-ordered Jacobian LM takes). The same values as the fancy-indexed assignment."""
    q = cols.shape[1]
    for k in range(at.size):
        src = at[k]
        for j in range(q):
            jac[k, first + j] = sign * cols[src, j]


@njit(cache=True)
def run_index(v):  # pragma: no cover - compiled
    """(the first value of every run of equal consecutive samples, the run index of
    every sample), one pass over ``v`` (float (n,)): as ``v[new]`` and
    ``cumsum(new) - 1`` with ``new`` the samples that differ from the one before."""
    n = v.size
    idx = np.empty(n, dtype=np.int64)
    vals = np.empty(n)
    r = -1
    for k in range(n):
        if k == 0 or v[k] != v[k - 1]:
            r += 1
            vals[r] = v[k]
        idx[k] = r
    return vals[: r + 1].copy(), idx


@njit(cache=True)
def ordered_sum(a):  # pragma: no cover - compiled
    """Sum of ``a`` (float (n,)) in index order, one addition after another: the same
    bits wherever the array sits in memory (numpy's ``sum`` takes SIMD steps whose
    split depends on the array's alignment, so two copies of one array can sum to
    values a few ulps apart, and a fit's search, which compares costs, then depended on
    the process's history)."""
    s = 0.0
    for k in range(a.size):
        s += a[k]
    return s
