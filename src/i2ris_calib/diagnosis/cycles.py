"""Held-out units of the paired evidence and loading branches, from the one segmentation.

The diagnosis has no segmentation of its own. Loading cycles are the fitting
stage's (:func:`i2ris_calib.data.cycles.cycle_index`, the same call that chose
the dataset's held-out cycles in :func:`i2ris_calib.data.dataset.make_dataset`),
and the loading/unloading branch of a sample is the model's own ``v'``
(:func:`i2ris_calib.hysteresis.kernel.motion_direction` with the dataset's dead band).
"""

from __future__ import annotations

import numpy as np

from i2ris_calib.data.cycles import cycle_index
from i2ris_calib.hysteresis.kernel import motion_direction


def dataset_cycles(v: np.ndarray) -> np.ndarray:
    """Loading-cycle number of every sample of a dataset's input ``v``, int (n,).

    Exactly the cycles its held-out mask was drawn from
    (:func:`~i2ris_calib.data.cycles.cycle_index` with its default dead band).
    """
    return cycle_index(np.asarray(v, dtype=float), None)


def loading_mask(v: np.ndarray, deadband: float) -> np.ndarray:
    """True where the input is loading (``v' > 0`` with dead band ``deadband``, input
    unit), bool (n,): the branch the hysteresis model itself sees."""
    v = np.ascontiguousarray(v, dtype=float)
    return np.asarray(motion_direction(v, float(deadband))) > 0


def holdout_units(cycles: np.ndarray, holdout: np.ndarray, min_units: int = 6) -> np.ndarray:
    """Unit label of each held-out sample for the per-unit count (-1 elsewhere), int (n,).

    Units are the held-out loading cycles (``cycles``, restricted to ``holdout``);
    while there are fewer than ``min_units`` units, every unit is cut into two
    halves (by sample order), at most 4 times.

    Parameters
    ----------
    cycles : ndarray of int, shape (n,)
        Loading-cycle number of every sample (:func:`dataset_cycles`).
    holdout : ndarray of bool, shape (n,)
        Held-out samples that count (in direction, angle measured).
    """
    units = np.where(np.asarray(holdout, dtype=bool), np.asarray(cycles, dtype=int), -1)
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
