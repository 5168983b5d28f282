"""Loading-cycle detection and the held-out split by cycles."""

from __future__ import annotations

import numpy as np

from i2ris_calib.hysteresis.kernel import motion_direction


def cycle_deadband(v: np.ndarray, fraction: float = 0.01) -> float:
    """Dead band (input unit) for ``v'`` in cycle detection: ``fraction`` of the input
    range (unit free: the same cycles for counts and volts)."""
    v = np.asarray(v, dtype=float)
    span = float(np.ptp(v)) if v.size else 0.0
    return fraction * span if span > 0 else 1.0


def cycle_index(v: np.ndarray, deadband: float | None = None) -> np.ndarray:
    """Loading-cycle number of every sample, int array (n,), starting at 0.

    A new cycle starts at the input minimum where the motion direction (``v'`` with
    a dead band, see :func:`~i2ris_calib.hysteresis.kernel.motion_direction`) turns
    from unloading to loading. ``deadband`` defaults to 1 % of the input range
    (:func:`cycle_deadband`).
    """
    v = np.ascontiguousarray(v, dtype=float)
    if v.size == 0:
        return np.zeros(0, dtype=int)
    db = cycle_deadband(v) if deadband is None else float(deadband)
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


def holdout_mask(
    cycles: np.ndarray, fraction: float = 0.25, v: np.ndarray | None = None
) -> np.ndarray:
    """Samples held out for validation: whole loading cycles, evenly spread.

    ``max(1, round(fraction * n_cycles))`` cycles are held out among the eligible ones:
    never cycle 0 (it carries the initial operator state), and - when the input ``v``
    is given - only cycles whose input range lies within the range of the cycles left
    for fitting (a held-out cycle must test interpolation, not extrapolation beyond the
    fitted input range). With fewer than 2 cycles, ``fraction <= 0`` or no eligible
    cycle, nothing is held out. The model is still evaluated over the whole input
    sequence (the operator state needs every sample); held-out angles only leave the loss.

    Returns
    -------
    ndarray of bool, shape (n,)
        True for held-out samples.
    """
    cycles = np.asarray(cycles, dtype=int)
    n_cyc = int(cycles.max()) + 1 if cycles.size else 0
    none = np.zeros(cycles.shape, dtype=bool)
    if n_cyc < 2 or fraction <= 0:
        return none
    eligible = np.arange(1, n_cyc)
    if v is not None:
        v = np.asarray(v, dtype=float)
        hi = np.array([v[cycles == c].max() for c in range(n_cyc)])
        lo = np.array([v[cycles == c].min() for c in range(n_cyc)])
        eligible = np.array(
            [
                c
                for c in eligible
                if hi[c] <= np.delete(hi, c).max() and lo[c] >= np.delete(lo, c).min()
            ],
            dtype=int,
        )
    if eligible.size == 0:
        return none
    k = int(min(eligible.size, max(1, round(fraction * n_cyc))))
    picks = np.unique(np.round(np.linspace(0, eligible.size - 1, k + 2)[1:-1]).astype(int))
    if picks.size < k:  # two evenly spread picks rounded to one cycle: spread k distinct
        picks = np.floor((np.arange(k) + 0.5) * eligible.size / k).astype(int)
    chosen = eligible if k >= eligible.size else eligible[picks]
    return np.isin(cycles, chosen)
