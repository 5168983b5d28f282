"""Is a time column an epoch clock read in the wrong unit? (issue 33, item 5)

Seconds since 1970 read with ``time_unit_s = 0.001`` become 1.7e6 s (20 January 1970)
and every step 1000x shorter: 5 Hz data is taken as 5 kHz, and every rate derived
from it (fit.json's input rate, compensate's safety limit) is 1000x too high. An
epoch clock's first time, in the unit given, must fall in :data:`EPOCH_DATES_S`; when it
does not but would in another unit, the unit is wrong.
"""

from __future__ import annotations

import datetime as _dt

__all__ = ["EPOCH_DATES_S", "EPOCH_MIN_S", "epoch_unit_problem"]

#: a first time at or above this (s) is an epoch clock (1970 + 11.6 days or later, no
#: recording's own clock)
EPOCH_MIN_S = 1e6
#: the first time (s since 1970) of a recording on an epoch clock: 2000-01-01 .. 2100-01-01
EPOCH_DATES_S = (946_684_800.0, 4_102_444_800.0)
#: the units an epoch clock is counted in, seconds per unit
_UNITS = ((1.0, "s"), (1e-3, "ms"), (1e-6, "us"), (1e-9, "ns"))


def _date(seconds: float) -> str:
    try:
        return _dt.datetime.fromtimestamp(seconds, tz=_dt.timezone.utc).date().isoformat()
    except (OverflowError, OSError, ValueError):
        return "after the year 9999" if seconds > 0 else "before the year 1"


def epoch_unit_problem(first_raw: float, step_raw: float | None, unit_s: float) -> str | None:
    """Why ``unit_s`` (s per unit) is wrong for a time column starting at ``first_raw``
    (as written in the file) with median step ``step_raw`` (same unit; None: one
    sample), or None when it is plausible.

    Wrong: the first time in seconds (``first_raw * unit_s``) is an epoch clock
    (>= :data:`EPOCH_MIN_S`) outside :data:`EPOCH_DATES_S` while another unit puts it
    inside. The reason names both readings (date and sample rate) and the unit that
    fits, e.g. ``"starts at 1.7e+09: with time unit 0.001 s that is 1970-01-20 at
    5000 Hz; as epoch s it is 2023-11-14 at 5 Hz: the unit is 1 s"``.
    """
    origin = float(first_raw) * unit_s
    lo, hi = EPOCH_DATES_S
    if not abs(origin) >= EPOCH_MIN_S or lo <= origin <= hi:
        return None
    for unit, name in _UNITS:
        if unit != unit_s and lo <= float(first_raw) * unit <= hi:
            now = then = ""
            if step_raw is not None and step_raw > 0:
                now = f" at {1.0 / (step_raw * unit_s):.4g} Hz"
                then = f" at {1.0 / (step_raw * unit):.4g} Hz"
            return (
                f"starts at {first_raw:.10g}: with time unit {unit_s:g} s that is "
                f"{_date(origin)}{now}; as epoch {name} it is {_date(first_raw * unit)}{then}"
                f": the unit is {unit:g} s"
            )
    return None
