"""Does each tracked angle follow its own motor? (a check on synced data)

Swapped ``view`` labels in session.toml (yaw and pitch exchanged by the tracking) or
swapped encoder columns give synced data in which each angle follows the *other*
motor. The fits would still run; this check says so before they do.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from i2ris_calib.data.dataset import AXES as AXIS_NAMES
from i2ris_calib.data.dataset import other_axis

#: (axis, angle column, encoder column) of each bending axis in angles.csv / synced.csv:
#: the one definition the sync stage uses
AXES = tuple((a, f"{a}_deg", f"enc_{a}") for a in AXIS_NAMES)
#: rows between the two ends of a step
LAG = 3
#: an angle "follows the other motor" when |step correlation| with it exceeds this ...
MIN_FOLLOW = 0.5
#: ... and exceeds the one with its own motor by this margin
MARGIN = 0.2


def _step_corr(x: np.ndarray, y: np.ndarray) -> float:
    """|Pearson correlation| of two series' steps (NaN if either does not move).

    Steps (differences over ``LAG`` rows) rather than levels: one motor resting at
    zero while the other moves must not look like a relation between them.
    """
    dx, dy = x[LAG:] - x[:-LAG], y[LAG:] - y[:-LAG]
    ok = np.isfinite(dx) & np.isfinite(dy)
    dx, dy = dx[ok], dy[ok]
    if dx.size < 10 or np.ptp(dx) == 0 or np.ptp(dy) == 0:
        return float("nan")
    return float(abs(np.corrcoef(dx, dy)[0, 1]))


def axis_check(table: pd.DataFrame) -> dict:
    """Correlation of each angle's steps with its own and the other motor's steps.

    Parameters
    ----------
    table : DataFrame
        Synced table with ``yaw_deg``, ``pitch_deg``, ``enc_yaw``, ``enc_pitch``,
        ``status`` (one row per frame; only ``measured`` rows are used).

    Returns
    -------
    dict
        ``{axis: {"own": r, "other": r}}`` (|Pearson| of the steps over ``LAG`` rows,
        unmeasured frames NaN; None when the motor or the angle does not move) and
        ``swapped_axes``: the axes whose angle follows the other motor (r_other > 0.5
        and > r_own + 0.2). An axis whose own motor never moves is not judged
        (cross-talk from the other motor is normal).
    """
    measured = table["status"].astype(str).to_numpy() == "measured"
    out: dict = {}
    swapped = []
    for axis, ang, own in AXES:
        other = f"enc_{other_axis(axis)}"
        th = pd.to_numeric(table[ang], errors="coerce").to_numpy(float)
        e_own = pd.to_numeric(table[own], errors="coerce").to_numpy(float)
        e_other = pd.to_numeric(table[other], errors="coerce").to_numpy(float)
        th = np.where(measured, th, np.nan)
        r_own = _step_corr(th, e_own)
        r_other = _step_corr(th, e_other)
        out[axis] = {
            "own": None if np.isnan(r_own) else round(r_own, 4),
            "other": None if np.isnan(r_other) else round(r_other, 4),
        }
        if np.isfinite(r_own) and np.isfinite(r_other):
            if r_other > MIN_FOLLOW and r_other > r_own + MARGIN:
                swapped.append(axis)
    out["swapped_axes"] = swapped
    return out
