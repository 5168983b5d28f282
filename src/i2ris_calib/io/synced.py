"""The one reader of synced CSVs (docs/formats.md) -> :class:`~i2ris_calib.data.Dataset`.

``fit``, ``diagnose`` and ``report`` all read a synced recording here, so a model
diagnosed on a dataset is refitted and plotted on exactly the same samples.
"""

from __future__ import annotations

import difflib
from collections.abc import Callable, Sequence
from dataclasses import astuple, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from i2ris_calib.data.coupling import MotorsTogether, motors_together
from i2ris_calib.data.dataset import AXES, Dataset, direction_datasets, input_bands, other_axis
from i2ris_calib.data.excursions import Excursions, excursions
from i2ris_calib.errors import CalibError
from i2ris_calib.io.columns import STANDARD_COLUMNS, ColumnsConfig, parse_columns_option
from i2ris_calib.io.csv_file import read_csv_file
from i2ris_calib.io.epoch import EPOCH_MIN_S, epoch_unit_problem
from i2ris_calib.sync.log import find_glitches, speed_limit

#: the largest |angle| (deg) the I2RIS can show (it bends about +-90 deg): angles read
#: as radians (``angle_unit = "rad"``) beyond it are degrees read x57
MAX_PLAUSIBLE_ANGLE_DEG = 180.0
#: median sample intervals a synced recording can plausibly have, s (10 kHz .. 0.1 Hz);
#: a slower one that becomes plausible in ms/us/ns is refused naming the time_unit_s to set
PLAUSIBLE_STEP_S = (1e-4, 10.0)


def with_columns(config, option: str | None = None):
    """``config`` with the effective ``[columns]`` section: ``config.columns``
    overridden key by key by the ``--columns`` text ``option`` (so provenance records
    the mapping used)."""
    if option is None:
        return config
    return replace(config, columns=parse_columns_option(option, config.columns))


def read_synced(path: str | Path, axis: str, columns: ColumnsConfig | None = None) -> pd.DataFrame:
    """Read and validate a synced CSV for ``axis``; one-line CalibError on bad input.

    ``columns`` (``[columns]``, default: the standard names) says which column of the file is which standard column and
    the file's time and angle units. The frame returned has the standard columns only,
    in s, counts and deg (time as float64 throughout; epoch times counted from the
    first sample, the origin in ``df.attrs["time_origin_s"]``).

    Checks: file readable, columns ``time_s, enc_<axis>, <axis>_deg`` present (header
    names are stripped of spaces), every column named in ``columns`` other than its
    standard name present, time and encoders numeric and finite, time strictly
    increasing and in a plausible unit. Angles of rows whose ``status`` (if present) is
    not ``measured`` are set to NaN (both axes). ``enc_<other>`` and ``<other>_deg``
    are read when present.
    """
    p = Path(path)
    if axis not in AXES:
        raise CalibError(f"--axis must be yaw or pitch, got '{axis}'")
    cols = ColumnsConfig() if columns is None else columns
    raw = read_csv_file(p, "file not found (give a synced CSV, see docs/formats.md)")
    other = other_axis(axis)
    need = ["time_s", f"enc_{axis}", f"{axis}_deg"]
    source = cols.mapping()
    _check_mapped_columns(p, raw, cols)
    _check_needed(p, raw, [source[c] for c in need], need)
    if raw.empty:
        raise CalibError(
            f"{p}: no samples (the file has only its header line); give a synced CSV with "
            "one row per sample (docs/formats.md)"
        )
    present = [c for c in STANDARD_COLUMNS if source[c] in raw.columns]
    df = pd.DataFrame({c: raw[source[c]] for c in present})
    label = {c: f"'{c}'" if source[c] == c else f"'{source[c]}' ({c})" for c in present}
    optional = [c for c in (f"enc_{other}", f"{other}_deg") if c in df.columns]
    numeric = _numeric_columns(p, df, [*need, *optional], label)
    encoders = [f"enc_{axis}", *([f"enc_{other}"] if f"enc_{other}" in df else [])]
    _check_finite(p, df, ["time_s", *encoders], label)
    where = list(raw.columns).index(source["time_s"])
    t, origin = _seconds(
        numeric["time_s"],
        cols.time_unit_s,
        lambda: pd.read_csv(p, usecols=[where], dtype=str, skipinitialspace=True).iloc[:, 0],
    )
    df["time_s"] = t
    df.attrs["time_origin_s"] = origin
    _check_increasing(p, t, label["time_s"], origin)
    _check_time_unit(p, t, label["time_s"], cols.time_unit_s)
    _check_epoch_unit(p, numeric["time_s"].to_numpy(dtype=float), label["time_s"], cols.time_unit_s)
    for col in encoders:
        check_encoder_jumps(t, df[col].to_numpy(), source[col], p)
    _check_some_measured(p, df, label)
    angles = [c for c in (f"{axis}_deg", f"{other}_deg") if c in df.columns]
    _angles_in_deg(p, df, angles, cols, label)
    return df


#: the values of a synced CSV's ``status`` column (tracking, docs/formats.md)
STATUS_VALUES = ("measured", "not_found", "ambiguous", "rejected")


def _check_some_measured(p: Path, df: pd.DataFrame, label: dict) -> None:
    """CalibError when the file has a ``status`` column and no row of it reads
    ``measured``: every angle would be ignored, leaving nothing to fit (a status
    column mapped to another column, or a recording tracking never measured)."""
    if "status" not in df.columns or df.empty:
        return
    values = df["status"].astype(str).str.strip()
    if (values == "measured").any():
        return
    counts = values.value_counts()
    seen = ", ".join(f"{v!r} x{n}" for v, n in counts.head(3).items())
    seen += ", ..." if len(counts) > 3 else ""
    if not set(counts.index) & set(STATUS_VALUES[1:]):
        why = (
            "these are not tracking statuses: map status to the column whose measured rows "
            "read 'measured' (--columns/[columns], docs/formats.md), or leave status out"
        )
    else:
        why = "tracking measured no frame: check the tracking of this recording (track, report)"
    raise CalibError(
        f"{p}: no row of {label['status']} reads 'measured' ({seen}); angles of rows not "
        f"'measured' are ignored, so nothing is left to fit; {why}"
    )


def _check_needed(p: Path, raw: pd.DataFrame, names: list[str], standard: list[str]) -> None:
    """CalibError naming the ``standard`` columns whose file ``names`` are missing."""
    missing = [c for c, n in zip(standard, names, strict=True) if n not in raw.columns]
    if missing:
        raise CalibError(
            f"{p}: missing column(s) {', '.join(missing)} (found: {', '.join(raw.columns)}); "
            "a synced CSV has time_s, enc_yaw, enc_pitch, yaw_deg, pitch_deg, status "
            "(docs/formats.md); name your file's columns with --columns or [columns]"
        )


def _check_finite(p: Path, df: pd.DataFrame, names: list[str], label: dict) -> None:
    """CalibError at the first column of ``names`` with a NaN/empty row (line named)."""
    for col in names:
        bad = np.flatnonzero(~np.isfinite(df[col].to_numpy()))
        if bad.size:
            raise CalibError(
                f"{p}: {bad.size} row(s) with NaN/empty {label[col]} (first at line {bad[0] + 2}); "
                "drop or interpolate them (only angles may be NaN)"
            )


def _angles_in_deg(
    p: Path, df: pd.DataFrame, angles: list[str], cols: ColumnsConfig, label: dict
) -> None:
    """The ``angles`` columns of ``df`` in deg (from rad when ``cols.angle_unit`` says so),
    NaN on rows whose ``status`` (when present) is not ``measured``; in place.

    Measured radians beyond :data:`MAX_PLAUSIBLE_ANGLE_DEG` are refused naming the
    largest, its line and the fix: degrees read as radians (x57)."""
    measured = np.ones(len(df), dtype=bool)
    if "status" in df.columns:
        measured = (df["status"].astype(str).str.strip() == "measured").to_numpy()
    for col in angles:
        x = df[col].to_numpy(dtype=float)
        if cols.angle_unit == "rad":
            x = np.rad2deg(x)
            _check_radians(p, x, measured, label[col])
        df[col] = np.where(measured, x, np.nan)


def _check_radians(p: Path, deg: np.ndarray, measured: np.ndarray, label: str) -> None:
    """CalibError when a measured angle read as radians is beyond +-
    :data:`MAX_PLAUSIBLE_ANGLE_DEG` deg (``deg``: the angles converted)."""
    size = np.where(measured & np.isfinite(deg), np.abs(deg), 0.0)
    big = int(np.count_nonzero(size > MAX_PLAUSIBLE_ANGLE_DEG))
    if not big:
        return
    k = int(np.argmax(size))
    raise CalibError(
        f"{p}: {label} = {np.deg2rad(deg[k]):.6g} at line {k + 2} is {deg[k]:.5g} deg with "
        f'angle_unit = "rad" ({big} row(s) beyond +-{MAX_PLAUSIBLE_ANGLE_DEG:g} deg; the '
        'I2RIS bends about +-90 deg): the angles look like degrees; set angle_unit = "deg" '
        "in [columns] or --columns (docs/formats.md)"
    )


def _numeric_columns(p: Path, df: pd.DataFrame, names: list[str], label: dict) -> dict:
    """Column name -> its values as numbers (as read: integers stay integers), each
    column of ``df`` in ``names`` replaced by float64 in place; one line naming the
    first non-numeric cell (empty cells are NaN)."""
    numeric: dict[str, pd.Series] = {}
    for col in names:
        num = pd.to_numeric(df[col], errors="coerce")
        bad = num.isna() & df[col].notna()
        if bad.any():
            k = int(np.flatnonzero(bad.to_numpy())[0])
            raise CalibError(
                f"{p}: column {label[col]} is not numeric at line {k + 2} ({df[col].iloc[k]!r}); "
                "fix or remove that row"
            )
        numeric[col] = num
        df[col] = num.astype(float)
    return numeric


def _check_increasing(p: Path, t: np.ndarray, label: str, origin: float) -> None:
    """One line naming the first duplicate or decreasing time (s)."""
    step = np.diff(t)
    if step.size and (step <= 0).any():
        k = int(np.flatnonzero(step <= 0)[0])
        kind = "duplicate" if step[k] == 0 else "decreasing"
        raise CalibError(
            f"{p}: {kind} {label} at line {k + 3} ({t[k]:.6g} -> {t[k + 1]:.6g} s"
            f"{' after the first sample' if origin else ''}); "
            "time must be strictly increasing (sort the rows and drop duplicates)"
        )


def _check_mapped_columns(p: Path, raw: pd.DataFrame, cols: ColumnsConfig) -> None:
    """One line naming the file, the column and the file's columns when a column that
    ``cols`` names (other than by its standard name) is not in the file."""
    for key in STANDARD_COLUMNS:
        name = cols.mapping()[key]
        if not cols.is_mapped(key) or name in raw.columns:
            continue
        close = difflib.get_close_matches(name, list(raw.columns), n=1, cutoff=0.6)
        hint = f"did you mean '{close[0]}'? " if close else ""
        raise CalibError(
            f"{p}: no column '{name}' (the {key} column in --columns/[columns]); the file has "
            f"{', '.join(repr(c) for c in raw.columns)}; {hint}fix the column mapping "
            "(docs/formats.md)"
        )


def _seconds(
    values: pd.Series, unit_s: float, text: Callable[[], pd.Series] | None = None
) -> tuple[np.ndarray, float]:
    """(time s as float64, origin s) from the time column as read and its unit.

    Times whose first value is an epoch clock (>= :data:`EPOCH_MIN_S` s) are returned
    from the first sample (origin = that time, s), the first time subtracted before
    anything is rounded: in the column's own type when it is integer (ns/ms stamps),
    else on the decimal text (``text()``, the column as strings) so that
    ``1700000000.2`` is 0.2 s after ``1700000000.0``, not 0.2000000477. Other times are
    returned as they are (origin 0).
    """
    v = values.to_numpy()
    first = v[0]
    origin = float(first) * unit_s
    if abs(origin) < EPOCH_MIN_S:
        return v.astype(np.float64) * unit_s, 0.0
    if np.issubdtype(v.dtype, np.integer):
        rel = (v - first).astype(np.float64)
    else:
        exact = None if text is None else _decimal_offsets(text())
        if exact is None or exact.size != v.size:
            exact = v.astype(np.float64) - np.float64(first)
        rel = exact
    return rel * unit_s, origin


def _decimal_offsets(text: pd.Series) -> np.ndarray | None:
    """Each value minus the first, float64, from plain decimal text (``123.456``): the
    integer parts subtracted exactly, then the fractions. None unless every value is
    a plain non-negative decimal with at most 18 integer digits."""
    parts = text.astype(str).str.strip().str.extract(r"^(\d{1,18})(?:\.(\d*))?$")
    if parts[0].isna().any():
        return None
    whole = parts[0].astype(np.int64).to_numpy()
    frac = ("0." + parts[1].fillna("")).astype(np.float64).to_numpy()
    return (whole - whole[0]).astype(np.float64) + (frac - frac[0])


def _check_time_unit(p: Path, t: np.ndarray, label: str, unit_s: float) -> None:
    """CalibError naming the ``time_unit_s`` to set when the median sample interval is
    implausibly slow in seconds but plausible in ms, us or ns (:data:`PLAUSIBLE_STEP_S`)."""
    if t.size < 2:
        return
    step = float(np.median(np.diff(t)))
    lo, hi = PLAUSIBLE_STEP_S
    if step <= hi:
        return
    for unit, name in ((1e-3, "ms"), (1e-6, "us"), (1e-9, "ns")):
        if lo <= step * unit <= hi:
            raise CalibError(
                f"{p}: {label} steps by {step:g} s per sample (median, with time_unit_s = "
                f"{unit_s:g}): the times look like {name}; set time_unit_s = {unit_s * unit:g} "
                f"in [columns] or --columns (docs/formats.md)"
            )


def _check_epoch_unit(p: Path, raw: np.ndarray, label: str, unit_s: float) -> None:
    """CalibError when the time column (``raw``, as written in the file) is an epoch
    clock that ``unit_s`` puts outside 2000..2100 while another unit puts it inside
    (:func:`~i2ris_calib.io.epoch.epoch_unit_problem`): epoch seconds read as ms would
    make 5 Hz data 5 kHz and every rate derived from it 1000x too high."""
    step = float(np.median(np.diff(raw))) if raw.size > 1 else None
    why = epoch_unit_problem(float(raw[0]), step, unit_s)
    if why:
        raise CalibError(
            f"{p}: {label} {why}; set time_unit_s to it in [columns] or --columns (docs/formats.md)"
        )


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


def read_frames(
    paths: Sequence[str | Path], axis: str, columns: ColumnsConfig | None = None
) -> list[tuple[str, pd.DataFrame]]:
    """Each synced CSV of ``paths`` read and validated once (:func:`read_synced`), with
    its path as text: what :func:`frame_datasets` and :func:`frames_for_fit` take."""
    return [(str(path), read_synced(path, axis, columns)) for path in paths]


def load_datasets(
    paths: Sequence[str | Path],
    axis: str,
    fit_config,
    directions: tuple[str, ...] | None = None,
    columns: ColumnsConfig | None = None,
) -> list[Dataset]:
    """All motion-direction datasets of ``axis`` in the given synced CSVs, uniquely
    named (``"yaw+ (file stem)"`` when two files give the same name). ``columns``:
    the column mapping and units of the files (``[columns]``; default: the standard
    synced CSV)."""
    return frame_datasets(read_frames(paths, axis, columns), axis, fit_config, directions)


def frame_datasets(
    frames: Sequence[tuple[str, pd.DataFrame]],
    axis: str,
    fit_config,
    directions: tuple[str, ...] | None = None,
) -> list[Dataset]:
    """:func:`load_datasets` of files already read (:func:`read_frames`): the datasets
    of each ``(path, frame)``, uniquely named."""
    found: list[Dataset] = []
    for source, df in frames:
        found += datasets_from_frame(df, axis, fit_config, source, directions)
    if not found:
        paths = [source for source, _ in frames]
        dfs = [df for _, df in frames]
        raise CalibError(_too_little_motion(paths, dfs, axis, fit_config, directions))
    seen: dict[str, int] = {}
    unique = []
    for d in found:
        seen[d.name] = seen.get(d.name, 0) + 1
        if seen[d.name] > 1:
            d = replace(d, name=f"{d.name} ({Path(d.source).stem})")
        unique.append(d)
    return unique


def _too_little_motion(paths, frames, axis: str, fit_config, directions) -> str:
    """The one line when no file gives a dataset: the samples each direction has
    outside the zero band, the minimum (``[fit] min_block_samples``) and what that
    is in seconds at the recording's own rate."""
    wanted = ("±",) if fit_config.signed else ("+", "-")
    if directions is not None:
        wanted = tuple(d for d in wanted if d in directions)
    counts = {d: 0 for d in wanted}
    rates = []
    for df in frames:
        enc = df[f"enc_{axis}"].to_numpy(dtype=float)
        band = input_bands(enc, fit_config.zero_band_counts, fit_config.deadband_counts).zero_band
        side = {"+": enc > band, "-": enc < -band, "±": np.abs(enc) > band}
        for d in wanted:
            counts[d] += int(side[d].sum())
        step = np.diff(df["time_s"].to_numpy(dtype=float))
        if step.size:
            rates.append(1.0 / float(np.median(step)))
    need = fit_config.min_block_samples
    files = ", ".join(map(str, paths))
    if not any(counts.values()):
        which = "" if directions is None else f" in direction {'/'.join(directions)}"
        return (
            f"no {axis} motion{which} in {files}: enc_{axis} never leaves its zero band "
            f"(check --axis, and --columns/[columns] enc_{axis})"
        )
    got = ", ".join(f"{d}: {n}" for d, n in counts.items())
    rate = f", {need / min(rates):.3g} s of motion at {min(rates):.3g} Hz" if rates else ""
    return (
        f"too little {axis} motion in {files}: fewer than {need} samples leave the zero band "
        f"of enc_{axis} in each motion direction ({got}); a direction needs at least {need} "
        f"([fit] min_block_samples{rate}): record longer or at a higher rate (or lower "
        "[fit] min_block_samples)"
    )


def recording_summary(whole: Sequence[Dataset]) -> tuple[Excursions, MotorsTogether | None]:
    """How the recording drives the axis, over all its files: the excursions of its
    signed input (:func:`~i2ris_calib.data.excursions.excursions`) and how the other
    motor moves with it (:func:`~i2ris_calib.data.coupling.motors_together`; None
    without the other motor's input). ``whole``: the signed datasets of the axis."""
    counts = [astuple(excursions(d.enc, d.bands.zero_band, d.time_s)) for d in whole]
    recording = Excursions(*(int(sum(c)) for c in zip(*counts, strict=True)))
    if any(d.signals.v_other is None for d in whole):
        return recording, None
    other = other_axis(whole[0].axis)
    enc = np.concatenate([d.enc for d in whole])
    enc_other = np.concatenate([np.asarray(d.signals.v_other, float) for d in whole])
    return recording, motors_together(enc, enc_other, other)


def datasets_for_fit(
    paths: Sequence[str | Path], axis: str, fit_config, model: str = "all", columns=None
) -> tuple[list[Dataset], Any]:
    """The datasets of a fit and the model choice (:func:`~i2ris_calib.fitting.pipeline.
    choose_model`): unless ``[fit] signed`` forces it, the recording's excursions
    (:func:`~i2ris_calib.data.excursions.excursions`, over all files) decide between
    the signed dataset of the axis and the paper's per-direction split; whether the
    other motor moves with this one decides the coupled model (:func:`recording_summary`).
    ``columns``: the files' column mapping (``[columns]``, default the standard names).
    Each file is read once (:func:`read_frames`)."""
    return frames_for_fit(read_frames(paths, axis, columns), axis, fit_config, model)


def frames_for_fit(
    frames: Sequence[tuple[str, pd.DataFrame]], axis: str, fit_config, model: str = "all"
) -> tuple[list[Dataset], Any]:
    """:func:`datasets_for_fit` of files already read (:func:`read_frames`): the signed
    datasets or the split, from the same frames, and the model choice."""
    whole = frame_datasets(frames, axis, replace(fit_config, signed=True, split=False))
    recording, together = recording_summary(whole)
    from i2ris_calib.fitting.pipeline import choose_model

    choice = choose_model(None if fit_config.signed else recording, fit_config, model, together)
    if choice.signed:
        return whole, choice
    split_config = replace(fit_config, signed=False, split=False)
    return frame_datasets(frames, axis, split_config), choice


def load_synced(
    paths: Sequence[str | Path],
    axis: str,
    fit_config,
    directions: tuple[str, ...] | None = None,
    columns: ColumnsConfig | None = None,
) -> list[Dataset]:
    """The datasets ``fit`` fits on these synced CSVs (the public ``load_synced``): the
    signed dataset of the axis or the paper's per-direction split, as the recording
    calls for (:func:`datasets_for_fit`, one rule for the CLI and the API); with
    ``directions`` only those direction datasets (:func:`load_datasets`)."""
    if directions is not None:
        return load_datasets(paths, axis, fit_config, directions, columns)
    return datasets_for_fit(paths, axis, fit_config, columns=columns)[0]
