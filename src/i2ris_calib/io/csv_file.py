"""Reading a CSV file a user gives, with a one-line error naming it."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from i2ris_calib.errors import CalibError


def read_csv_file(path: str | Path, what: str) -> pd.DataFrame:
    """The CSV at ``path`` as read (header names stripped of spaces).

    ``what`` completes the not-found line (``"<path>: <what>"``, e.g. ``"file not found
    (give a synced CSV, see docs/formats.md)"``); a file pandas cannot parse, an empty one
    or one that is not UTF-8 text gives ``"<path>: not a readable CSV (<reason>)"``.
    """
    return _read(path, what)


def read_csv_header(path: str | Path, what: str) -> list[str]:
    """The column names of the CSV at ``path`` (stripped of spaces), the file checked
    as by :func:`read_csv_file` (not found, unparsable, empty, not UTF-8: one line)."""
    return list(_read(path, what, nrows=0).columns)


def _read(path: str | Path, what: str, nrows: int | None = None) -> pd.DataFrame:
    p = Path(path)
    if not p.is_file():
        raise CalibError(f"{p}: {what}")
    try:
        raw = pd.read_csv(p, skipinitialspace=True, nrows=nrows)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise CalibError(f"{p}: not a readable CSV ({str(exc).splitlines()[0]})") from None
    raw.columns = [str(c).strip() for c in raw.columns]
    return raw
