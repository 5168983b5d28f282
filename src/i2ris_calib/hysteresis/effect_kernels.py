"""Sequential state loops of the effect catalogue, compiled with numba.

Each loop runs once per model evaluation and the diagnosis evaluates models a few
thousand times, so the loops are compiled (``cache=True``: compiled once per
machine). All inputs are float64 arrays of shape (n,).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def play_varying(v, h):
    """Play (backlash) operator with a time-varying half-width.

    ``u[k] = clip(u[k-1], v[k] - h[k], v[k] + h[k])``, ``u[-1] = v[0]``.

    Parameters
    ----------
    v : ndarray, shape (n,)
        Input (counts).
    h : ndarray, shape (n,)
        Half-width of the band, >= 0 (counts).

    Returns
    -------
    ndarray, shape (n,)
        Output of the operator (counts).
    """
    n = v.shape[0]
    u = np.empty(n)
    prev = v[0] if n > 0 else 0.0
    for k in range(n):
        lo = v[k] - h[k]
        hi = v[k] + h[k]
        cur = prev
        if cur < lo:
            cur = lo
        elif cur > hi:
            cur = hi
        u[k] = cur
        prev = cur
    return u


@njit(cache=True)
def staged_backlash(v, v_flag, width):
    """Input seen through one more backlash stage engaged below a flag point.

    A slack ``d`` in [0, width] (counts) is taken up while the input falls at or
    below ``v_flag`` and given back while it rises; the stage's output is
    ``u = v + d``. So on a falling branch the output holds for ``width`` counts
    once the input passes ``v_flag`` (the extra dead zone of the stage), and the
    next rising branch first pays the slack back.

    Parameters
    ----------
    v : ndarray, shape (n,)
        Input (counts).
    v_flag, width : float
        Flag point and slack of the stage (counts).

    Returns
    -------
    ndarray, shape (n,)
        Effective input (counts).
    """
    n = v.shape[0]
    u = np.empty(n)
    d = 0.0
    for k in range(n):
        if k > 0:
            dv = v[k] - v[k - 1]
            if dv < 0.0 and v[k] <= v_flag:
                # only the part of the step below the flag point feeds the slack
                step = min(-dv, v_flag - v[k])
                d = min(width, d + step)
            elif dv > 0.0:
                d = max(0.0, d - dv)
        u[k] = v[k] + d
    return u


@njit(cache=True)
def first_order_lag(y, t, tau):
    """First-order low-pass of ``y`` sampled at times ``t`` (exact for held input).

    ``x[k] = x[k-1] + (1 - exp(-(t[k]-t[k-1])/tau)) (y[k] - x[k-1])``, ``x[0] = y[0]``.

    Parameters
    ----------
    y : ndarray, shape (n,)
    t : ndarray, shape (n,)
        Sample times (s), non-decreasing.
    tau : float
        Time constant (s), > 0.
    """
    n = y.shape[0]
    x = np.empty(n)
    if n == 0:
        return x
    x[0] = y[0]
    for k in range(1, n):
        a = 1.0 - np.exp(-(t[k] - t[k - 1]) / tau)
        x[k] = x[k - 1] + a * (y[k] - x[k - 1])
    return x


def lag_sum(y, t, taus):
    """Sum over time constants of :func:`first_order_lag` of every column of ``y``.

    ``out[:, c] = sum_j first_order_lag(y[:, c], t, taus[j])``, added in the order of
    ``taus`` with the same arithmetic, so one column equals ``sum(first_order_lag(y,
    t, tau) for tau in taus)`` to the last bit.

    Parameters
    ----------
    y : ndarray, shape (n, m)
    t : ndarray, shape (n,)
        Sample times (s), non-decreasing.
    taus : ndarray, shape (q,)
        Time constants (s), > 0.

    Returns
    -------
    ndarray, shape (n, m)
    """
    return lag_sum_with(y, lag_coefficients(t, taus))


@njit(cache=True)
def lag_coefficients(t, taus):
    """Step coefficients ``a[k, j] = 1 - exp(-(t[k] - t[k-1]) / taus[j])`` of
    :func:`first_order_lag` (the same arithmetic), shape (n, q); row 0 is 0.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Sample times (s), non-decreasing.
    taus : ndarray, shape (q,)
        Time constants (s), > 0.
    """
    n = t.shape[0]
    q = taus.shape[0]
    a = np.zeros((n, q))
    for k in range(1, n):
        for j in range(q):
            a[k, j] = 1.0 - np.exp(-(t[k] - t[k - 1]) / taus[j])
    return a


@njit(cache=True)
def lag_sum_with(y, a):
    """:func:`lag_sum` from its coefficients ``a`` (:func:`lag_coefficients`,
    shape (n, q)); ``y`` shape (n, m); returns shape (n, m)."""
    n, m = y.shape
    q = a.shape[1]
    out = np.zeros((m, n))  # transposed: each column's loop writes contiguously
    x = np.empty(q)
    for c in range(m):
        if n == 0:
            break
        acc = 0.0
        for j in range(q):
            x[j] = y[0, c]
            acc += x[j]
        out[c, 0] = acc
        for k in range(1, n):
            yk = y[k, c]
            acc = 0.0
            for j in range(q):  # the q lags are independent chains: run side by side
                x[j] = x[j] + a[k, j] * (yk - x[j])
                acc += x[j]
            out[c, k] = acc
    return out.T
