"""The motor rate limit of compensation: the fastest input move a recording shows
(computed when the fit is written, fit.json ``max_input_rate_counts_per_s``) and the
limit an axis is inverted with (an explicit one, the configured one, the recording's,
or a fallback share of the fitted range).

Pure numbers (no files, no printing); docs/compensate.md ("Safe by default").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from i2ris_calib.errors import CalibError

#: Percentile of |dv/dt| over the moving samples taken as a recording's fastest input
#: move (robust to a few glitches, :func:`max_input_rate`)
RATE_PERCENTILE = 99.0
#: Rate limit when fit.json does not store the recording's fastest input move (older
#: files): this share of the fitted input range per second
FALLBACK_RANGE_SHARE_PER_S = 0.1


def max_input_rate(v: np.ndarray, t_s: np.ndarray) -> float | None:
    """The fastest input move of a recording (input unit per s): the
    :data:`RATE_PERCENTILE` percentile of ``|dv/dt|`` over the samples where the input
    moves; None when it never moves (or has fewer than 2 samples).

    Parameters
    ----------
    v : ndarray, shape (n,)
        Input (encoder counts).
    t_s : ndarray, shape (n,)
        Sample times (s), increasing.
    """
    v = np.asarray(v, dtype=float)
    t = np.asarray(t_s, dtype=float)
    if v.size < 2 or t.size != v.size:
        return None
    dv = np.abs(np.diff(v))
    dt = np.diff(t)
    ok = (dv > 0) & (dt > 0) & np.isfinite(dv) & np.isfinite(dt)
    if not ok.any():
        return None
    return float(np.percentile(dv[ok] / dt[ok], RATE_PERCENTILE))


@dataclass(frozen=True)
class RateLimit:
    """The rate limit an axis is inverted with.

    Attributes
    ----------
    counts_per_s : float
        The limit (counts/s; ``inf``: none).
    source : str
        Where it comes from (the option, the config key, fit.json, ``fallback``).
    warning : str or None
        A line to show (the fallback of an older fit.json), or None.
    """

    counts_per_s: float
    source: str
    warning: str | None = None


def rate_limit(
    recorded: float | None,
    explicit: float | None,
    configured: float,
    range_counts: float,
    dataset: str,
    option: str = "--max-counts-per-s",
) -> RateLimit:
    """The rate limit of one axis.

    ``explicit`` (the ``option``, ``--max-counts-per-s`` or ``max_counts_per_s=``) wins,
    then ``configured`` (``[compensate] max_counts_per_s``, 0 = not set); ``inf`` means
    no limit. Otherwise ``recorded``, the fastest input move of the fit's recording
    (fit.json ``max_input_rate_counts_per_s``, :func:`max_input_rate`); a fit without it
    (older files, None) falls back to :data:`FALLBACK_RANGE_SHARE_PER_S` of the fitted
    input range ``range_counts`` per second, with a warning naming ``dataset``. A rate
    that is not > 0 is a one-line CalibError.
    """
    for value, source in ((explicit, option.rstrip("=")),
                          (configured or None, "[compensate] max_counts_per_s")):  # fmt: skip
        if value is not None:
            if not float(value) > 0:
                raise CalibError(f"{source} = {value:g}: give a rate > 0 counts/s (inf: no limit)")
            return RateLimit(float(value), source)
    if recorded is not None and float(recorded) > 0:
        return RateLimit(
            float(recorded), "fit.json max_input_rate_counts_per_s (the recording's fastest move)"
        )
    rate = FALLBACK_RANGE_SHARE_PER_S * range_counts
    return RateLimit(
        rate,
        "fallback",
        f"{dataset}: fit.json has no max_input_rate_counts_per_s (written by an older "
        f"'fit'); rate limit {rate:g} counts/s ({FALLBACK_RANGE_SHARE_PER_S:g} of the fitted "
        f"input range per second): re-run 'fit' or give {option}",
    )
