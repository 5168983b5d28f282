"""The encoder log as arrays (controller clock), its validation and interpolation.

Each channel (``enc_yaw``, ``enc_pitch``, optional ``sync_flash``) has its own sample
times, because ROS bags log each motor on its own topic; a CSV log simply shares one
time column between them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from i2ris_calib.errors import CalibError

ENCODER_CHANNELS = ("enc_yaw", "enc_pitch")


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
    """

    channels: dict[str, Channel]
    flash: Channel | None = None
    source: str = ""
    meta: dict = field(default_factory=dict)

    def time_range(self) -> tuple[float, float]:
        """(first, last) time, s, over which every encoder channel is defined."""
        lo = max(float(c.t_s[0]) for c in self.channels.values())
        hi = min(float(c.t_s[-1]) for c in self.channels.values())
        return lo, hi

    def interpolate(self, name: str, t_s: np.ndarray) -> np.ndarray:
        """Channel ``name`` linearly interpolated at ``t_s`` (NaN outside its range)."""
        ch = self.channels[name]
        return np.interp(t_s, ch.t_s, ch.values.astype(float), left=np.nan, right=np.nan)


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


def make_encoder_log(
    channels: dict[str, tuple[np.ndarray, np.ndarray]],
    flash: tuple[np.ndarray, np.ndarray] | None,
    source: str,
    max_gap_s: float,
) -> EncoderLog:
    """Validated :class:`EncoderLog` from raw (times, values) pairs.

    Gaps are checked on the encoder channels only (the flash channel may be logged
    on change); every channel must be strictly increasing in time.
    """
    built = {}
    for name, (t, v) in channels.items():
        t = np.asarray(t, dtype=float)
        v = np.asarray(v, dtype=float)
        check_channel(t, v, name, source, max_gap_s)
        built[name] = Channel(t, v)
    fl = None
    if flash is not None:
        t, v = (np.asarray(a, dtype=float) for a in flash)
        check_channel(t, v, "sync_flash", source, np.inf)
        fl = Channel(t, (v != 0).astype(float))
    return EncoderLog(channels=built, flash=fl, source=source)
