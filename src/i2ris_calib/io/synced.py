"""The one reader of synced CSVs (docs/formats.md) -> :class:`~i2ris_calib.data.Dataset`.

``fit``, ``diagnose`` and ``report`` all read a synced recording here, so a model
diagnosed on a dataset is refitted and plotted on exactly the same samples.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from i2ris_calib.data.dataset import AXES, Dataset, direction_datasets, input_bands, other_axis
from i2ris_calib.errors import CalibError
from i2ris_calib.sync.log import find_glitches, speed_limit


def read_synced(path: str | Path, axis: str) -> pd.DataFrame:
    """Read and validate a synced CSV for ``axis``; one-line CalibError on bad input.

    Checks: file readable, columns ``time_s, enc_<axis>, <axis>_deg`` present (header
    names are stripped of spaces), time and encoders numeric and finite, time
    strictly increasing. Angles of rows whose ``status`` (if present) is not
    ``measured`` are set to NaN (both axes). ``enc_<other>`` and ``<other>_deg`` are
    read when present.
    """
    p = Path(path)
    if axis not in AXES:
        raise CalibError(f"--axis must be yaw or pitch, got '{axis}'")
    if not p.is_file():
        raise CalibError(f"{p}: file not found (give a synced CSV, see docs/formats.md)")
    try:
        df = pd.read_csv(p, skipinitialspace=True)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise CalibError(f"{p}: not a readable CSV ({str(exc).splitlines()[0]})") from None
    df.columns = [str(c).strip() for c in df.columns]
    other = other_axis(axis)
    need = ["time_s", f"enc_{axis}", f"{axis}_deg"]
    missing = [c for c in need if c not in df.columns]
    if missing:
        raise CalibError(
            f"{p}: missing column(s) {', '.join(missing)} (found: {', '.join(df.columns)}); "
            "a synced CSV has time_s, enc_yaw, enc_pitch, yaw_deg, pitch_deg, status (docs/formats.md)"
        )
    optional = [c for c in (f"enc_{other}", f"{other}_deg") if c in df.columns]
    for col in [*need, *optional]:
        num = pd.to_numeric(df[col], errors="coerce")
        bad = num.isna() & df[col].notna()
        if bad.any():
            k = int(np.flatnonzero(bad.to_numpy())[0])
            raise CalibError(
                f"{p}: column '{col}' is not numeric at line {k + 2} ({df[col].iloc[k]!r}); "
                "fix or remove that row"
            )
        df[col] = num.astype(float)
    for col in ("time_s", f"enc_{axis}", *([f"enc_{other}"] if f"enc_{other}" in df else [])):
        bad = np.flatnonzero(~np.isfinite(df[col].to_numpy()))
        if bad.size:
            raise CalibError(
                f"{p}: {bad.size} row(s) with NaN/empty '{col}' (first at line {bad[0] + 2}); "
                "drop or interpolate them (only angles may be NaN)"
            )
    t = df["time_s"].to_numpy()
    step = np.diff(t)
    if step.size and (step <= 0).any():
        k = int(np.flatnonzero(step <= 0)[0])
        kind = "duplicate" if step[k] == 0 else "decreasing"
        raise CalibError(
            f"{p}: {kind} time_s at line {k + 3} ({t[k]:.6g} -> {t[k + 1]:.6g} s); "
            "time must be strictly increasing (sort the rows and drop duplicates)"
        )
    for col in (f"enc_{axis}", *([f"enc_{other}"] if f"enc_{other}" in df else [])):
        check_encoder_jumps(t, df[col].to_numpy(), col, p)
    if "status" in df.columns:
        not_measured = df["status"].astype(str).str.strip() != "measured"
        for col in (f"{axis}_deg", f"{other}_deg"):
            if col in df.columns:
                df.loc[not_measured, col] = np.nan
    return df


# --- encoder glitches (issue 9): 'sync' repairs them; a synced CSV made elsewhere is checked
def check_encoder_jumps(t: np.ndarray, enc: np.ndarray, col: str, p: Path) -> None:
    """CalibError naming the line of the first encoder sample the motor cannot produce:
    one that departs from its neighbours and comes back faster than the speed limit
    derived from the file itself (``sync.log.find_glitches``, ``sync.log.speed_limit``).
    A step that stays is left alone (synthetic inputs and joined recordings have them).
    """
    limit = speed_limit(t, enc)
    bad = find_glitches(t, enc, limit)
    if not bad.any():
        return
    k = int(np.flatnonzero(bad)[0])
    raise CalibError(
        f"{p}: '{col}' = {enc[k]:.6g} at line {k + 2} (t = {t[k]:.6f} s) jumps away and back "
        f"faster than the motor moves anywhere else in the file (> {limit:.4g} counts/s): an "
        "encoder glitch? fix or interpolate that row ('i2ris-calib sync' repairs glitches in the log)"
    )


def datasets_from_frame(
    df: pd.DataFrame,
    axis: str,
    fit_config,
    source: str = "",
    directions: tuple[str, ...] | None = None,
) -> list[Dataset]:
    """Motion-direction datasets of ``axis`` in one validated synced frame.

    Every dataset holds every row (the whole input history); see
    :mod:`i2ris_calib.data.dataset`. ``fit_config`` gives the bands
    (``zero_band_counts``, ``deadband_counts``: negative = derived from the input),
    ``holdout_fraction``, ``min_block_samples`` and ``signed``.
    """
    other = other_axis(axis)
    enc = df[f"enc_{axis}"].to_numpy(dtype=float)
    bands = input_bands(enc, fit_config.zero_band_counts, fit_config.deadband_counts)
    th_other = df[f"{other}_deg"].to_numpy(dtype=float) if f"{other}_deg" in df else None
    return direction_datasets(
        axis,
        df["time_s"].to_numpy(dtype=float),
        enc,
        df[f"{axis}_deg"].to_numpy(dtype=float),
        enc_other=df[f"enc_{other}"].to_numpy(dtype=float) if f"enc_{other}" in df else None,
        theta_other_deg=_filled(df["time_s"].to_numpy(dtype=float), th_other),
        bands=bands,
        holdout_fraction=fit_config.holdout_fraction,
        min_samples=fit_config.min_block_samples,
        signed=fit_config.signed,
        directions=directions,
        source=source,
    )


def _filled(t: np.ndarray, x: np.ndarray | None) -> np.ndarray | None:
    """``x`` with NaN gaps linearly interpolated (coupling effects read it as an
    input), None when fewer than 2 values are finite."""
    if x is None:
        return None
    ok = np.isfinite(x)
    return np.interp(t, t[ok], x[ok]) if ok.sum() >= 2 else None


def load_datasets(
    paths: Sequence[str | Path],
    axis: str,
    fit_config,
    directions: tuple[str, ...] | None = None,
) -> list[Dataset]:
    """All motion-direction datasets of ``axis`` in the given synced CSVs, uniquely
    named (``"yaw+ (file stem)"`` when two files give the same name)."""
    found: list[Dataset] = []
    for path in paths:
        found += datasets_from_frame(
            read_synced(path, axis), axis, fit_config, str(path), directions
        )
    if not found:
        which = "" if directions is None else f" in direction {'/'.join(directions)}"
        raise CalibError(
            f"no {axis} motion{which} in {', '.join(map(str, paths))}: fewer than "
            f"{fit_config.min_block_samples} samples leave the zero band of enc_{axis} "
            "(check --axis, or lower [fit] min_block_samples)"
        )
    seen: dict[str, int] = {}
    unique = []
    for d in found:
        seen[d.name] = seen.get(d.name, 0) + 1
        if seen[d.name] > 1:
            d = replace(d, name=f"{d.name} ({Path(d.source).stem})")
        unique.append(d)
    return unique
