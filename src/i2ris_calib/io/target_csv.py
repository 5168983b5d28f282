"""Reading the CSVs ``compensate`` takes: the target angles (``--target``) and the
commands sent before (``--history``); formats in docs/compensate.md."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from i2ris_calib.compensation.plan import AxisPlan
from i2ris_calib.errors import CalibError
from i2ris_calib.io.csv_file import read_csv_file
from i2ris_calib.io.epoch import epoch_unit_problem

__all__ = ["PLAUSIBLE_TARGET_STEP_S", "read_history", "read_target"]

#: Median target sample interval (s) a motor command stream can plausibly have
#: (100 kHz .. 1 Hz); outside it the target's time unit is questioned
PLAUSIBLE_TARGET_STEP_S = (1e-5, 1.0)


def read_target(path: str | Path, axes: Sequence[str], time_unit_s: float = 1.0) -> pd.DataFrame:
    """Read and validate a target CSV: ``time_s`` and ``<axis>_deg`` for every axis.

    ``time_s`` is multiplied by ``time_unit_s`` (seconds per unit of the column: 1e-3
    for ms). One-line CalibError for: unreadable file, missing columns, non-numeric or
    NaN values, time not strictly increasing, a median sample interval outside
    :data:`PLAUSIBLE_TARGET_STEP_S` (naming the ``time_unit_s`` that fits), an epoch
    clock read in the wrong unit (:func:`~i2ris_calib.io.epoch.epoch_unit_problem`).
    """
    p = Path(path)
    df = read_csv_file(p, "target file not found (a CSV with time_s and <axis>_deg)")
    need = ["time_s", *[f"{a}_deg" for a in axes]]
    missing = [c for c in need if c not in df.columns]
    if missing:
        raise CalibError(
            f"{p}: missing column(s) {', '.join(missing)} (found: {', '.join(df.columns)}); "
            f"a target CSV has {', '.join(need)}"
        )
    if len(df) == 0:
        raise CalibError(f"{p}: no rows")
    for col in need:
        num = pd.to_numeric(df[col], errors="coerce").to_numpy(dtype=float)
        bad = np.flatnonzero(~np.isfinite(num))
        if bad.size:
            raise CalibError(
                f"{p}: column '{col}' has {bad.size} missing/non-numeric value(s) "
                f"(first at line {bad[0] + 2}: {df[col].iloc[bad[0]]!r}); fill or remove them"
            )
        df[col] = num
    t = df["time_s"].to_numpy()
    d = np.flatnonzero(np.diff(t) <= 0)
    if d.size:
        raise CalibError(
            f"{p}: time_s must increase strictly; line {d[0] + 3} (t = {t[d[0] + 1]:g} s) "
            f"does not (previous t = {t[d[0]]:g} s)"
        )
    why = epoch_unit_problem(t[0], float(np.median(np.diff(t))) if t.size > 1 else None,
                             float(time_unit_s))  # fmt: skip
    if why:
        raise CalibError(
            f"{p}: time_s {why}; give it with --time-unit-s (or [compensate] time_unit_s)"
        )
    df["time_s"] = t * float(time_unit_s)
    _check_target_step(p, df["time_s"].to_numpy(), float(time_unit_s))
    return df


def _check_target_step(p: Path, t: np.ndarray, unit_s: float) -> None:
    """CalibError when the median sample interval (s) is implausible for a command
    stream (:data:`PLAUSIBLE_TARGET_STEP_S`), naming the ``time_unit_s`` that fits."""
    if t.size < 2:
        return
    step = float(np.median(np.diff(t)))
    lo, hi = PLAUSIBLE_TARGET_STEP_S
    if lo <= step <= hi:
        return
    hint = "give time_s in seconds or the unit with --time-unit-s / [compensate] time_unit_s"
    for unit, name in ((1e-3, "ms"), (1e-6, "us"), (1e-9, "ns"), (60.0, "min")):
        if lo <= step * unit <= hi:
            hint = (
                f"the times look like {name}: give --time-unit-s {unit_s * unit:g} "
                "(or [compensate] time_unit_s)"
            )
            break
    raise CalibError(
        f"{p}: time_s steps by {step:g} s per sample (median, time_unit_s = {unit_s:g}), "
        f"outside {lo:g}..{hi:g} s for motor commands; {hint}"
    )


def read_history(path: str | Path, plans: Mapping[str, AxisPlan]) -> dict[str, np.ndarray]:
    """The commands sent before (``--history``): per axis of ``plans`` (the compensation
    plans, :class:`~i2ris_calib.compensation.plan.AxisPlan`) its ``enc_<axis>`` column
    (signed counts, oldest first) in the model's convention (the plan's ``sign`` x
    counts). One-line CalibError for an unreadable file, a missing column, non-numeric
    values or counts outside the plan's input range ``lo..hi`` (the fit's: the model is
    not known beyond it)."""
    p = Path(path)
    df = read_csv_file(p, "--history file not found (a CSV of the commands sent before)")
    need = [f"enc_{axis}" for axis in plans]
    missing = [c for c in need if c not in df.columns]
    if missing or len(df) == 0:
        raise CalibError(
            f"{p}: --history needs the column(s) {', '.join(need)} with at least one row "
            f"(found: {', '.join(df.columns) or 'nothing'}; an earlier COMMANDS.csv or the "
            "encoder log)"
        )
    out = {}
    for axis, a in plans.items():
        col = f"enc_{axis}"
        v = pd.to_numeric(df[col], errors="coerce").to_numpy(dtype=float)
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            raise CalibError(
                f"{p}: column '{col}' has {bad.size} missing/non-numeric value(s) (first at "
                f"line {bad[0] + 2}); --history needs every command sent"
            )
        m = a.sign * v
        off = np.flatnonzero((m < a.lo) | (m > a.hi))
        if off.size:
            rng = sorted((a.sign * a.lo + 0.0, a.sign * a.hi + 0.0))
            raise CalibError(
                f"{p}: {col} = {v[off[0]]:g} at line {off[0] + 2} is outside the {a.name} "
                f"fit's input range {rng[0]:g}..{rng[1]:g} counts (the model is not known "
                "there); give a history inside it or --conditioning sweep without --history"
            )
        out[axis] = m
    return out
