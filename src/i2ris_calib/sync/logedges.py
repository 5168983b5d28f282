"""LED edges of the logged ``sync_flash`` channel (controller clock)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from i2ris_calib.sync.edgetime import TIME_FLOOR_S
from i2ris_calib.sync.log import Channel


@dataclass(frozen=True)
class LogEdge:
    """One logged LED edge: it lies in ``[t_lo_s, t_hi_s]`` (uniform), controller clock.

    Attributes
    ----------
    t_s : float
        Edge time (middle of the interval), s.
    sd_s : float
        Standard deviation of ``t_s`` (the interval's width / sqrt(12), floored), s.
    rising : bool
        True for LED on, False for LED off.
    t_lo_s, t_hi_s : float
        The interval the edge is known to lie in, s.
    """

    t_s: float
    sd_s: float
    rising: bool
    t_lo_s: float
    t_hi_s: float

    @classmethod
    def at(cls, t_s: float, rising: bool, sd_s: float = TIME_FLOOR_S) -> LogEdge:
        """An edge known to ``sd_s`` around ``t_s`` (interval +-sqrt(3) sd)."""
        h = float(np.sqrt(3.0) * sd_s)
        return cls(float(t_s), float(sd_s), bool(rising), t_s - h, t_s + h)


def log_edges(flash: Channel, at: str) -> list[LogEdge]:
    """LED edges of the logged ``sync_flash`` channel (controller clock).

    ``at="first_on"``: the edge is at the first sample with the new state (the
    controller logs the tick at which it switched the LED); ``"midpoint"``: half
    way between the two samples, with a uniform uncertainty over the interval.
    """
    v = flash.values > 0
    k = np.flatnonzero(v[1:] != v[:-1]) + 1
    edges = []
    for i in k:
        t0, t1 = float(flash.t_s[i - 1]), float(flash.t_s[i])
        lo = t0 if at == "midpoint" else t1
        sd = (t1 - lo) / np.sqrt(12.0)
        edges.append(
            LogEdge(0.5 * (lo + t1), max(sd, TIME_FLOOR_S), bool(v[i]), t_lo_s=lo, t_hi_s=t1)
        )
    return edges
