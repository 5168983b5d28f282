"""A camera's timestamp CSV (``frame``, ``time_s``; docs/session.md), read for ``track``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from i2ris_calib.errors import CalibError

#: Above this fraction of out-of-order timestamps the file is refused (not flagged).
MAX_NON_MONOTONIC = 0.05
#: A median frame interval above this (s) means time_s is not in seconds (ms, ns).
MAX_FRAME_INTERVAL_S = 2.0


def read_timestamps(path: Path) -> pd.DataFrame:
    """Timestamp CSV (``frame``, ``time_s``) with a ``valid`` column for monotonic rows."""
    try:
        df = pd.read_csv(path)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise CalibError(f"{path}: unreadable CSV ({str(exc).splitlines()[0]})") from None
    df.columns = [str(c).strip() for c in df.columns]
    missing = {"frame", "time_s"} - set(df.columns)
    if missing:
        raise CalibError(
            f"{path}: missing column(s) {', '.join(sorted(missing))} (need frame, time_s)"
        )
    if len(df) < 2:
        raise CalibError(
            f"{path}: {len(df)} frame row(s) below the header (need one row per video frame: "
            "re-export the camera timestamps)"
        )
    t = pd.to_numeric(df["time_s"], errors="coerce").to_numpy(float)
    fr = pd.to_numeric(df["frame"], errors="coerce").to_numpy(float)
    if not np.all(np.isfinite(t)) or not np.all(np.isfinite(fr)):
        bad = int(np.flatnonzero(~(np.isfinite(t) & np.isfinite(fr)))[0]) + 2
        raise CalibError(f"{path}: non-numeric frame/time_s at line {bad}")
    if not np.array_equal(fr, np.arange(len(fr))):
        raise CalibError(
            f"{path}: column 'frame' must count 0, 1, 2, ... (one row per video frame, in order)"
        )
    running = np.maximum.accumulate(np.concatenate([[-np.inf], t[:-1]]))
    valid = t > running
    if (~valid).mean() > MAX_NON_MONOTONIC:
        first = int(np.flatnonzero(~valid)[0]) + 2
        raise CalibError(
            f"{path}: {int((~valid).sum())} timestamps are not increasing (first at line {first}); "
            "fix the camera clock export"
        )
    step = float(np.median(np.diff(t[valid]))) if valid.sum() >= 2 else 0.0
    if step > MAX_FRAME_INTERVAL_S:
        unit = "milliseconds: divide by 1000" if step < 2000 else "ms, us or ns"
        raise CalibError(
            f"{path}: median frame interval {step:g} 'seconds' ({1 / step:.3g} fps): time_s "
            f"must be in seconds (the values look like {unit})"
        )
    return pd.DataFrame({"frame": fr.astype(int), "time_s": t, "valid": valid})
