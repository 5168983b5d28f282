"""The encoder log as arrays (controller clock), its validation and interpolation.

Each channel (``enc_yaw``, ``enc_pitch``, optional ``sync_flash``) has its own sample
times, because ROS bags log each motor on its own topic; a CSV log simply shares one
time column between them.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
from scipy.ndimage import median_filter

from i2ris_calib.errors import CalibError

ENCODER_CHANNELS = ("enc_yaw", "enc_pitch")

#: without ``[encoder] max_counts_per_s`` the motor's speed limit is this many times the
#: 99th percentile of the log's own per-sample speed (|change| / interval)
GLITCH_SPEED_FACTOR = 10.0
#: half-width (samples) of the running median a glitch is measured against: up to this
#: many consecutive bad samples are recognised as one glitch
GLITCH_HALF_WINDOW = 5
#: encoder rates a log can plausibly have, Hz (the documented logs run at 100 Hz-1 kHz)
PLAUSIBLE_RATE_HZ = (10.0, 100_000.0)


@dataclass(frozen=True)
class Channel:
    """One logged signal.

    Attributes
    ----------
    t_s : ndarray, shape (n,)
        Sample times, controller clock, s, strictly increasing.
    values : ndarray, shape (n,)
        Sample values (encoder counts, or 0/1 for the sync flash).
    """

    t_s: np.ndarray
    values: np.ndarray

    @cached_property
    def with_corners(self) -> tuple[np.ndarray, np.ndarray]:
        """Sample times and values with the corners of piecewise-linear motion added
        (:func:`corner_knots`), sorted: the knots of :meth:`EncoderLog.interpolate`."""
        tk, vk = corner_knots(self.t_s, self.values)
        t = np.concatenate([self.t_s, tk])
        v = np.concatenate([self.values.astype(float), vk])
        order = np.argsort(t, kind="stable")
        return t[order], v[order]


#: smallest tolerance (counts) of the straight-line test of :func:`corner_knots`: a line of
#: whole counts has second differences of at most 1
CORNER_MIN_TOL_COUNTS = 1.5


def corner_knots(t_s: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Corners of piecewise-linear motion that fall between two samples.

    A motor moving at constant speed that reverses or stops between two samples has its
    corner cut by linear interpolation (up to half a sample interval times the change of
    speed: 8 counts at 100 Hz and 1600 counts/s). Where the three samples before an
    interval lie on one straight line and the three after it on another (second
    differences within a tolerance), the lines' speeds differ by more than twice the
    tolerance over the interval and the lines meet inside it, the meeting point is a
    corner. Smooth motion (accelerating over several samples) and noise fail the
    straight-line test and keep plain linear interpolation. The tolerance is the larger
    of :data:`CORNER_MIN_TOL_COUNTS` and 3 robust sd of the log's second differences.

    Parameters
    ----------
    t_s, values : ndarray, shape (n,)
        Sample times (s, increasing) and values (counts).

    Returns
    -------
    t_s, values : ndarray, shape (k,)
        The corners' times and values.
    """
    t = np.asarray(t_s, dtype=float)
    v = np.asarray(values, dtype=float)
    n = t.size
    if n < 6:
        return np.zeros(0), np.zeros(0)
    dt, dv = np.diff(t), np.diff(v)
    s = dv / dt
    d2 = dv[1:] - s[:-1] * dt[1:]  # sample k+2 off the line through samples k, k+1
    tol = max(CORNER_MIN_TOL_COUNTS, 3 * 1.4826 * float(np.median(np.abs(d2 - np.median(d2)))))
    k = np.arange(2, n - 3)  # interval k: line A through samples k-2..k, line B through k+1..k+3
    sa, sb = s[k - 1], s[k + 1]
    ok = (np.abs(d2[k - 2]) <= tol) & (np.abs(d2[k + 1]) <= tol)
    ok &= np.abs(sa - sb) * dt[k] > 2 * tol
    with np.errstate(divide="ignore", invalid="ignore"):
        tc = (v[k + 1] - v[k] - sb * t[k + 1] + sa * t[k]) / (sa - sb)
    ok &= (tc > t[k]) & (tc < t[k + 1])
    return tc[ok], v[k[ok]] + sa[ok] * (tc[ok] - t[k[ok]])


@dataclass(frozen=True)
class EncoderLog:
    """Encoder channels by name (``enc_yaw``, ``enc_pitch``) plus the optional flash.

    Attributes
    ----------
    channels : dict[str, Channel]
        Encoder channels, counts.
    flash : Channel or None
        ``sync_flash`` (1 while the sync LED is on), or None when not logged.
    source : str
        Where the log came from (for messages).
    interpolation : {"corners", "linear"}
        How :meth:`interpolate` fills between samples (``[sync] encoder_interpolation``).
    """

    channels: dict[str, Channel]
    flash: Channel | None = None
    source: str = ""
    meta: dict = field(default_factory=dict)
    interpolation: str = "corners"

    def time_range(self) -> tuple[float, float]:
        """(first, last) time, s, over which every encoder channel is defined."""
        lo = max(float(c.t_s[0]) for c in self.channels.values())
        hi = min(float(c.t_s[-1]) for c in self.channels.values())
        return lo, hi

    def shifted(self, dt_s: float) -> EncoderLog:
        """The same log with every time plus ``dt_s`` (recording-local clocks)."""
        return replace(
            self,
            channels={k: Channel(c.t_s + dt_s, c.values) for k, c in self.channels.items()},
            flash=None if self.flash is None else Channel(self.flash.t_s + dt_s, self.flash.values),
        )

    def interpolate(self, name: str, t_s: np.ndarray) -> np.ndarray:
        """Channel ``name`` at ``t_s`` (NaN outside its range): linear between samples,
        with the corners of piecewise-linear motion restored (:func:`corner_knots`)
        unless ``interpolation = "linear"``."""
        ch = self.channels[name]
        if self.interpolation == "linear":
            t, v = ch.t_s, ch.values.astype(float)
        else:
            t, v = ch.with_corners
        return np.interp(t_s, t, v, left=np.nan, right=np.nan)


def check_channel(t_s: np.ndarray, values: np.ndarray, name: str, where: str, max_gap_s: float):
    """Raise CalibError unless ``t_s`` is finite, strictly increasing and gap-free.

    Parameters
    ----------
    t_s, values : ndarray, shape (n,)
        Sample times (s) and values of one channel.
    name, where : str
        Channel name and source (file/topic) for the message.
    max_gap_s : float
        Longest allowed interval between consecutive samples, s.
    """
    if t_s.size < 2:
        raise CalibError(
            f"{where}: channel '{name}' has {t_s.size} sample(s); an encoder log needs at least 2"
        )
    bad = ~np.isfinite(t_s) | ~np.isfinite(values)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise CalibError(
            f"{where}: channel '{name}' has a missing/non-numeric value at sample {i} "
            "(remove or fix that row)"
        )
    dt = np.diff(t_s)
    if (dt < 0).any():
        i = int(np.flatnonzero(dt < 0)[0])
        raise CalibError(
            f"{where}: clock reset in '{name}': time goes back from {t_s[i]:.6f} s to "
            f"{t_s[i + 1]:.6f} s at sample {i + 1} (split the log at the reset and sync each part)"
        )
    if (dt == 0).any():
        i = int(np.flatnonzero(dt == 0)[0])
        raise CalibError(
            f"{where}: repeated timestamp {t_s[i]:.6f} s in '{name}' at sample {i + 1} "
            "(drop duplicate rows; timestamps must be strictly increasing)"
        )
    if (dt > max_gap_s).any():
        i = int(np.argmax(dt))
        raise CalibError(
            f"{where}: gap of {dt[i]:.3f} s in '{name}' after t = {t_s[i]:.6f} s (sample {i}), "
            f"longer than sync.max_gap_s = {max_gap_s:g} s (trim the log or raise sync.max_gap_s)"
        )


def time_unit_hint(t: np.ndarray) -> float | None:
    """Factor that would make the sample interval of ``t`` plausible, or None.

    A median interval slower than :data:`PLAUSIBLE_RATE_HZ` allows (e.g. 1 "s" for a
    1 kHz log whose times are in ms) that becomes plausible when scaled by 1e-3, 1e-6
    or 1e-9 returns that factor; otherwise None (including logs already plausible).

    Parameters
    ----------
    t : ndarray, shape (n,)
        Sample times as read (s under the configured unit).
    """
    dt = np.diff(np.asarray(t, dtype=float))
    dt = dt[np.isfinite(dt) & (dt > 0)]
    if dt.size == 0:
        return None
    step = float(np.median(dt))
    lo, hi = 1.0 / PLAUSIBLE_RATE_HZ[1], 1.0 / PLAUSIBLE_RATE_HZ[0]
    if step <= hi:
        return None
    for unit in (1e-3, 1e-6, 1e-9):
        if lo <= step * unit <= hi:
            return unit
    return None


def speed_limit(t_s: np.ndarray, values: np.ndarray, configured: float = 0.0) -> float:
    """Fastest physically possible change of a channel, units/s.

    ``configured`` (> 0, ``[encoder] max_counts_per_s``) is used as given; 0 derives it
    from the log: :data:`GLITCH_SPEED_FACTOR` times the larger of the 99th percentile
    of the per-sample speed |dv|/dt and one quantum (the smallest change, at most 1
    count) per median interval. A handful of glitches cannot move a percentile of a
    long log; a motor at rest has the quantum as its floor.
    """
    if configured > 0:
        return float(configured)
    dt = np.diff(t_s)
    dv = np.abs(np.diff(values))
    if dt.size == 0:
        return float("inf")
    moving = dv[dv > 0]
    quantum = min(1.0, float(np.min(moving))) if moving.size else 1.0
    typical = max(float(np.quantile(dv / dt, 0.99)), quantum / float(np.median(dt)))
    return GLITCH_SPEED_FACTOR * typical


def find_glitches(t_s: np.ndarray, values: np.ndarray, limit_per_s: float) -> np.ndarray:
    """Samples no motor can produce: far from their neighbours' median, and back again.

    Sample ``i`` is a glitch when it departs from the median of the
    ``2*GLITCH_HALF_WINDOW + 1`` samples around it by more than the motor can move
    in that window (``limit_per_s`` times half its duration). Real motion, however
    fast, is monotone over such a window or turns smoothly, so its median follows it;
    a spike (a sensor glitch, a bad field, 2147483647) does not.

    Parameters
    ----------
    t_s, values : ndarray, shape (n,)
        Sample times (s, strictly increasing) and values of one channel.
    limit_per_s : float
        Speed limit, units/s (:func:`speed_limit`).

    Returns
    -------
    ndarray of bool, shape (n,)
    """
    n = values.size
    w = GLITCH_HALF_WINDOW
    if n < 2 * w + 1 or not np.isfinite(limit_per_s):
        return np.zeros(n, dtype=bool)
    med = median_filter(values, size=2 * w + 1, mode="nearest")
    idx = np.arange(n)
    span = t_s[np.minimum(idx + w, n - 1)] - t_s[np.maximum(idx - w, 0)]
    return np.abs(values - med) > limit_per_s * 0.5 * span


def repair_glitches(t_s: np.ndarray, values: np.ndarray, bad: np.ndarray) -> np.ndarray:
    """``values`` with the ``bad`` samples replaced by linear interpolation between the
    nearest good samples in time (the series keeps every sample: nothing is spliced)."""
    if not bad.any():
        return values
    out = values.copy()
    out[bad] = np.interp(t_s[bad], t_s[~bad], values[~bad])
    return out


def check_jumps(t_s, values, limit_per_s: float, name: str, where: str) -> None:
    """CalibError when consecutive samples differ by more than the motor can move.

    Run after :func:`repair_glitches`: what is left is a jump that stays (an encoder
    reset or re-homing, a counter wrap), which no interpolation can repair.
    """
    speed = np.abs(np.diff(values)) / np.diff(t_s)
    if not (speed > limit_per_s).any():
        return
    i = int(np.flatnonzero(speed > limit_per_s)[0])
    raise CalibError(
        f"{where}: '{name}' jumps from {values[i]:.6g} to {values[i + 1]:.6g} between "
        f"t = {t_s[i]:.6f} and {t_s[i + 1]:.6f} s (sample {i + 1}) and stays there: "
        f"{speed[i]:.4g}/s, faster than the motor moves ({limit_per_s:.4g}/s); an encoder "
        "reset? split the log at the jump, or set [encoder] max_counts_per_s in session.toml "
        "if the motor really moves this fast"
    )


def make_encoder_log(
    channels: dict[str, tuple[np.ndarray, np.ndarray]],
    flash: tuple[np.ndarray, np.ndarray] | None,
    source: str,
    max_gap_s: float,
    max_counts_per_s: float = 0.0,
) -> EncoderLog:
    """Validated :class:`EncoderLog` from raw (times, values) pairs.

    Gaps are checked on the encoder channels only (the flash channel may be logged
    on change); every channel must be strictly increasing in time.

    Encoder glitches (samples faster than the motor can move and back,
    :func:`find_glitches`; speed limit ``max_counts_per_s`` counts/s, 0 = derived from
    the log, :func:`speed_limit`) are replaced by linear interpolation between their
    good neighbours and recorded in ``meta["glitches"]`` (per channel: count, first
    times and values, the limit). They are interpolated rather than left as missing
    samples because the hysteresis models carry state and need an input at every
    frame; the motor cannot have moved faster than the limit in between, so the
    interpolation is within the limit times the gap of the truth. A jump that does
    not come back is a CalibError (:func:`check_jumps`).
    """
    built = {}
    glitches = {}
    for name, (t, v) in channels.items():
        t = np.asarray(t, dtype=float)
        v = np.asarray(v, dtype=float)
        check_channel(t, v, name, source, max_gap_s)
        limit = speed_limit(t, v, max_counts_per_s)
        bad = find_glitches(t, v, limit)
        fixed = repair_glitches(t, v, bad)
        check_jumps(t, fixed, limit, name, source)
        k = np.flatnonzero(bad)
        glitches[name] = {
            "n_samples": int(k.size),
            "first_times_s": t[k[:5]].tolist(),
            "first_values": v[k[:5]].tolist(),
            "all_times_s": t[k].tolist(),
            "limit_counts_per_s": limit,
            "limit_source": "configured" if max_counts_per_s > 0 else "derived",
        }
        built[name] = Channel(t, fixed)
    fl = None
    if flash is not None:
        t, v = (np.asarray(a, dtype=float) for a in flash)
        check_channel(t, v, "sync_flash", source, np.inf)
        fl = Channel(t, (v != 0).astype(float))
    return EncoderLog(channels=built, flash=fl, source=source, meta={"glitches": glitches})
