"""angles.csv, the tracked angles ``track`` writes (docs/tracking.md), read for ``sync``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from i2ris_calib.errors import CalibError
from i2ris_calib.sync.estimate import check_angles


def read_angles(path: Path) -> pd.DataFrame:
    """angles.csv from the tracking stage, validated (sync.estimate.check_angles).

    Frames that ``track`` flagged ``rejected`` because their timestamp goes backwards
    (docs/session.md: tolerated) are left out here, so they do not look like a clock
    reset; their number is in ``df.attrs["n_backward_rejected"]`` (sync.json). A time
    that goes backwards on a frame not flagged so is still refused.
    """
    if not path.is_file():
        raise CalibError(
            f"tracked angles not found: {path} (run 'i2ris-calib track SESSION' first, or pass --angles)"
        )
    try:
        df = pd.read_csv(path)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise CalibError(f"{path}: not a readable CSV file ({exc})") from None
    df, n_back = drop_backward_rejected(df)
    out = check_angles(df, str(path))
    out.attrs["n_backward_rejected"] = n_back
    return out


def drop_backward_rejected(df: pd.DataFrame) -> tuple[pd.DataFrame, int]:
    """Rows of status ``rejected`` whose time is not after every earlier kept row, removed.

    Returns the remaining rows (index reset) and how many were removed. Tables without
    ``time_s``/``status`` columns are returned unchanged (check_angles names them).
    """
    if "time_s" not in df.columns or "status" not in df.columns:
        return df, 0
    t = pd.to_numeric(df["time_s"], errors="coerce").to_numpy(dtype=float)
    rejected = df["status"].astype(str).to_numpy() == "rejected"
    # a dropped row is never later than the running maximum, so including it changes nothing
    earlier = np.fmax.accumulate(np.concatenate([[-np.inf], t[:-1]]))
    drop = rejected & (t <= earlier)
    if not drop.any():
        return df, 0
    return df[~drop].reset_index(drop=True), int(drop.sum())
