"""One data layer: a synced recording's axis -> motion-direction datasets.

A hysteresis model carries state (its play operators), so it must see the whole
input history in time order. A motion-direction dataset is therefore *never* a
subset of the samples: it is the whole recording, with

* the **input that direction sees** (``v = max(enc, 0)`` for ``"+"``,
  ``v = max(-enc, 0)`` for ``"-"``: while the motor is on the other side of zero the
  direction's input rests at 0; ``v = enc`` for the signed dataset ``"±"``), and
* the **loss mask**: the samples that belong to the direction. Only those enter the
  fit's loss and the metrics; every other sample still drives the model.

Sign convention (the paper fits |counts| -> |deg| for a negative-input dataset): in
a ``"-"`` dataset the angle is ``-theta``, which equals |theta| on the direction's
samples. Predictions of a ``"-"`` model are in the same convention; multiply by -1
for the robot's signed angle.

Attribution of a sample to a direction: ``enc > zero_band`` -> "+", ``enc <
-zero_band`` -> "-", and a sample inside the zero band (the axis at rest near zero)
belongs to the excursion that came before it (its angle is that excursion's residual
deflection); rest samples before the first excursion belong to the first one. No
sample is dropped.

Bands (``zero_band``, ``deadband``) are in the input's own unit. Negative settings
mean "derive from the input" (:func:`input_bands`), so nothing depends on whether
the input is in encoder counts or volts. The bands are the models' (the ``v'`` dead band
of the EGPI switch): they live in :mod:`i2ris_calib.hysteresis.bands`, re-exported here.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

import i2ris_calib._display as _display
from i2ris_calib._validate import (
    as_1d_bool,
    as_1d_float,
    as_real,
    check_choice,
    check_choices,
    check_instance,
    check_signals,
    check_str,
    describe,
    same_length,
)
from i2ris_calib.data.cycles import cycle_index, holdout_mask
from i2ris_calib.errors import CalibError
from i2ris_calib.hysteresis.bands import Bands, input_bands
from i2ris_calib.model import Signals

DIRECTIONS = ("+", "-", "±")
AXES = ("yaw", "pitch")


def other_axis(axis: str) -> str:
    """The other bending axis: ``"pitch"`` for ``"yaw"`` and vice versa."""
    return "pitch" if axis == "yaw" else "yaw"


def direction_of_samples(enc: np.ndarray, zero_band: float) -> np.ndarray:
    """Direction each sample belongs to: int8 (n,), +1 ("+"), -1 ("-"), 0 (no excursion).

    Outside the zero band the sign of ``enc``; inside it, the direction of the last
    excursion (the first excursion's for rest samples before it). 0 only when the
    input never leaves the band.
    """
    e = np.asarray(enc, dtype=float)
    d = np.where(e > zero_band, 1, np.where(e < -zero_band, -1, 0)).astype(np.int8)
    moving = np.flatnonzero(d != 0)
    if moving.size == 0:
        return d
    idx = np.zeros(d.size, dtype=int)
    idx[moving] = moving
    idx = np.maximum.accumulate(idx)
    idx[: moving[0]] = moving[0]
    return d[idx]


def direction_input(enc: np.ndarray, direction: str) -> np.ndarray:
    """The input a direction's model sees (input unit), shape (n,).

    ``"+"``: ``max(enc, 0)``; ``"-"``: ``max(-enc, 0)``; ``"±"``: ``enc``.
    """
    e = np.asarray(enc, dtype=float)
    if direction == "+":
        return np.maximum(e, 0.0)
    if direction == "-":
        return np.maximum(-e, 0.0)
    if direction == "±":
        return e.copy()
    raise ValueError(f"direction must be one of {', '.join(DIRECTIONS)}, got {direction!r}")


def direction_sign(direction: str) -> float:
    """-1 for a ``"-"`` dataset (angle sign flipped, the paper's |deg|), else +1."""
    return -1.0 if direction == "-" else 1.0


@dataclass(frozen=True)
class Dataset:
    """One axis and motion direction of a recording, over its whole history.

    Attributes
    ----------
    name : str
        ``"<axis><direction>"``, e.g. ``"yaw+"``, ``"pitch-"``, ``"yaw±"``.
    axis : str
        ``"yaw"`` or ``"pitch"``.
    direction : str
        ``"+"``, ``"-"`` or ``"±"`` (the signed input, one model across zero).
    signals : Signals
        Every sample in time order: ``v`` = the direction's input (input unit, see
        :func:`direction_input`), ``t_s`` (s), ``v_other`` (the other axis's signed
        input) and ``theta_other_deg`` when known.
    theta_deg : ndarray, shape (n,)
        Angle in the direction's convention (``-theta`` for ``"-"``), NaN where not
        measured *or* not in this direction: the loss and the metrics see exactly the
        finite samples.
    theta_measured_deg : ndarray, shape (n,)
        Angle in the direction's convention on every measured sample (for figures).
    in_direction : ndarray of bool, shape (n,)
        Samples that belong to this direction (:func:`direction_of_samples`).
    holdout : ndarray of bool, shape (n,)
        Held-out samples (whole loading cycles of this direction, metrics only).
    enc : ndarray, shape (n,)
        The axis's signed input as recorded.
    bands : Bands
        Zero band and ``v'`` dead band used (input unit).
    source : str
        Where the samples came from (file path), for messages.
    rows : dict
        Row accounting: ``total``, ``in_direction``, ``angle_missing`` (in direction,
        angle not measured), ``holdout``, ``fitted``.
    """

    name: str
    axis: str
    direction: str
    signals: Signals
    theta_deg: np.ndarray
    theta_measured_deg: np.ndarray
    in_direction: np.ndarray
    holdout: np.ndarray
    enc: np.ndarray
    bands: Bands
    source: str = ""
    rows: dict = field(default_factory=dict)

    @property
    def v(self) -> np.ndarray:
        """The direction's input, shape (n,)."""
        return self.signals.v

    @property
    def time_s(self) -> np.ndarray:
        """Sample times (s), shape (n,)."""
        return self.signals.t_s

    @property
    def sign(self) -> float:
        """-1 for a ``"-"`` dataset, else +1 (angle convention)."""
        return direction_sign(self.direction)

    @property
    def abs_fitted(self) -> bool:
        """True for a ``"-"`` dataset (|input| -> |angle|, the paper's convention)."""
        return self.direction == "-"

    @property
    def fit_mask(self) -> np.ndarray:
        """Samples in the loss: in direction, angle measured, not held out, shape (n,)."""
        return np.isfinite(self.theta_deg) & ~self.holdout

    @property
    def n_samples(self) -> int:
        """Samples in the recording (every one drives the model)."""
        return int(self.v.size)

    def _display_facts(self) -> list[tuple[str, str]]:
        """(label, text) of what :meth:`__repr__` and :meth:`_repr_html_` show (counts
        and ranges only: cheap on any recording)."""
        v = np.asarray(self.v, dtype=float)
        th = np.asarray(self.theta_deg, dtype=float)
        fitted = int(np.sum(np.isfinite(th) & ~np.asarray(self.holdout, bool)))
        held = int(np.sum(np.isfinite(th) & np.asarray(self.holdout, bool)))
        num = _display.num
        measured = th[np.isfinite(th)]
        angle = f"{num(measured.min())}..{num(measured.max())} deg" if measured.size else "none"
        t = self.time_s
        facts = [
            ("samples", f"{v.size} ({fitted} fitted, {held} held out)"),
            ("input", f"{num(v.min())}..{num(v.max())}" if v.size else "empty"),
            ("angle", angle),
        ]
        if t is not None and np.size(t) > 1:
            facts.append(("duration", f"{num(float(t[-1]) - float(t[0]))} s"))
        if self.source:
            facts.append(("source", os.path.basename(str(self.source))))
        return facts

    def __repr__(self) -> str:
        facts = dict(self._display_facts())
        text = (
            f"<Dataset {self.name}: {facts['samples'].replace(' (', ' samples (', 1)}, "
            f"input {facts['input']}, "
            f"angle {facts['angle']}" + (f", {facts['source']}" if "source" in facts else "") + ">"
        )
        return _display.clip(text)

    def _repr_html_(self) -> str:
        """Notebook display: samples, input and angle ranges, duration, source."""
        title = f"<b>Dataset</b> {_display.esc(self.name)}"
        return _display.table(("", ""), self._display_facts(), title)


_ANGLE_HINT = "mark an unmeasured angle with NaN, never inf"
_INPUT_HINT = "an input must be finite everywhere (angles may be NaN: unmeasured)"


@dataclass(frozen=True)
class _Inputs:
    """The arrays of :func:`make_dataset` / :func:`direction_datasets`, checked."""

    time_s: np.ndarray
    enc: np.ndarray
    theta: np.ndarray
    enc_other: np.ndarray | None
    theta_other: np.ndarray | None


def _checked_inputs(
    func, axis, time_s, enc, theta_deg, enc_other, theta_other_deg, bands, holdout_fraction,
    source,
) -> _Inputs:  # fmt: skip
    """CalibError naming ``func`` and the argument on any misuse (see docs/api.md):
    an unknown axis, arrays that are not 1-D numbers of one length, NaN or inf in an
    input (time, encoders), inf in an angle, decreasing time, bands that are not a
    :class:`Bands`, a held-out fraction outside [0, 1)."""
    check_choice(func, "axis", axis, AXES)
    t = as_1d_float(func, "time_s", time_s, min_size=1, hint=_INPUT_HINT)
    e = as_1d_float(func, "enc", enc, hint=_INPUT_HINT)
    th = as_1d_float(func, "theta_deg", theta_deg, nan_ok=True, hint=_ANGLE_HINT)
    eo = None if enc_other is None else as_1d_float(func, "enc_other", enc_other, hint=_INPUT_HINT)
    tho = (
        None
        if theta_other_deg is None
        else as_1d_float(func, "theta_other_deg", theta_other_deg, nan_ok=True, hint=_ANGLE_HINT)
    )
    same_length(func, enc=e, time_s=t, theta_deg=th, enc_other=eo, theta_other_deg=tho)
    back = np.flatnonzero(np.diff(t) < 0)
    if back.size:
        k = int(back[0]) + 1
        raise CalibError(
            f"{func}: time_s decreases at index {k} ({t[k - 1]:.6g} -> {t[k]:.6g} s); give "
            "the samples in time order (sort all arrays by time)"
        )
    check_instance(func, "bands", bands, Bands, none_ok=True, hint="or None: derived")
    as_real(func, "holdout_fraction", holdout_fraction, lo=0.0, hi=1.0, hi_open=True)
    if not isinstance(source, os.PathLike):
        check_str(func, "source", source, "runs/s/sync/synced.csv")
    return _Inputs(t, e, th, eo, tho)


def checked_dataset(func: str, name: str, data: object) -> Dataset:
    """``data`` if it is a :class:`Dataset` whose arrays agree (a finite 1-D input, an
    angle and a held-out mask of its length), else CalibError naming ``func`` and
    ``name``: a list of datasets (``load_synced`` returns one), a (v, theta) tuple, a
    DataFrame, None, ... each with its fix."""
    if isinstance(data, (list, tuple)) and data and all(isinstance(d, Dataset) for d in data):
        names = ", ".join(d.name for d in data)
        raise CalibError(
            f"{func}: {name} is a {type(data).__name__} of {len(data)} "
            f"dataset{'s' if len(data) > 1 else ''} ({names}); "
            f"give one, e.g. {name}[0]"
        )
    if not isinstance(data, Dataset):
        hint = (
            "make_dataset(axis, direction, df['time_s'], df['enc_<axis>'], df['<axis>_deg'])"
            if _is_frame(data)
            else "make_dataset(...) or load_synced(path, axis)[0]"
        )
        raise CalibError(f"{func}: {name} is {describe(data)}; give a Dataset: {hint}")
    check_signals(func, f"{name}.signals", data.signals)
    n = data.signals.v.size
    th = as_1d_float(func, f"{name}.theta_deg", data.theta_deg, nan_ok=True, hint=_ANGLE_HINT)
    as_1d_bool(func, f"{name}.holdout", data.holdout, n)
    same_length(func, **{f"{name}.signals.v": data.signals.v, f"{name}.theta_deg": th})
    return data


def checked_directions(func: str, directions: object) -> tuple[str, ...]:
    """``directions`` as a tuple of directions (a str such as ``"+"`` or ``"+-"``: its
    characters), else CalibError."""
    if isinstance(directions, str):
        directions = tuple(directions)
    return check_choices(func, "directions", directions, DIRECTIONS, "('+', '-')")


def _is_frame(x: object) -> bool:
    return type(x).__name__ == "DataFrame"


def make_dataset(
    axis: str,
    direction: str,
    time_s: np.ndarray,
    enc: np.ndarray,
    theta_deg: np.ndarray,
    *,
    enc_other: np.ndarray | None = None,
    theta_other_deg: np.ndarray | None = None,
    bands: Bands | None = None,
    holdout_fraction: float = 0.25,
    source: str = "",
) -> Dataset:
    """The ``direction`` dataset of ``axis`` (see the module docstring).

    Parameters
    ----------
    axis : {"yaw", "pitch"}
    direction : {"+", "-", "±"}
    time_s, enc, theta_deg : ndarray, shape (n,)
        Sample times (s, increasing), the axis's signed input, its measured angle
        (deg, NaN where not measured).
    enc_other, theta_other_deg : ndarray, shape (n,), optional
        The other axis's signed input and angle (coupling effects).
    bands : Bands, optional
        Default: derived from ``enc`` (:func:`input_bands`).
    holdout_fraction : float
        Fraction of this direction's loading cycles held out (0 = none).

    Raises
    ------
    CalibError
        On a misuse, naming the argument: an unknown axis or direction; arrays that
        are not 1-D numbers of one length (a column (n, 1): ``.ravel()``); NaN or inf in
        ``time_s``, ``enc`` or ``enc_other`` (only angles may be NaN: unmeasured);
        decreasing ``time_s``; ``bands`` not a :class:`Bands`; ``holdout_fraction``
        outside [0, 1).
    """
    func = "make_dataset"
    check_choice(func, "direction", direction, DIRECTIONS)
    x = _checked_inputs(
        func, axis, time_s, enc, theta_deg, enc_other, theta_other_deg, bands,
        holdout_fraction, source,
    )  # fmt: skip
    return _make_dataset(axis, direction, x, bands, holdout_fraction, source)


def _make_dataset(
    axis: str, direction: str, x: _Inputs, bands: Bands | None, holdout_fraction: float, source: str
) -> Dataset:
    """:func:`make_dataset` on checked inputs."""
    enc, theta = x.enc, x.theta
    bands = input_bands(enc) if bands is None else bands
    sign = direction_sign(direction)
    v = direction_input(enc, direction)
    if direction == "±":
        mine = np.ones(enc.size, dtype=bool)
    else:
        mine = direction_of_samples(enc, bands.zero_band) == (1 if direction == "+" else -1)
    measured = sign * theta
    masked = np.where(mine, measured, np.nan)
    cyc = cycle_index(v, None)
    hold = holdout_mask(cyc, holdout_fraction, v) & mine if mine.any() else np.zeros_like(mine)
    sig = Signals(v=v, t_s=x.time_s, v_other=x.enc_other, theta_other_deg=x.theta_other)
    fitted = np.isfinite(masked) & ~hold
    rows = {
        "total": int(enc.size),
        "in_direction": int(mine.sum()),
        "angle_missing": int((mine & ~np.isfinite(theta)).sum()),
        "holdout": int((hold & np.isfinite(masked)).sum()),
        "fitted": int(fitted.sum()),
    }
    return Dataset(
        name=f"{axis}{direction}",
        axis=axis,
        direction=direction,
        signals=sig,
        theta_deg=masked,
        theta_measured_deg=measured,
        in_direction=mine,
        holdout=hold,
        enc=enc,
        bands=bands,
        source=str(source),
        rows=rows,
    )


def direction_datasets(
    axis: str,
    time_s: np.ndarray,
    enc: np.ndarray,
    theta_deg: np.ndarray,
    *,
    enc_other: np.ndarray | None = None,
    theta_other_deg: np.ndarray | None = None,
    bands: Bands | None = None,
    holdout_fraction: float = 0.25,
    min_samples: int = 50,
    signed: bool = False,
    directions: tuple[str, ...] | None = None,
    source: str = "",
) -> list[Dataset]:
    """Every motion-direction dataset of ``axis`` with >= ``min_samples`` samples.

    ``signed``: one ``"±"`` dataset (the whole signed input) instead of ``"+"`` and
    ``"-"``. ``directions`` restricts to the named ones. The count of a direction is
    its samples outside the zero band (an axis at rest is not a dataset).

    Raises
    ------
    CalibError
        On a misuse, naming the argument (as :func:`make_dataset`; ``min_samples`` an
        integer >= 1, ``signed`` a bool, ``directions`` a tuple of directions).
    """
    func = "direction_datasets"
    x = _checked_inputs(
        func, axis, time_s, enc, theta_deg, enc_other, theta_other_deg, bands,
        holdout_fraction, source,
    )  # fmt: skip
    as_real(func, "min_samples", min_samples, integer=True, lo=1)
    if not isinstance(signed, (bool, np.bool_)):
        raise CalibError(f"{func}: signed is {signed!r}; give True or False")
    if directions is not None:
        directions = checked_directions(func, directions)
    enc = x.enc
    bands = input_bands(enc) if bands is None else bands
    wanted = ("±",) if signed else ("+", "-")
    if directions is not None:
        wanted = tuple(d for d in wanted if d in directions)
    out = []
    for d in wanted:
        outside = (
            np.abs(enc) > bands.zero_band
            if d == "±"
            else (enc > bands.zero_band if d == "+" else enc < -bands.zero_band)
        )
        if outside.sum() < min_samples:
            continue
        out.append(_make_dataset(axis, d, x, bands, holdout_fraction, source))
    return out
