"""Strokes and loading cycles, and the held-out units of the paired evidence.

A *stroke* is a monotone run of the input between two reversals; a *loading
cycle* is a rising stroke followed by the falling stroke after it (minimum to
minimum). Reversals are found with a zig-zag rule: a new extremum is confirmed
once the input has moved ``min_travel`` away from it, so encoder jitter and
holds do not create spurious strokes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def reversal_indices(v: np.ndarray, min_travel: float) -> np.ndarray:
    """Indices of confirmed extrema of ``v`` (zig-zag with threshold ``min_travel``).

    Parameters
    ----------
    v : ndarray, shape (n,)
        Input (counts).
    min_travel : float
        Travel (counts) away from an extremum needed to confirm it.

    Returns
    -------
    ndarray of int, shape (m,)
        Sample index of each confirmed extremum, increasing.
    """
    v = np.asarray(v, float)
    out: list[int] = []
    direction, hi, lo, ext = 0, 0, 0, 0
    for k in range(1, v.size):
        if direction == 0:
            hi = k if v[k] > v[hi] else hi
            lo = k if v[k] < v[lo] else lo
            if v[hi] - v[lo] >= min_travel:
                first, direction, ext = (lo, 1, hi) if hi > lo else (hi, -1, lo)
                if first > 0:
                    out.append(first)
        elif direction > 0:
            if v[k] >= v[ext]:
                ext = k
            elif v[ext] - v[k] >= min_travel:
                out.append(ext)
                direction, ext = -1, k
        else:
            if v[k] <= v[ext]:
                ext = k
            elif v[k] - v[ext] >= min_travel:
                out.append(ext)
                direction, ext = 1, k
    return np.array(out, dtype=int)


@dataclass(frozen=True)
class Segmentation:
    """Per-sample stroke and cycle labels.

    Attributes
    ----------
    stroke : ndarray of int, shape (n,)
        Stroke number of each sample (0-based, increasing with time).
    cycle : ndarray of int, shape (n,)
        Loading-cycle number (a new cycle starts at every input minimum).
    rising : ndarray of bool, shape (n,)
        True on rising strokes.
    """

    stroke: np.ndarray
    cycle: np.ndarray
    rising: np.ndarray


def segment(v: np.ndarray, min_travel_frac: float = 0.05) -> Segmentation:
    """Label strokes and loading cycles of input ``v`` (shape (n,), counts).

    ``min_travel_frac`` is the zig-zag threshold as a fraction of the input span.
    """
    v = np.asarray(v, float)
    span = float(np.ptp(v)) if v.size else 0.0
    rev = reversal_indices(v, max(min_travel_frac * span, 1e-12))
    stroke = np.zeros(v.size, dtype=int)
    for r in rev:
        stroke[r + 1 :] += 1
    bounds = np.concatenate([[0], rev + 1, [v.size]])
    rising = np.zeros(v.size, dtype=bool)
    for s in range(bounds.size - 1):
        a, b = bounds[s], bounds[s + 1]
        if b > a:
            rising[a:b] = v[b - 1] >= v[a] if b - a > 1 else (s > 0 and v[a] >= v[a - 1])
    # a cycle starts at each rising stroke (after a minimum)
    starts = np.zeros(v.size, dtype=bool)
    starts[1:] = rising[1:] & ~rising[:-1]
    cycle = np.cumsum(starts)
    return Segmentation(stroke=stroke, cycle=cycle, rising=rising)


def holdout_units(seg: Segmentation, holdout: np.ndarray, min_units: int = 6) -> np.ndarray:
    """Unit label of each held-out sample for the paired test (-1 elsewhere).

    Units are the held-out strokes; while there are fewer than ``min_units``
    units, every unit is cut into two contiguous halves.

    Returns
    -------
    ndarray of int, shape (n,)
    """
    units = np.where(holdout, seg.stroke, -1)
    for _ in range(4):
        labels = np.unique(units[units >= 0])
        if labels.size >= min_units:
            break
        new = np.full_like(units, -1)
        nxt = 0
        for lab in labels:
            idx = np.flatnonzero(units == lab)
            half = idx.size // 2
            if half == 0:
                new[idx] = nxt
                nxt += 1
                continue
            new[idx[:half]] = nxt
            new[idx[half:]] = nxt + 1
            nxt += 2
        units = new
    return units
