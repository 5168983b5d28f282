"""Independent reference implementations and inputs for the hysteresis tests."""

from __future__ import annotations

import numpy as np


def play_reference(v, gl, gr, r, ml=1.0, mr=1.0):
    """One generalized play operator, written directly from Eq1-2 (pure Python).

    ``gl``, ``gr`` are callables; initial state 0 clamped into the band (docs/models.md).
    """
    w = min(max(0.0, gl(v[0]) - ml * r), gr(v[0]) + mr * r)
    out = [w]
    for k in range(1, len(v)):
        if v[k] > v[k - 1]:
            w = max(gl(v[k]) - ml * r, w)
        elif v[k] < v[k - 1]:
            w = min(gr(v[k]) + mr * r, w)
        out.append(w)
    return np.array(out)


def gpi_reference(v, a1, a2, a3, a4, lam, sigma, r1, rn, n):
    """GPI output from Eq3/14/15 with :func:`play_reference` operators."""
    r = [0.0] + [r1 + (i - 1) * (rn - r1) / (n - 1) for i in range(1, n + 1)]
    y = np.zeros(len(v))
    for ri in r:
        y += (
            lam
            * np.exp(-sigma * ri)
            * play_reference(v, lambda x: a1 * x + a2, lambda x: a3 * x + a4, ri)
        )
    return y


def triangle(levels, step=7.0):
    """Piecewise-linear input through the given turning levels (counts)."""
    parts = [np.array([levels[0]], dtype=float)]
    for a, b in zip(levels[:-1], levels[1:], strict=True):
        n = max(2, int(abs(b - a) / step) + 1)
        parts.append(np.linspace(a, b, n)[1:])
    return np.concatenate(parts)


def refine(v, rng, max_insert=3):
    """Insert holds and intermediate points on each monotone step of ``v`` (the same
    input path, sampled more finely): return (v', the indices of v's samples in v')."""
    out, kept = [v[0]], [0]
    for k in range(1, v.size):
        for _ in range(rng.integers(0, max_insert + 1)):
            out.append(out[-1])  # hold
        lo, hi = v[k - 1], v[k]
        for x in np.sort(rng.uniform(0, 1, rng.integers(0, max_insert + 1))):
            out.append(lo + x * (hi - lo))  # monotone intermediate value
        out.append(v[k])
        kept.append(len(out) - 1)
    return np.array(out), np.array(kept)
