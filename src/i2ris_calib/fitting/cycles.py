"""Loading-cycle detection and the held-out split by cycles."""

from __future__ import annotations

import numpy as np

from i2ris_calib.hysteresis.kernel import motion_direction


def default_deadband(v: np.ndarray, fraction: float = 0.01) -> float:
    """Dead band (counts) for ``v'``: ``fraction`` of the input range, at least 1 count."""
    v = np.asarray(v, dtype=float)
    return max(1.0, fraction * float(np.ptp(v))) if v.size else 1.0


def cycle_index(v: np.ndarray, deadband: float | None = None) -> np.ndarray:
    """Loading-cycle number of every sample, int array (n,), starting at 0.

    A new cycle starts at the input minimum where the motion direction (``v'`` with
    a dead band, see :func:`~i2ris_calib.hysteresis.kernel.motion_direction`) turns
    from unloading to loading. ``deadband`` defaults to 1 % of the input range.
    """
    v = np.ascontiguousarray(v, dtype=float)
    if v.size == 0:
        return np.zeros(0, dtype=int)
    db = default_deadband(v) if deadband is None else float(deadband)
    d = motion_direction(v, db).astype(int)
    turns_up = np.flatnonzero((d[1:] > 0) & (d[:-1] < 0)) + 1
    turns_down = np.flatnonzero((d[1:] < 0) & (d[:-1] > 0)) + 1
    marks = np.zeros(v.size, dtype=int)
    for s in turns_up:
        # the cycle starts at the minimum reached since unloading began
        down = turns_down[turns_down < s]
        lo = int(down[-1]) if down.size else 0
        marks[lo + int(np.argmin(v[lo:s]))] += 1
    return np.cumsum(marks)


def holdout_mask(cycles: np.ndarray, fraction: float = 0.25) -> np.ndarray:
    """Samples held out for validation: whole cycles, evenly spread, never cycle 0.

    ``max(1, round(fraction * n_cycles))`` cycles out of 1..n_cycles-1 are held out
    (deterministic, evenly spaced). With fewer than 2 cycles, or ``fraction <= 0``,
    nothing is held out. The model is still evaluated over the whole input sequence
    (the operator state needs every sample); held-out angles only leave the loss.

    Returns
    -------
    ndarray of bool, shape (n,)
        True for held-out samples.
    """
    cycles = np.asarray(cycles, dtype=int)
    n_cyc = int(cycles.max()) + 1 if cycles.size else 0
    if n_cyc < 2 or fraction <= 0:
        return np.zeros(cycles.shape, dtype=bool)
    k = int(min(n_cyc - 1, max(1, round(fraction * n_cyc))))
    if k >= n_cyc - 1:
        chosen = np.arange(1, n_cyc)
    else:
        chosen = np.unique(np.round(np.linspace(1, n_cyc - 1, k + 2)[1:-1]).astype(int))
    return np.isin(cycles, chosen)
