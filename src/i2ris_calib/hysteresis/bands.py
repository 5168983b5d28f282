"""Input bands: the input's noise, the zero band and the ``v'`` dead band.

In the input's own unit (counts or volts): a negative setting means "derive from the
input" (:func:`input_bands`). The dead band is the models' (the EGPI output switch and
the cycle turns, :func:`~i2ris_calib.hysteresis.kernel.motion_direction`); the zero band
attributes samples to a motion direction (:mod:`i2ris_calib.data.dataset`). Here, below
the data layer, so that the models' data-driven starts can use them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Bands", "input_bands", "input_noise"]


@dataclass(frozen=True)
class Bands:
    """Input bands (unit of the input) and how they were chosen.

    Attributes
    ----------
    noise : float
        Robust input noise sd (from second differences), input unit.
    zero_band : float
        ``|input| <= zero_band`` is "at rest near zero" (direction attribution only).
    deadband : float
        Dead band of ``v'`` (EGPI output switch, cycle turns), input unit.
    derived : tuple of str
        Names of the bands derived from the input (not configured).
    """

    noise: float
    zero_band: float
    deadband: float
    derived: tuple[str, ...] = ()


def input_noise(v: np.ndarray) -> float:
    """Robust sd of the input's sample-to-sample noise (input unit), >= 0.

    ``1.4826 * MAD(diff2) / sqrt(6)``: white noise of sd s has second differences of
    sd ``s sqrt(6)``; smooth motion contributes almost nothing to the median.
    """
    v = np.asarray(v, dtype=float)
    v = v[np.isfinite(v)]
    if v.size < 4:
        return 0.0
    d2 = np.diff(v, 2)
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6.0))


def input_bands(enc: np.ndarray, zero_band: float = -1.0, deadband: float = -1.0) -> Bands:
    """Bands for input ``enc`` (any unit); a negative setting is derived from the input.

    * ``deadband`` = max(3 x input noise sd, 3e-4 x max |input|): above the jitter,
      and as small as the data allow (a wide band delays the EGPI switch back to
      loading at a turning point). Encoder counts up to 6000 counts: 1.8 counts.
    * ``zero_band`` = max(3 x input noise sd, 0.5 % of max |input|).
    """
    e = np.asarray(enc, dtype=float)
    e = e[np.isfinite(e)]
    noise = input_noise(e)
    span = float(np.ptp(e)) if e.size else 0.0
    peak = float(np.max(np.abs(e))) if e.size else 0.0
    derived = []
    if deadband < 0:
        deadband = max(3.0 * noise, 3e-4 * (peak if peak > 0 else span))
        derived.append("deadband")
    if zero_band < 0:
        zero_band = max(3.0 * noise, 5e-3 * peak)
        derived.append("zero_band")
    return Bands(noise, float(zero_band), float(deadband), tuple(derived))
