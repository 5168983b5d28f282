"""What the recording itself allows: its angle noise, its cycle-to-cycle repeatability,
model-free baselines, and the held-out error cross-validated over its cycles.

A model's held-out RMSE means little alone: 0.1 deg is excellent on a recording whose
cycles repeat to 0.1 deg and poor on one that repeats to 0.01. :func:`recording_limits`
states the yardsticks and says in plain words whether the model is at the limit of
this recording or what it leaves (fit.json ``datasets[].limits``, the report).

* **noise** (:func:`noise_sd`): from the high-frequency residual of the model, the
  robust sd of its first differences over consecutive measured samples divided by
  sqrt(2) (white noise doubles its variance under a difference; a smooth misfit
  hardly moves it).
* **repeatability** (:func:`repeatability`): the spread between cycles at the same
  input and direction of motion (RMS over input bins of the deviation of each cycle's
  mean angle from the mean over the cycles), among cycles of the same input range
  only (a smaller loop's branch differs by hysteresis, not by chance).
* **baselines** (:func:`line_baseline`, :func:`phase_baseline`): held-out RMSE of a
  straight line on the inputs (both motors' when the other moves), and for a periodic
  input the best Fourier series of the cycle's phase (harmonics chosen by BIC on the
  fitted samples).
* **cross-validation** (:func:`cross_validated`): on a recording of at most
  :data:`CV_MAX_CYCLES` cycles every eligible cycle is held out once and the model
  refitted from its full fit (a local search): the mean and the spread.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

CV_MAX_CYCLES = 8
"""Recordings with at most this many cycles get the held-out error cross-validated."""
AT_LIMIT_RATIO = 1.5
"""A model is "at the limit of this recording" when its held-out RMSE is at most this
many times the recording's floor (the larger of its noise and its repeatability)."""
REPEAT_BINS = 24
"""Input bins per branch for :func:`repeatability`."""
SAME_RANGE = 0.05
"""Cycles count as the same protocol when their input ranges agree within this share of
the recording's input span."""
MAX_HARMONICS = 12
"""Most harmonics :func:`phase_baseline` tries."""
MAD_SD = 1.4826
"""MAD -> sd of a normal distribution."""
REST_MIN_S = 1.0
"""A rest (input still) this long or longer is compared with the loop (:func:`rest_anomalies`)."""
REST_NEAR = 0.02
"""Moving samples within this share of the input span of a rest's input describe the
loop there."""
REST_OFF_FLOOR = 5.0
"""A rest is off the loop when its mean angle lies outside the loop's angles at its
input by more than this many times the recording's floor."""


@dataclass(frozen=True)
class CrossValidation:
    """Held-out RMSE with each eligible cycle held out once.

    Attributes
    ----------
    model : str
        The kind refitted.
    folds_rmse_deg : tuple of float
        Held-out RMSE of each fold (deg), in cycle order.
    cycles : tuple of int
        The held-out cycle of each fold.
    """

    model: str
    folds_rmse_deg: tuple[float, ...]
    cycles: tuple[int, ...]

    @property
    def mean_deg(self) -> float:
        """Mean of the folds' held-out RMSE (deg)."""
        return float(np.mean(self.folds_rmse_deg)) if self.folds_rmse_deg else math.nan

    @property
    def sd_deg(self) -> float:
        """Spread (sd) of the folds' held-out RMSE (deg); 0 with one fold."""
        x = np.asarray(self.folds_rmse_deg, dtype=float)
        return float(x.std(ddof=1)) if x.size > 1 else 0.0

    def as_dict(self) -> dict[str, Any]:
        return {
            "model": self.model,
            "folds_rmse_deg": list(self.folds_rmse_deg),
            "cycles": list(self.cycles),
            "mean_deg": self.mean_deg,
            "sd_deg": self.sd_deg,
        }


@dataclass(frozen=True)
class RecordingLimits:
    """The recording's own yardsticks and the model's place among them.

    Attributes
    ----------
    model : str or None
        The model judged (the recommended one).
    model_rmse_deg : float
        Its held-out RMSE (deg).
    noise_sd_deg : float
        Angle noise sd (deg), :func:`noise_sd`.
    repeatability_deg : float
        Cycle-to-cycle spread at the same input (deg), :func:`repeatability`; NaN when
        no two cycles cover the same input range.
    n_cycles_compared : int
        Cycles the repeatability compares (-1: not compared, the other motor moves).
    line_rmse_deg : float
        Held-out RMSE of a straight line on the inputs (deg).
    phase_rmse_deg : float
        Held-out RMSE of the best function of the phase (deg); NaN: the input is not
        periodic.
    phase_harmonics : int
        Its harmonics (0: not periodic).
    worst_sample : dict
        The held-out sample with the largest |error|: ``time_s``, ``error_deg``.
    crossval : CrossValidation or None
        Cross-validated held-out error (short recordings).
    without_worst_deg : float
        The model's held-out RMSE without its worst sample (deg).
    anomalies : tuple of str
        Warnings with numbers on the recording itself (:func:`rest_anomalies`).
    verdict : str
        Plain words: at the limit of this recording, or what the model leaves.
    """

    model: str | None
    model_rmse_deg: float
    noise_sd_deg: float
    repeatability_deg: float
    n_cycles_compared: int
    line_rmse_deg: float
    phase_rmse_deg: float
    phase_harmonics: int
    worst_sample: dict = field(default_factory=dict)
    crossval: CrossValidation | None = None
    without_worst_deg: float = math.nan
    anomalies: tuple[str, ...] = ()
    verdict: str = ""

    @property
    def floor_deg(self) -> float:
        """The recording's floor: the larger of its noise and repeatability (deg)."""
        vals = [x for x in (self.noise_sd_deg, self.repeatability_deg) if math.isfinite(x)]
        return max(vals) if vals else math.nan

    def as_dict(self) -> dict[str, Any]:
        """The fit.json ``limits`` record."""

        def num(x: float) -> float | None:
            return float(x) if math.isfinite(x) else None

        return {
            "model": self.model,
            "model_rmse_deg": num(self.model_rmse_deg),
            "noise_sd_deg": num(self.noise_sd_deg),
            "repeatability_deg": num(self.repeatability_deg),
            "n_cycles_compared": int(self.n_cycles_compared),
            "floor_deg": num(self.floor_deg),
            "ratio_to_floor": num(self.model_rmse_deg / self.floor_deg)
            if self.floor_deg > 0
            else None,
            "line_rmse_deg": num(self.line_rmse_deg),
            "phase_rmse_deg": num(self.phase_rmse_deg),
            "phase_harmonics": int(self.phase_harmonics),
            "worst_sample": self.worst_sample,
            "without_worst_deg": num(self.without_worst_deg),
            "crossval": None if self.crossval is None else self.crossval.as_dict(),
            "anomalies": list(self.anomalies),
            "verdict": self.verdict,
        }


def noise_sd(residuals: np.ndarray) -> float:
    """Angle noise sd (deg) from the high-frequency part of a model's residual.

    ``residuals``: shape (n,), model minus measured angle in time order (NaN where not
    measured). The robust sd (MAD) of the first differences over consecutive measured
    samples, divided by sqrt(2). NaN with fewer than 10 such pairs."""
    r = np.asarray(residuals, dtype=float)
    both = np.isfinite(r[1:]) & np.isfinite(r[:-1])
    d = np.diff(r)[both]
    if d.size < 10:
        return math.nan
    return float(MAD_SD * np.median(np.abs(d - np.median(d))) / math.sqrt(2.0))


def _ranges(v: np.ndarray, cycles: np.ndarray, own: np.ndarray) -> dict[int, tuple[float, float]]:
    out = {}
    for c in np.unique(cycles[own]):
        x = v[own & (cycles == c)]
        if x.size >= 4:
            out[int(c)] = (float(x.min()), float(x.max()))
    return out


def _alike(ranges: dict[int, tuple[float, float]], span: float) -> list[int]:
    """The largest group of cycles whose input ranges agree within :data:`SAME_RANGE`."""
    best: list[int] = []
    for lo, hi in ranges.values():
        group = [
            k
            for k, (a, b) in ranges.items()
            if abs(a - lo) <= SAME_RANGE * span and abs(b - hi) <= SAME_RANGE * span
        ]
        if len(group) > len(best):
            best = group
    return sorted(best)


def repeatability(v: np.ndarray, theta: np.ndarray, cycles: np.ndarray) -> tuple[float, int]:
    """(cycle-to-cycle spread of the angle at the same input and direction (deg), the
    cycles compared).

    ``v``, ``theta``, ``cycles``: shape (n,), the input, the measured angle (NaN where
    not measured) and each sample's cycle. Among the largest group of cycles with the
    same input range (:data:`SAME_RANGE`), each branch (input rising, falling) is cut
    into :data:`REPEAT_BINS` input bins; per bin the mean angle of each cycle; the
    pooled sd of those means about their mean over the cycles. (NaN, n) with fewer than
    two comparable cycles."""
    v, theta = np.asarray(v, dtype=float), np.asarray(theta, dtype=float)
    cycles = np.asarray(cycles, dtype=int)
    own = np.isfinite(theta)
    if own.sum() < 8:
        return math.nan, 0
    span = float(np.ptp(v[own])) or 1.0
    group = _alike(_ranges(v, cycles, own), span)
    if len(group) < 2:
        return math.nan, len(group)
    dv = np.gradient(v)
    edges = np.linspace(v[own].min(), v[own].max(), REPEAT_BINS + 1)
    ss, dof = 0.0, 0
    for branch in (dv > 0, dv < 0):
        for lo, hi in zip(edges[:-1], edges[1:], strict=True):
            sel = own & branch & (v >= lo) & (v <= hi)
            means = [
                theta[sel & (cycles == c)].mean() for c in group if (sel & (cycles == c)).any()
            ]
            if len(means) >= 2:
                m = np.asarray(means)
                ss += float(np.sum((m - m.mean()) ** 2))
                dof += m.size - 1
    if dof == 0:
        return math.nan, len(group)
    return float(math.sqrt(ss / dof)), len(group)


def _lstsq_holdout(x: np.ndarray, theta: np.ndarray, fit: np.ndarray, hold: np.ndarray) -> float:
    if fit.sum() <= x.shape[1] or not hold.any():
        return math.nan
    coef, *_ = np.linalg.lstsq(x[fit], theta[fit], rcond=None)
    e = x[hold] @ coef - theta[hold]
    return float(np.sqrt(np.mean(e**2)))


def line_baseline(
    v: np.ndarray, theta: np.ndarray, fit: np.ndarray, hold: np.ndarray,
    v_other: np.ndarray | None = None,
) -> float:  # fmt: skip
    """Held-out RMSE (deg) of a straight line on the inputs (``theta ~ a + b v (+ c
    v_other)``) fitted on the ``fit`` samples, evaluated on the ``hold`` ones."""
    cols = [np.ones_like(v, dtype=float), np.asarray(v, dtype=float)]
    if v_other is not None and np.ptp(np.asarray(v_other, dtype=float)) > 0:
        cols.append(np.asarray(v_other, dtype=float))
    return _lstsq_holdout(np.column_stack(cols), np.asarray(theta, float), fit, hold)


def cycle_phase(cycles: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Phase in [0, 1) of every sample within its cycle (time from the cycle's first
    sample over the cycle's duration), shape (n,)."""
    cycles, t = np.asarray(cycles, dtype=int), np.asarray(t, dtype=float)
    phase = np.zeros(t.size)
    for c in np.unique(cycles):
        idx = np.flatnonzero(cycles == c)
        t0 = t[idx[0]]
        nxt = idx[-1] + 1
        t1 = (
            t[nxt] if nxt < t.size else t[idx[-1]] + (t[idx[-1]] - t[idx[0]]) / max(idx.size - 1, 1)
        )
        phase[idx] = (t[idx] - t0) / (t1 - t0) if t1 > t0 else 0.0
    return phase


def is_periodic(v: np.ndarray, t: np.ndarray, cycles: np.ndarray) -> bool:
    """At least 3 whole cycles (the first and the last may be partial) whose input
    ranges agree within 2x :data:`SAME_RANGE` of the span: the same loop, repeated (its
    period may vary: the phase is taken within each cycle)."""
    cycles = np.asarray(cycles, dtype=int)
    ids = np.unique(cycles)[1:-1]
    if ids.size < 3:
        return False
    v = np.asarray(v, dtype=float)
    span = float(np.ptp(v)) or 1.0
    lo = np.array([v[cycles == c].min() for c in ids])
    hi = np.array([v[cycles == c].max() for c in ids])
    return bool(np.ptp(lo) <= 2 * SAME_RANGE * span and np.ptp(hi) <= 2 * SAME_RANGE * span)


def phase_baseline(
    phase: np.ndarray, theta: np.ndarray, fit: np.ndarray, hold: np.ndarray
) -> tuple[float, int]:
    """(held-out RMSE (deg), harmonics) of the best Fourier series of the phase: 1 to
    :data:`MAX_HARMONICS` harmonics, the number chosen by BIC on the ``fit`` samples."""
    theta = np.asarray(theta, dtype=float)
    best = (math.inf, 0, math.nan)
    n = int(fit.sum())
    for k in range(1, MAX_HARMONICS + 1):
        x = _fourier(phase, k)
        if n <= 2 * x.shape[1]:
            break
        coef, *_ = np.linalg.lstsq(x[fit], theta[fit], rcond=None)
        rss = float(np.sum((x[fit] @ coef - theta[fit]) ** 2))
        bic = n * math.log(max(rss, 1e-300) / n) + x.shape[1] * math.log(n)
        if bic < best[0]:
            best = (bic, k, _lstsq_holdout(x, theta, fit, hold))
    return best[2], best[1]


def _fourier(phase: np.ndarray, k: int) -> np.ndarray:
    w = 2 * np.pi * np.asarray(phase, dtype=float)
    cols = [np.ones_like(w)]
    for j in range(1, k + 1):
        cols += [np.cos(j * w), np.sin(j * w)]
    return np.column_stack(cols)


def verdict(lim: RecordingLimits) -> str:
    """Plain words on the model's held-out error against the recording's limits."""
    m, floor = lim.model_rmse_deg, lim.floor_deg
    if lim.model is None or not math.isfinite(m):
        return "no recommended model to judge"
    parts = [f"noise {lim.noise_sd_deg:.2g} deg"]
    if math.isfinite(lim.repeatability_deg):
        parts.append(f"cycle-to-cycle repeatability {lim.repeatability_deg:.2g} deg")
    else:
        parts.append(
            "repeatability not measurable ("
            + ("the other motor moves: cycles at one input differ by coupling"
               if lim.n_cycles_compared < 0
               else "no two cycles over the same input range")
            + ")"
        )  # fmt: skip
    base = f"held-out {m:.2g} deg against {', '.join(parts)}"
    if not math.isfinite(floor) or floor <= 0:
        text = f"{lim.model}: {base}"
    elif m <= AT_LIMIT_RATIO * floor:
        text = f"{lim.model} is at the limit of this recording ({base}; {m / floor:.2g}x its floor)"
    else:
        left = math.sqrt(max(m**2 - floor**2, 0.0))
        text = (
            f"{lim.model} leaves about {left:.2g} deg beyond this recording's limits ({base}; "
            f"{m / floor:.2g}x its floor): a missing effect, or a better model, can still gain"
        )
    w = lim.worst_sample
    if w and math.isfinite(lim.without_worst_deg) and lim.without_worst_deg < 0.7 * m:
        text += (
            f"; one sample carries much of it (t = {w['time_s']:.4g} s, {w['error_deg']:+.2g} "
            f"deg: an onset or a tracking glitch?): without it {lim.without_worst_deg:.2g} deg"
        )
    if math.isfinite(lim.phase_rmse_deg):
        cmp = "better than" if m < lim.phase_rmse_deg else "no better than"
        text += (
            f"; {cmp} the best function of the loop's phase ({lim.phase_rmse_deg:.2g} deg, "
            f"{lim.phase_harmonics} harmonics)"
        )
    if math.isfinite(lim.line_rmse_deg) and m >= lim.line_rmse_deg:
        text += f"; no better than a straight line on the inputs ({lim.line_rmse_deg:.2g} deg)"
    return text


def recording_limits(data, result, model: str | None, crossval: CrossValidation | None = None,
                     cycles: np.ndarray | None = None) -> RecordingLimits:  # fmt: skip
    """The :class:`RecordingLimits` of one dataset (``data``: a
    :class:`~i2ris_calib.data.dataset.Dataset`) judged with the fit ``result`` of
    ``model`` (its recommended model; None: the yardsticks alone, ``result`` may be
    None). ``cycles``: each sample's cycle (default :func:`data.cycles.cycle_index`)."""
    from i2ris_calib.data.cycles import cycle_index

    v = np.asarray(data.v, dtype=float)
    theta = np.asarray(data.theta_deg, dtype=float)
    cyc = cycle_index(v) if cycles is None else np.asarray(cycles, dtype=int)
    hold = np.asarray(data.holdout, bool) & np.isfinite(theta)
    fit = ~np.asarray(data.holdout, bool) & np.isfinite(theta)
    noise = noise_sd(result.residuals) if result is not None else math.nan
    rep, n_rep = repeatability(v, theta, cyc)
    vo = data.signals.v_other
    other_moves = vo is not None and bool(np.ptp(np.asarray(vo, dtype=float)[np.isfinite(vo)]) > 0)
    if other_moves:  # cycles at one input differ by the other motor's motion, not by chance
        rep, n_rep = math.nan, -1
    v_other = data.signals.v_other
    line = line_baseline(v, theta, fit, hold, v_other)
    t = np.asarray(data.time_s, dtype=float)
    phase_rmse, k = math.nan, 0
    if is_periodic(v, t, cyc):
        phase_rmse, k = phase_baseline(cycle_phase(cyc, t), theta, fit, hold)
    m = float(result.holdout_metrics.rmse_deg) if result is not None else math.nan
    worst = {}
    if result is not None and hold.any():
        err = np.asarray(result.residuals, dtype=float)
        e = np.where(hold, np.abs(err), -1.0)
        i = int(np.nanargmax(e))
        worst = {"time_s": float(t[i]), "error_deg": float(err[i]), "sample": i}
    ww = (
        float(getattr(result.holdout_metrics, "rmse_without_worst_deg", math.nan))
        if result is not None
        else math.nan
    )
    lim = RecordingLimits(model, m, noise, rep, n_rep, line, phase_rmse, k, worst, crossval, ww)
    odd = rest_anomalies(v, theta, t, lim.floor_deg, v_other)
    return RecordingLimits(**{**lim.__dict__, "anomalies": tuple(odd), "verdict": verdict(lim)})


def _runs(still: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of every run of True in ``still``."""
    edges = np.flatnonzero(np.diff(np.r_[0, still.astype(np.int8), 0]))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))


def rest_anomalies(
    v: np.ndarray, theta: np.ndarray, t: np.ndarray, floor: float,
    v_other: np.ndarray | None = None,
) -> list[str]:  # fmt: skip
    """Warnings for rests whose angle lies outside the loop's angles at the same input.

    A rest is a run of at least :data:`REST_MIN_S` s (and 5 samples) with the input
    still inside its range (not at either end, where the operators clamp and no loop
    passes), and the other motor still too when there is one (its motion moves the
    angle through coupling: that is not a rest). The loop at the rest's input is the range of
    the measured angles of the moving samples within :data:`REST_NEAR` of the span, on
    both branches (rising and falling). A rest whose mean measured angle lies outside
    that range by more than :data:`REST_OFF_FLOOR` x ``floor`` (the recording's noise or
    repeatability, deg) is named with its numbers."""
    v, theta, t = (np.asarray(x, dtype=float) for x in (v, theta, t))
    if v.size < 10 or not math.isfinite(floor):
        return []
    span = float(np.ptp(v)) or 1.0
    dv = np.r_[0.0, np.diff(v)]
    still = np.abs(dv) <= 1e-9 * span
    if v_other is not None:
        vo = np.asarray(v_other, dtype=float)
        span_o = float(np.ptp(vo[np.isfinite(vo)])) if np.isfinite(vo).any() else 0.0
        still &= np.abs(np.r_[0.0, np.diff(vo)]) <= 1e-9 * max(span_o, 1.0)
    out = []
    for a, b in _runs(still):
        a = max(a - 1, 0)  # the sample the input stopped at
        if b - a < 5 or t[b - 1] - t[a] < REST_MIN_S:
            continue
        level = float(np.median(v[a:b]))
        if not (v.min() + REST_NEAR * span < level < v.max() - REST_NEAR * span):
            continue  # at an end of the input range the operators clamp: no loop to compare
        at_rest = theta[a:b][np.isfinite(theta[a:b])]
        near = ~still & np.isfinite(theta) & (np.abs(v - level) <= REST_NEAR * span)
        near[a:b] = False  # the rest's own samples (the one it stopped at included)
        rising, falling = near & (dv > 0), near & (dv < 0)
        if at_rest.size < 3 or not rising.any() or not falling.any():
            continue
        lo, hi = float(theta[near].min()), float(theta[near].max())
        mean = float(at_rest.mean())
        off = max(lo - mean, mean - hi, 0.0)
        if off > REST_OFF_FLOOR * floor:
            out.append(
                f"a rest of {t[b - 1] - t[a]:.3g} s at input {level:.4g} (t = {t[a]:.4g}-"
                f"{t[b - 1]:.4g} s) sits at {mean:.3g} deg, {off:.2g} deg outside the loop's "
                f"angles there ({lo:.3g} to {hi:.3g} deg): not on the loop (drift, a "
                "slipped marker or another experiment?); if it is not part of the "
                "experiment, leave it out (a status column) and refit"
            )
    return out


def cv_folds(cycles: np.ndarray, v: np.ndarray, own: np.ndarray) -> list[int]:
    """The cycles held out in turn by :func:`cross_validated`: every cycle but the
    first (it carries the start state) with measured samples, whose input range lies
    within that of the other cycles (a fold tests interpolation); empty when the
    recording has more than :data:`CV_MAX_CYCLES` cycles or fewer than 3."""
    cycles = np.asarray(cycles, dtype=int)
    ids = [int(c) for c in np.unique(cycles[own])]
    n = int(cycles.max()) + 1 if cycles.size else 0
    if n > CV_MAX_CYCLES or n < 3:
        return []
    out = []
    for c in ids:
        if c == 0:
            continue
        inside, rest = own & (cycles == c), own & (cycles != c)
        if inside.any() and rest.any():
            if v[inside].min() >= v[rest].min() and v[inside].max() <= v[rest].max():
                out.append(c)
    return out


def cross_validated(
    kind: str, data, refit: Callable[[np.ndarray], Any], cycles: np.ndarray | None = None
) -> CrossValidation | None:
    """Each fold of :func:`cv_folds` held out once: ``refit(holdout_mask)`` returns the
    model refitted with that cycle held out (a FitResult); None when the recording has
    no folds (long, or fewer than 3 cycles)."""
    from i2ris_calib.data.cycles import cycle_index

    v = np.asarray(data.v, dtype=float)
    theta = np.asarray(data.theta_deg, dtype=float)
    cyc = cycle_index(v) if cycles is None else np.asarray(cycles, dtype=int)
    own = np.isfinite(theta)
    folds = cv_folds(cyc, v, own)
    if len(folds) < 2:
        return None
    rmse = []
    for c in folds:
        res = refit(cyc == c)
        rmse.append(float(res.holdout_metrics.rmse_deg))
    return CrossValidation(kind, tuple(rmse), tuple(folds))


def dataset_limits(data, results: dict, decision, config) -> RecordingLimits:
    """:func:`recording_limits` of one dataset judged with its recommended model
    (``decision``: :class:`~i2ris_calib.fitting.decision.Decision`; its fallback when
    none is recommended), cross-validated on a short recording (:func:`cross_validated`:
    each fold refitted from the full fit's values by a local search: one start, no
    restarts, the kind's method). ``results``: kind -> FitResult;
    ``config``: the FitConfig."""
    from dataclasses import replace

    from i2ris_calib.data.cycles import cycle_index
    from i2ris_calib.fitting.pipeline import _fit_configured
    from i2ris_calib.hysteresis.registry import BUILT_KINDS

    kind = decision.model if decision.model is not None else decision.fallback
    result = results.get(kind) if kind is not None else None
    cyc = cycle_index(np.asarray(data.v, dtype=float))
    cv = None
    if result is not None:
        local = replace(config, max_restarts=0)
        x0 = np.array([p.value for p in result.model.parameters], dtype=float)

        def refit(hold: np.ndarray):
            # a local search from the full fit (its basin), the kind's method
            return _fit_configured(result.model, data.signals, data.theta_deg, hold, [x0],
                                   local, kind if kind in BUILT_KINDS else None)  # fmt: skip

        cv = cross_validated(kind, data, refit, cyc)
    return recording_limits(data, result, kind if result is not None else None, cv, cyc)
