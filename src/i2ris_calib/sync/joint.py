"""Clock offset (and drift) estimated jointly with the hysteresis model.

Without a sync event the only link between the clocks is the motion itself. Plain
cross-correlation mistakes the hysteresis lag for clock offset; here the offset is
the one at which the hysteresis model (fitted anew at each candidate) explains the
measured angle best:

0. the model of each axis is the one ``fit`` would choose for it
   (:func:`i2ris_calib.fitting.pipeline.choose_model` on the axis's excursions and
   how the other motor moves with it, at the starting offset): on a recording shaped
   like the paper's protocol (excursions from rest, one side at a time) the paper's
   per-direction model ``[sync] model`` (EGPI or GPI); on one whose input crosses
   zero or does not start at rest, one model over the axis's whole signed input (the
   two-tendon GPI, with coupling to the other motor's input when that motor moves
   with this one and the recording can separate it). A per-direction model on such a
   recording leaves degrees of misfit at every zero crossing (the loop memory the
   split throws away), and its offset profile then has no usable minimum;
1. frames are mapped to the controller clock with a candidate clock, the encoder is
   interpolated there, and the model is fitted per axis and motion direction
   (``i2ris_calib.fitting``) over the axis's **whole frame history**: one sequence of
   every frame in time order, the direction's input ``max(+-enc, 0)`` on all of them
   (the signed input, and the other motor's, for the signed kinds), the loss
   restricted to the direction's measured samples (exactly the attribution of
   ``i2ris_calib.data.dataset``); the objective is the total (trimmed) residual sum
   of squares;
2. the offset profile is scanned on a grid around the cross-correlation offset and
   refined by golden-section search; its curvature, inflated for model misfit and
   residual autocorrelation (:func:`offset_stderr`), gives the standard error;
3. drift: with the fitted models held fixed, a Gauss-Newton step on (offset, drift)
   over all frames, then the offset profile is refined again at the new drift.

The frame set and the direction attribution are fixed for a profile (at the coarse
offset, then again at the scanned minimum), so the objective is a smooth function
of the offset and not of which samples happen to be in range. Frames are only ever
truncated at the ends of the recording (where a candidate offset could map them
outside the encoder log), never dropped in the middle: the play operators carry
state, and a spliced input would show them fake steps.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from i2ris_calib.data.coupling import motors_together
from i2ris_calib.data.cycles import cycle_index
from i2ris_calib.data.dataset import Bands, direction_datasets, direction_input, input_bands
from i2ris_calib.data.excursions import excursions
from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.config import FitConfig
from i2ris_calib.fitting.fit import PROFILE_PARAMS, fit_from_state, fit_model
from i2ris_calib.fitting.pipeline import choose_model, fit_kind, unfitted_model
from i2ris_calib.fitting.prehistory import InitialState
from i2ris_calib.fitting.result import output_after_state
from i2ris_calib.hysteresis.registry import kind_info
from i2ris_calib.model import Signals
from i2ris_calib.sync.clock import PPM, ClockModel, clock_from_offsets, clock_model
from i2ris_calib.sync.config import SyncConfig
from i2ris_calib.sync.log import EncoderLog
from i2ris_calib.sync.xcorr import AxisSeries, coarse_xcorr_offset

GOLDEN = (np.sqrt(5.0) - 1.0) / 2.0
REST_KEEP_S = 0.5
"""Seconds of each rest at zero (input inside the zero band) kept in the sync loss."""


@dataclass(frozen=True)
class DirectionBlock:
    """One axis and motion direction over the axis's whole frame history.

    Attributes
    ----------
    name : str
        e.g. ``"yaw+"``, ``"pitch-"`` (``"yaw±"`` with ``[fit] signed``).
    channel : str
        Encoder channel of the axis.
    direction : str
        ``"+"``, ``"-"`` or ``"±"``: the model's input is
        ``direction_input(enc, direction)`` (``max(enc, 0)``, ``max(-enc, 0)``, ``enc``).
    t_cam_s : ndarray, shape (m,)
        Every frame of the axis in time order (camera clock, s), measured or not.
    theta_deg : ndarray, shape (m,)
        Angle in the direction's convention (``-theta`` for ``"-"``), NaN where not
        measured or not in this direction (out of the loss; the model still runs).
    in_direction : ndarray of bool, shape (m,)
        Frames attributed to this direction (``data.dataset.direction_of_samples``).
    bands : Bands
        Zero band and ``v'`` dead band of the axis (encoder counts), fixed for the profile.
    kind : str
        Model kind fitted to the block (registry name); "" = the profile's ``[sync] model``.
    other_channel : str or None
        Encoder channel of the other motor, the coupled kinds' second input.
    why : str
        Why this model (:attr:`i2ris_calib.fitting.pipeline.ModelChoice.line`).
    """

    name: str
    channel: str
    direction: str
    t_cam_s: np.ndarray
    theta_deg: np.ndarray
    in_direction: np.ndarray
    bands: Bands
    kind: str = ""
    other_channel: str | None = None
    why: str = ""

    @property
    def sign(self) -> float:
        """-1 for a ``"-"`` block (angle sign flipped), else +1."""
        return -1.0 if self.direction == "-" else 1.0

    @property
    def n_loss(self) -> int:
        """Frames in the loss (in direction, angle measured)."""
        return int(np.isfinite(self.theta_deg).sum())


def map_times(t_cam_s: np.ndarray, offset_c_s: float, drift_ppm: float, t_c_s: float) -> np.ndarray:
    """Controller times for a clock given by its offset at camera time ``t_c_s``."""
    return offset_c_s + t_c_s + (1.0 + drift_ppm * PPM) * (np.asarray(t_cam_s) - t_c_s)


def model_blocks(
    series: list[AxisSeries],
    log: EncoderLog,
    offset_c_s: float,
    t_c_s: float,
    margin_s: float,
    fit_config,
    min_range_counts: float,
) -> list[DirectionBlock]:
    """Motion-direction blocks of each moving axis, each over the axis's whole history.

    Per axis ONE sequence of frames: every frame whose mapped time stays inside the
    log for every offset within ``offset_c_s +- margin_s`` (a contiguous run: frames
    are truncated at the ends, never dropped in the middle; unmeasured frames stay,
    with NaN angle). The blocks of an axis share these frames; each gets the
    direction's input and its own loss mask, attributed by
    :func:`i2ris_calib.data.dataset.direction_datasets` with the axis's bands
    (``[fit] zero_band_counts``/``deadband_counts``, negative = derived from the
    input) exactly as ``fit`` does. An axis whose encoder spans less than
    ``min_range_counts`` is skipped, and so is a direction with fewer than
    ``fit_config.min_block_samples`` frames outside the zero band.

    The model of an axis is the one ``fit`` would choose (:func:`axis_choice`): on a
    signed choice the axis is ONE block ``"<axis>±"`` fitted with the chosen kind
    (the two-tendon GPI, coupled to the other motor's channel when it moves with this
    one); else the per-direction blocks, fitted with ``[sync] model`` (``kind`` "").

    Parameters
    ----------
    series : list of AxisSeries
        Per axis every frame in time order (``theta_deg`` NaN where not measured).
    log : EncoderLog
    offset_c_s, t_c_s : float
        Offset at camera time ``t_c_s`` (s) used to attribute frames to directions.
    margin_s : float
        Half-width of the offsets the blocks must stay valid for, s.
    fit_config : FitConfig
    min_range_counts : float

    Returns
    -------
    list of DirectionBlock
    """
    lo, hi = log.time_range()
    blocks = []
    for s in series:
        tc = map_times(s.t_cam_s, offset_c_s, 0.0, t_c_s)
        keep = np.flatnonzero((tc - margin_s >= lo) & (tc + margin_s <= hi))
        if keep.size < 8:
            continue
        run = slice(keep[0], keep[-1] + 1)  # contiguous (times increase): ends only
        t, th = s.t_cam_s[run], s.theta_deg[run]
        enc = log.interpolate(s.channel, tc[run])
        if not np.isfinite(enc).all() or np.ptp(enc) < min_range_counts:
            continue
        bands = input_bands(enc, fit_config.zero_band_counts, fit_config.deadband_counts)
        other = next((o.channel for o in series if o.channel != s.channel), None)
        enc_other = None if other is None else log.interpolate(other, tc[run])
        if enc_other is not None and not np.isfinite(enc_other).all():
            enc_other = None
        choice = axis_choice(s.axis, t, enc, enc_other, bands, fit_config)
        kind = choice.main if choice.signed else ""
        coupled = bool(kind) and kind_info(kind).coupled
        datasets = direction_datasets(
            s.axis, t, enc, th, bands=bands, holdout_fraction=0.0,
            min_samples=fit_config.min_block_samples, signed=choice.signed,
        )  # fmt: skip
        quiet = long_rest(t, enc, bands.zero_band)
        for ds in datasets:
            theta = np.where(quiet, np.nan, ds.theta_deg)
            if np.isfinite(theta).sum() < 16:
                continue
            other_ch = other if coupled else None
            block = DirectionBlock(
                ds.name, s.channel, ds.direction, t, theta, ds.in_direction, bands
            )
            blocks.append(replace(block, kind=kind, other_channel=other_ch, why=choice.line))
    return blocks


def axis_choice(axis: str, t_s, enc, enc_other, bands: Bands, fit_config):
    """The model ``fit`` would choose for an axis (:func:`~i2ris_calib.fitting.pipeline.
    choose_model`) from its signed input ``enc`` and the other motor's ``enc_other``
    (counts, shape (m,), or None) at frame times ``t_s`` (s)."""
    recording = excursions(enc, bands.zero_band, np.asarray(t_s, dtype=float))
    other = "pitch" if axis == "yaw" else "yaw"
    together = motors_together(enc, enc_other, other)
    return choose_model(None if fit_config.signed else recording, fit_config, "all", together)


def long_rest(t_s: np.ndarray, enc: np.ndarray, zero_band: float) -> np.ndarray:
    """Frames resting at zero for longer than :data:`REST_KEEP_S` (bool, shape (m,)).

    A frame inside the zero band more than ``REST_KEEP_S`` after the input entered it.
    These frames still drive the model (whole history) but leave the *sync* loss: the
    input does not change there, so they carry no clock information, while their angle
    is where slow effects no hysteresis model has live (creep, relaxation of the
    residual deflection). Kept: the first ``REST_KEEP_S`` of each rest, where the input
    stops (a corner that does carry timing information).
    """
    band = np.abs(np.asarray(enc, dtype=float)) <= zero_band
    start = np.flatnonzero(band & ~np.concatenate(([False], band[:-1])))
    idx = np.zeros(band.size, dtype=int)
    idx[start] = start
    idx = np.maximum.accumulate(idx)
    return band & (np.asarray(t_s) - np.asarray(t_s)[idx] > REST_KEEP_S)


class OffsetProfile:
    """Residual sum of squares of the hysteresis fits as a function of the offset.

    Each evaluation refits every block. Starts: the fits at the two nearest offsets
    evaluated so far and the best fit found anywhere (warm starts), plus, while
    ``cold`` is True (the coarse scan), the fitter's own data-driven multi-start; the
    lowest residual wins. A warm-start chain alone can stay in a poor local minimum
    found far from the true offset. Results are cached by offset.

    A warm start is refitted twice: with its start state searched again (the fitter's
    own local search) and with its start state held (:func:`held_state_fit`: the
    pre-history of a recording that starts mid-loop is the same whatever the clock, so
    the profile stays a smooth function of the offset; its levels re-searched at every
    offset made the lab session's profile jump between start states).

    ``seeds``: ``{block name: fit}`` (FitResult or :class:`StartEval`) tried as starts
    (from an earlier profile); with seeds the profile starts warm.
    """

    def __init__(self, blocks, log, t_c_s, drift_ppm, kind, fit_config, seeds=None):
        self.blocks, self.log, self.t_c, self.drift = blocks, log, t_c_s, drift_ppm
        self.kind, self.fit_config = kind, fit_config
        self.cache: dict[float, tuple[float, list]] = {}
        self.n_samples = sum(b.n_loss for b in blocks)
        self.n_params = 0
        self.cold = seeds is None
        self.seeds = seeds or {}

    def inputs(self, block: DirectionBlock, offset_c_s: float, drift_ppm: float | None = None):
        """The direction's input (counts), shape (m,), of ``block`` at a candidate clock;
        for a coupled block the :class:`Signals` with the other motor's input too."""
        d = self.drift if drift_ppm is None else drift_ppm
        tc = map_times(block.t_cam_s, offset_c_s, d, self.t_c)
        v = direction_input(self.log.interpolate(block.channel, tc), block.direction)
        if block.other_channel is None:
            return v
        return Signals(v=v, v_other=self.log.interpolate(block.other_channel, tc))

    def kind_of(self, block: DirectionBlock) -> str:
        """The model kind fitted to ``block``."""
        return block.kind or self.kind

    def __call__(self, offset_c_s: float) -> float:
        key = round(float(offset_c_s), 9)
        if key not in self.cache:
            self.cache[key] = self._fit(key)
        return self.cache[key][0]

    def fits(self, offset_c_s: float) -> list:
        """FitResults of the blocks at an evaluated offset."""
        self(offset_c_s)
        return self.cache[round(float(offset_c_s), 9)][1]

    def best_fits(self) -> dict:
        """``{block name: fit}`` of the lowest-RSS evaluation (or the seeds)."""
        if not self.cache:
            return dict(self.seeds)
        k = min(self.cache, key=lambda x: self.cache[x][0])
        return dict(zip((b.name for b in self.blocks), self.cache[k][1], strict=True))

    def _starts(self, i: int, offset_c_s: float) -> list:
        """The warm starts of block ``i`` (fits): at the two nearest evaluated offsets
        and the best anywhere."""
        near = sorted(self.cache, key=lambda k: abs(k - offset_c_s))[:2]
        starts = [self.cache[k][1][i] for k in near]
        best = self.best_fits()
        if self.blocks[i].name in best:
            starts.append(best[self.blocks[i].name])
        return starts

    def _fit(self, offset_c_s: float) -> tuple[float, list]:
        total, results = 0.0, []
        cfg = self.fit_config
        for i, b in enumerate(self.blocks):
            v = self.inputs(b, offset_c_s)
            kind = self.kind_of(b)
            db = b.bands.deadband
            candidates = []
            start_fits = self._starts(i, offset_c_s)
            starts = [f.model.values for f in start_fits]
            if starts:
                model = unfitted_model(kind, input_values(v), cfg, db)
                candidates.append(
                    fit_model(
                        model,
                        v,
                        b.theta_deg,
                        starts=starts,
                        method=cfg.method,
                        max_nfev=cfg.max_nfev,
                        # warm refits along the clock profile: local (the cold fit
                        # of fit_kind is the global search)
                        basin_hops=0,
                    )  # fmt: skip
                )
            if self.cold or not starts:
                hold = np.zeros(input_values(v).size, bool)
                candidates.append(fit_kind(kind, v, b.theta_deg, cfg, hold, deadband=db))
            # the warm starts refitted with their start state held, and never worse than
            # the starts themselves (a refit can wander off)
            candidates += [held_state_fit(f, v, b.theta_deg, cfg) for f in start_fits
                           if f.initial_state is not None]  # fmt: skip
            candidates += [start_as_fit(kind, v, b.theta_deg, f.model.values, cfg, db,
                                        f.initial_state) for f in start_fits]  # fmt: skip
            res = min(candidates, key=lambda r: trimmed_ss(r.residuals))
            total += trimmed_ss(res.residuals)
            results.append(res)
        self.n_params = sum(len(r.free) for r in results)
        return total, results

    def points(self) -> tuple[np.ndarray, np.ndarray]:
        """Evaluated (offsets, rss), sorted by offset."""
        k = np.array(sorted(self.cache))
        return k, np.array([self.cache[x][0] for x in k])


TRIM_FRACTION = 0.01
TRIMMED_VARIANCE = 0.915  # E[sum of squares without the top 1 %] / E[sum], normal errors


def trimmed_ss(residuals: np.ndarray, fraction: float = TRIM_FRACTION) -> float:
    """Sum of squares without the largest ``fraction`` (at least 2) of the finite residuals.

    The EGPI output switches branch at the flag point and on the direction of the last
    input change beyond the dead band; which frame switches first jumps with the clock
    offset, so a few samples make the plain sum of squares step by whole deg^2. Dropping
    the largest 1 % makes the offset profile smooth.
    """
    e = residuals[np.isfinite(residuals)] ** 2
    k = min(max(int(fraction * e.size), 2), max(e.size - 1, 0))
    return float(np.sort(e)[: e.size - k].sum())


def trim_mask(residuals: np.ndarray, fraction: float = TRIM_FRACTION) -> np.ndarray:
    """Finite residuals kept by :func:`trimmed_ss` (bool, same shape)."""
    r = np.asarray(residuals, dtype=float)
    ok = np.isfinite(r)
    e = np.abs(r[ok])
    k = min(max(int(fraction * e.size), 2), max(e.size - 1, 0))
    if k > 0:
        cut = np.sort(e)[e.size - k - 1]
        ok &= np.abs(np.where(ok, r, 0.0)) <= cut
    return ok


@dataclass(frozen=True)
class StartEval:
    """A parameter vector evaluated without refitting (the parts of FitResult used here)."""

    model: object
    residuals: np.ndarray
    free: tuple
    initial_state: InitialState | None = None  # None: from rest


def held_state_fit(fit, v, theta: np.ndarray, fit_config):
    """``fit`` (a block's FitResult or :class:`StartEval` with a start state) refitted
    on the input ``v`` at another clock, its start state held
    (:func:`~i2ris_calib.fitting.fit.fit_from_state`: local least squares from its own
    values)."""
    return fit_from_state(fit.model, v, theta, fit.initial_state, method=fit_config.method,
                          max_nfev=fit_config.max_nfev)  # fmt: skip


def held_output(fit, v, values: np.ndarray | None = None) -> np.ndarray:
    """Output (deg) of a block's fit (FitResult or :class:`StartEval`) for the input
    ``v`` at any candidate clock, its parameters ``values`` (default: the fit's) and
    its fitted start state held (:func:`~i2ris_calib.fitting.result.output_after_state`).

    The start state is the pre-history of a recording that does not start at rest. It
    must be held, not dropped, when the clock moves: ``FitResult.predict`` runs it only
    on the fit's own first input, so at ``offset +- eps`` the opening transient would
    come back and its jump read as the clock's sensitivity (measured on the rendered lab
    session, both motors mid-loop at the first frame: the drift's Gauss-Newton step went
    from the event's 68 ppm to -121 ppm and the profile's minimum cost from 1.41 to 6.6
    deg^2, so the model refinement was refused).
    """
    x = np.asarray(fit.model.values if values is None else values, dtype=float)
    return output_after_state(fit.model, fit.initial_state, v, x)


def input_values(v) -> np.ndarray:
    """The model's own input (counts), shape (m,), of an array or :class:`Signals`."""
    return np.asarray(v.v if isinstance(v, Signals) else v, dtype=float)


def start_as_fit(
    kind: str, v, theta: np.ndarray, values: np.ndarray, fit_config, deadband=None, state=None
):  # fmt: skip
    """:class:`StartEval` of ``values`` on (v, theta), run after the start state
    ``state`` (None: from rest): the fallback when a refit is worse (``v``: the input,
    shape (m,), or :class:`Signals` for a coupled kind)."""
    model = unfitted_model(kind, input_values(v), fit_config, deadband).with_values(values)
    free = tuple(p.name for p in model.parameters if not p.fixed)
    y = output_after_state(model, state, v, model.values)
    return StartEval(model, y - theta, free, state)


def scan_profile(
    profile: OffsetProfile, centre: float, halfwidth: float, step: float, extend: bool = True
) -> float:
    """Best offset of a grid (step ``step``) around ``centre``, evaluated from the centre
    outwards; extended by ``halfwidth`` (up to 4 times) while the minimum is at an end
    (``extend=False``: CalibError instead)."""
    n = max(int(round(halfwidth / step)), 1)
    lo, hi = -n, n  # grid indices: offset = centre + i * step
    for _ in range(5 if extend else 1):
        for i in sorted(range(lo, hi + 1), key=abs):
            profile(centre + i * step)
        vals = {i: profile(centre + i * step) for i in range(lo, hi + 1)}
        k = min(vals, key=vals.get)
        if lo < k < hi:
            return float(centre + k * step)
        if k == lo:
            lo -= n
        else:
            hi += n
    if not extend:
        raise CalibError(
            "sync (model): the best offset lies on the edge of the allowed window "
            f"+-{halfwidth * 1e3:.1f} ms (model and sync event disagree)"
        )
    raise CalibError(
        "sync (model): the offset profile has no minimum within "
        f"{5 * halfwidth:.2f} s of the cross-correlation offset (is the encoder channel of "
        "each axis right? set sync.offset_guess_s/offset_search_s, or use a sync flash)"
    )


def golden_min(f, a: float, b: float, tol: float) -> float:
    """Minimiser of a unimodal ``f`` on [a, b] by golden-section search (to ``tol``)."""
    c, d = b - GOLDEN * (b - a), a + GOLDEN * (b - a)
    fc, fd = f(c), f(d)
    while b - a > tol:
        if fc < fd:
            b, d, fd = d, c, fc
            c = b - GOLDEN * (b - a)
            fc = f(c)
        else:
            a, c, fc = c, d, fd
            d = a + GOLDEN * (b - a)
            fd = f(d)
    return c if fc < fd else d


# ----------------------------------------------------------------------------- uncertainty


def nw_bandwidth(scores: list[np.ndarray]) -> int:
    """Newey-West lag truncation from the data (Andrews 1991, AR(1) plug-in, Bartlett).

    ``L = ceil(1.1447 (alpha n)^(1/3))`` with ``alpha = 4 rho^2 / ((1 - rho)^2 (1 + rho)^2)``,
    ``rho`` the pooled lag-1 autocorrelation of the score sequences (clipped to
    [0, 0.97]) and ``n`` the number of non-zero scores; at least 1, at most the longest
    sequence minus 1.

    Parameters
    ----------
    scores : list of ndarray, shape (m_b,) or (m_b, k)
        Per block the score ``J_i r_i`` of every frame in time order, 0 where the frame
        is not in the loss (so lag products never pair frames across a gap wrongly).
    """
    num = den = 0.0
    n = 0
    longest = 1
    for s in scores:
        s = np.asarray(s, dtype=float).reshape(len(s), -1)
        num += float(np.sum(s[1:] * s[:-1]))
        den += float(np.sum(s * s))
        n += int(np.count_nonzero(np.any(s != 0, axis=1)))
        longest = max(longest, s.shape[0])
    rho = min(max(num / den, 0.0), 0.97) if den > 0 else 0.0
    alpha = 4 * rho**2 / ((1 - rho) ** 2 * (1 + rho) ** 2)
    lag = int(np.ceil(1.1447 * (alpha * max(n, 1)) ** (1 / 3)))
    return int(min(max(lag, 1), longest - 1))


def long_run_covariance(scores: list[np.ndarray], bandwidth: int) -> np.ndarray:
    """Newey-West (Bartlett kernel) long-run covariance ``sum_l w_l Gamma_l``, (k, k).

    ``Gamma_l = sum_i s_i s_(i+l)^T`` within each block, ``w_l = 1 - |l| / (L + 1)``;
    blocks are summed as independent.
    """
    out = None
    for s in scores:
        s = np.asarray(s, dtype=float).reshape(len(s), -1)
        om = s.T @ s
        for lag in range(1, min(bandwidth, s.shape[0] - 1) + 1):
            g = s[lag:].T @ s[:-lag]
            om = om + (1 - lag / (bandwidth + 1)) * (g + g.T)
        out = om if out is None else out + om
    return out


def noise_sd(residuals: list[np.ndarray]) -> float:
    """Tracking-noise sd (deg) from the residuals' frame-to-frame differences.

    ``1.4826 MAD(diff r) / sqrt(2)`` over consecutive frames both in the loss: the
    white tracking noise doubles the variance of a difference, a smooth misfit adds
    almost nothing to it. NaN with fewer than 10 pairs.
    """
    d = np.concatenate([np.diff(r) for r in residuals if r.size > 1] or [np.zeros(0)])
    d = d[np.isfinite(d)]
    if d.size < 10:
        return float("nan")
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / np.sqrt(2.0))


def _param_jacobian(fit, v: np.ndarray, x: np.ndarray) -> np.ndarray:
    """d(model output)/d(free least-squares parameters), shape (m, q), central differences
    (the profiled flag point ``v_f`` excluded: the output is piecewise constant in it),
    ``fit``'s start state held (:func:`held_output`)."""
    cols = []
    for i, p in enumerate(fit.model.parameters):
        if p.fixed or p.name in PROFILE_PARAMS:
            continue
        h = 1e-5 * max(abs(float(x[i])), 1e-4)
        xp, xm = x.copy(), x.copy()
        xp[i] += h
        xm[i] -= h
        cols.append((held_output(fit, v, xp) - held_output(fit, v, xm)) / (2 * h))
    return np.column_stack(cols) if cols else np.zeros((input_values(v).size, 0))


def offset_scores(profile: OffsetProfile, offset_c_s: float, eps_s: float = 1e-3):
    """Per block the residual and the profiled offset sensitivity at ``offset_c_s``.

    ``J_o = d y / d offset`` (central difference, the fitted parameters held) projected
    orthogonal to the parameter Jacobian (what the parameters cannot absorb: the
    sensitivity of the profiled objective), on the frames of the trimmed loss that are
    not among the 1 % largest ``|J_o|`` (frames whose EGPI branch switches within
    ``+-eps_s`` have spike derivatives).

    Returns
    -------
    list of (j_perp, r, cycle), each ndarray shape (m_b,)
        ``j_perp`` and ``r`` are 0 where a frame is not used (NaN-free, time order
        kept); ``cycle`` is the loading-cycle number of each frame
        (:func:`i2ris_calib.data.cycles.cycle_index` of the direction's input).
    """
    out = []
    for b, f in zip(profile.blocks, profile.fits(offset_c_s), strict=True):
        x = np.asarray(f.model.values, dtype=float)
        v = profile.inputs(b, offset_c_s)
        r = np.asarray(f.residuals, dtype=float)
        jo = (
            held_output(f, profile.inputs(b, offset_c_s + eps_s))
            - held_output(f, profile.inputs(b, offset_c_s - eps_s))
        ) / (2 * eps_s)
        use = trim_mask(r) & np.isfinite(jo)
        if use.sum() > 10:
            use &= np.abs(jo) <= np.quantile(np.abs(jo[use]), 1 - TRIM_FRACTION)
        jp = np.zeros(r.size)
        rr = np.zeros(r.size)
        if use.sum() > 2:
            jt = _param_jacobian(f, v, x)[use]
            ok = np.isfinite(jt).all(axis=0)
            jt = jt[:, ok]
            proj = jo[use]
            if jt.shape[1]:
                coef, *_ = np.linalg.lstsq(jt, proj, rcond=None)
                proj = proj - jt @ coef
            jp[use] = proj
            rr[use] = r[use]
        out.append((jp, rr, cycle_index(input_values(v))))
    return out


def cluster_covariance(
    scores: list[np.ndarray], clusters: list[np.ndarray]
) -> tuple[np.ndarray, int]:
    """Cluster-robust long-run covariance ``G/(G-1) sum_g S_g S_g^T`` (k, k) and ``G``.

    ``S_g`` is the sum of the scores of cluster ``g``; clusters are the loading cycles
    of each block: the misfit may be correlated in any way within a cycle (a whole
    ramp), cycles are taken as independent. ``G`` counts the clusters with a non-zero
    score; the covariance is NaN when ``G < 2``.

    Parameters
    ----------
    scores : list of ndarray, shape (m_b,) or (m_b, k)
    clusters : list of ndarray of int, shape (m_b,)
    """
    sums = []
    for s, c in zip(scores, clusters, strict=True):
        s = np.asarray(s, dtype=float).reshape(len(s), -1)
        if s.shape[0] == 0:
            continue
        c = np.asarray(c, dtype=int)
        tot = np.stack([np.bincount(c, weights=s[:, j]) for j in range(s.shape[1])], axis=1)
        sums.append(tot[np.any(tot != 0, axis=1)])
    k = sums[0].shape[1] if sums else 1
    allsums = np.concatenate(sums) if sums else np.zeros((0, k))
    g = allsums.shape[0]
    if g < 2:
        return np.full((k, k), np.nan), g
    return g / (g - 1) * (allsums.T @ allsums), g


def curvature(profile: OffsetProfile, best: float, halfwidth: float) -> float:
    """``RSS''(best)`` (deg^2/s^2) from a quadratic through the evaluated points within
    ``halfwidth`` of the minimum, widened twice (x2, x4) while there are too few or the
    fit is not convex; NaN if it never is."""
    x, y = profile.points()
    for width in (halfwidth, 2 * halfwidth, 4 * halfwidth):
        sel = np.abs(x - best) <= width
        if sel.sum() >= 3:
            c2 = np.polyfit(x[sel] - best, y[sel], 2)[0]
            if c2 > 0:
                return float(2 * c2)
    return float("nan")


def offset_stderr(profile: OffsetProfile, best: float, halfwidth: float) -> tuple[float, dict]:
    """Standard error of the offset (s) and how it was obtained.

    ::

        sd^2 = 2 sigma_n^2 chi2 / RSS''  *  F
        chi2 = max(1, sigma_r^2 / sigma_n^2)          misfit inflation
        F    = max(1, Omega / (sigma_r^2 B))          residual autocorrelation

    * ``RSS''``: curvature of the (trimmed) offset profile at its minimum
      (:func:`curvature`); ``2 sigma^2 / RSS''`` is the least-squares variance of the
      profiled offset for white errors of variance ``sigma^2``.
    * ``sigma_n``: tracking noise from the residuals' frame-to-frame differences
      (:func:`noise_sd`); ``sigma_r^2 = RSS_min / (n - p - 1) / 0.915`` (trim-corrected);
      ``chi2`` is the reduced chi-square of the fit against the tracking noise, so
      ``sigma_n^2 chi2 = max(sigma_r^2, sigma_n^2)``: model misfit raises the variance.
    * ``F``: the long-run variance ``Omega`` of the scores ``s_i = J_i r_i`` over
      their white-noise variance ``sigma_r^2 B``, ``B = sum J_i^2`` (``J_i``: the
      profiled offset sensitivity of frame i, :func:`offset_scores`). ``Omega`` is the
      larger of the Newey-West estimate (Bartlett kernel, data-driven lag,
      :func:`nw_bandwidth`) and the cluster-robust one with the loading cycles as
      clusters (:func:`cluster_covariance`: misfit correlated over a whole cycle,
      longer than a kernel lag sees). The effective number of independent samples is
      ``n / F``; ``(2 sigma_r^2 / RSS'') F`` is the sandwich ``Omega / B^2`` written as
      an inflation of the curvature-based variance (``RSS'' = 2 B`` for a linear model).
    """
    info: dict = {}
    c = curvature(profile, best, halfwidth)
    fits = profile.fits(best)
    dof = max(profile.n_samples - profile.n_params - 1, 1)
    sigma_r2 = profile(best) / dof / TRIMMED_VARIANCE
    resid = [np.where(trim_mask(f.residuals), f.residuals, np.nan) for f in fits]
    sn = noise_sd(resid)
    sigma_n2 = sn**2 if np.isfinite(sn) and sn > 0 else sigma_r2
    chi2 = sigma_r2 / sigma_n2
    scores = offset_scores(profile, best)
    s = [j * r for j, r, _ in scores]
    bread = float(sum(j @ j for j, _, _ in scores))
    lag = nw_bandwidth(s)
    omega_nw = float(long_run_covariance(s, lag)[0, 0]) if s else float("nan")
    om_cl, n_clusters = cluster_covariance(s, [c for _, _, c in scores])
    omega_cl = float(om_cl[0, 0])
    omega = np.nanmax([omega_nw, omega_cl])
    f_ac = omega / (sigma_r2 * bread) if bread > 0 else float("nan")
    factor = max(1.0, f_ac) if np.isfinite(f_ac) else 1.0
    var = 2 * sigma_n2 * max(chi2, 1.0) / c * factor if c > 0 else float("nan")
    info = {
        "formula": "sd^2 = 2 sigma_n^2 max(1, chi2) / RSS'' * max(1, F)",
        "rss_curvature_deg2_per_s2": c,
        "sigma_resid_deg": float(np.sqrt(sigma_r2)),
        "sigma_noise_deg": float(np.sqrt(sigma_n2)),
        "chi2_reduced": float(chi2),
        "autocorr_factor_F": float(f_ac),
        "nw_lag_frames": lag,
        "F_newey_west": omega_nw / (sigma_r2 * bread) if bread > 0 else float("nan"),
        "F_cycle_clusters": omega_cl / (sigma_r2 * bread) if bread > 0 else float("nan"),
        "n_cycle_clusters": n_clusters,
        "curvature_only_sd_s": float(np.sqrt(2 * sigma_r2 / c)) if c > 0 else float("nan"),
        "sandwich_sd_s": float(np.sqrt(omega) / bread) if bread > 0 else float("nan"),
    }
    return float(np.sqrt(var)), info


def drift_gauss_newton(
    profile: OffsetProfile, offset_c_s: float, drift_ppm: float, iters: int = 4
) -> tuple[float, float, np.ndarray]:
    """(offset_c, drift) by Gauss-Newton with the fitted models held fixed.

    Returns the new offset at ``t_c``, drift (ppm) and their covariance (2, 2): the
    white-noise covariance ``sigma^2 (A^T A)^-1`` scaled up (never down) so that its
    diagonal covers the sandwiches ``(A^T A)^-1 Omega (A^T A)^-1`` of the scores
    ``A_i r_i``, ``Omega`` by Newey-West and by loading-cycle clusters (residual
    autocorrelation, as :func:`offset_stderr`).
    """
    fits = profile.fits(offset_c_s)
    o, d = offset_c_s, drift_ppm
    eps_o, eps_d = 1e-3, 50.0
    sizes = [b.t_cam_s.size for b in profile.blocks]
    splits = np.cumsum(sizes)[:-1]

    def predict(o_, d_):
        out = [
            held_output(f, profile.inputs(b, o_, d_))
            for b, f in zip(profile.blocks, fits, strict=True)
        ]
        return np.concatenate(out)

    theta = np.concatenate([b.theta_deg for b in profile.blocks])
    ok = np.isfinite(theta)
    cycles = [cycle_index(input_values(profile.inputs(b, o, d))) for b in profile.blocks]
    cov = np.full((2, 2), np.nan)
    for _ in range(iters):
        y = predict(o, d)
        jo = (predict(o + eps_o, d) - predict(o - eps_o, d)) / (2 * eps_o)
        jd = (predict(o, d + eps_d) - predict(o, d - eps_d)) / (2 * eps_d)
        r_all = theta - y
        # samples whose EGPI branch switches within +-eps have spike derivatives: drop the
        # top 1 % of |d/d offset| and of |residual| (as in trimmed_ss)
        use = ok & np.isfinite(jo) & np.isfinite(jd)
        use &= np.abs(jo) <= np.quantile(np.abs(jo[use]), 1 - TRIM_FRACTION)
        use &= np.abs(r_all) <= np.quantile(np.abs(r_all[use]), 1 - TRIM_FRACTION)
        a = np.column_stack([jo, jd])[use]
        r = r_all[use]
        if not np.isfinite(a).all() or np.linalg.matrix_rank(a) < 2:
            break
        step, *_ = np.linalg.lstsq(a, r, rcond=None)
        o, d = o + step[0], d + step[1]
        dof = max(r.size - 2 - profile.n_params, 1)
        sigma2 = float(r @ r) / dof
        inv = np.linalg.inv(a.T @ a)
        cov = inv * sigma2
        scores = np.where(use[:, None], np.column_stack([jo, jd]) * r_all[:, None], 0.0)
        parts = np.split(scores, splits)
        factor = 1.0
        omegas = [long_run_covariance(parts, nw_bandwidth(parts))]
        omegas.append(cluster_covariance(parts, cycles)[0])
        for omega in omegas:
            if np.isfinite(omega).all():
                sand = inv @ omega @ inv
                factor = max(factor, float(np.max(np.diag(sand) / np.diag(cov))))
        cov = cov * factor
        if abs(step[0]) < 1e-5 and abs(step[1]) < 0.1:
            break
    return o, d, cov


def cycle_offsets(
    profile: OffsetProfile, offset_c_s: float, drift_ppm: float, eps_s: float = 1e-3
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Local offsets, one per loading cycle of every block, with the models held fixed.

    For each (block, loading cycle) with >= 10 frames in the trimmed loss: one
    Gauss-Newton step of the offset on that cycle's frames alone,
    ``o_g = offset + sum(J r) / sum(J^2)``, its white-noise sd
    ``sigma_b / sqrt(sum J^2)`` (``sigma_b``: the block's residual rms) and its time
    ``t_g = sum(J^2 t) / sum(J^2)`` (camera clock). Their scatter about the clock line
    shows misfit that differs between cycles and axes (which a drift fitted to all
    frames at once cannot see).

    Returns
    -------
    t_cam_s, offsets_s, sd_s : ndarray, shape (g,)
        Offsets as ``t_ctrl - t_cam`` at ``t_g`` (the clock's offset at ``t_c`` moved
        along the drift).
    block : ndarray of int, shape (g,)
        Index of the block (axis and direction) of each cycle in ``profile.blocks``.
    """
    ts, os_, sds, blk = [], [], [], []
    for k, (b, f) in enumerate(zip(profile.blocks, profile.fits(offset_c_s), strict=True)):
        v = profile.inputs(b, offset_c_s, drift_ppm)
        r = b.theta_deg - held_output(f, v)
        jo = (
            held_output(f, profile.inputs(b, offset_c_s + eps_s, drift_ppm))
            - held_output(f, profile.inputs(b, offset_c_s - eps_s, drift_ppm))
        ) / (2 * eps_s)
        use = trim_mask(r) & np.isfinite(jo)
        if use.sum() < 10:
            continue
        use &= np.abs(jo) <= np.quantile(np.abs(jo[use]), 1 - TRIM_FRACTION)
        sigma = float(np.sqrt(np.mean(r[use] ** 2)))
        cyc = cycle_index(input_values(v))
        for g in np.unique(cyc[use]):
            sel = use & (cyc == g)
            jj = float(jo[sel] @ jo[sel])
            if sel.sum() < 10 or not jj > 0:
                continue
            t_g = float(jo[sel] ** 2 @ b.t_cam_s[sel]) / jj
            ts.append(t_g)
            os_.append(
                offset_c_s + float(jo[sel] @ r[sel]) / jj + drift_ppm * PPM * (t_g - profile.t_c)
            )
            sds.append(sigma / np.sqrt(jj))
            blk.append(k)
    return np.array(ts), np.array(os_), np.array(sds), np.array(blk, dtype=int)


def block_bias_cov(
    t_g: np.ndarray,
    o_g: np.ndarray,
    sd_g: np.ndarray,
    block: np.ndarray,
    t_c: float,
    offset_c_s: float,
    drift_ppm: float,
    fit_drift: bool = True,
) -> tuple[np.ndarray, dict]:
    """Covariance of (offset at ``t_c``, drift) allowing a misfit bias shared by a block.

    The per-cycle offsets (:func:`cycle_offsets`) are modelled as

    ::

        o_g = offset_c + drift * 1e-6 * (t_g - t_c) + u_b(g) + e_g
        u_b ~ N(0, tau^2)   one per block (axis and direction), shared by its cycles
        e_g ~ N(0, sd_g^2)  per cycle

    A hysteresis model that misfits an axis-direction in the same way on every cycle
    shifts all its cycles' offsets alike: no number of cycles averages that out, and
    when the axes move at different times (yaw first, pitch later) the difference of
    their biases looks exactly like drift. ``tau^2`` is the pooled scatter of the
    cycle offsets about their block's mean (the misfit that differs between cycles is
    taken to be as large as the one they share; without two cycles in a block, the
    scatter about the clock line). The covariance is the generalised least-squares one,
    ``(X^T V^-1 X)^-1`` with ``V = diag(sd_g^2) + tau^2 [b(g) = b(h)]``, scaled by the
    reduced chi-square of that fit when it exceeds 1.

    Parameters
    ----------
    t_g, o_g, sd_g : ndarray, shape (G,)
        Cycle times (camera clock, s), offsets (s) and their sd (s).
    block : ndarray of int, shape (G,)
        DirectionBlock of each cycle.
    t_c, offset_c_s, drift_ppm : float
        The clock: offset at camera time ``t_c`` (s) and drift (ppm).
    fit_drift : bool
        False: the offset only (drift held).

    Returns
    -------
    cov : ndarray, shape (2, 2)
        Covariance of (offset at ``t_c``, drift); NaN with fewer than 2 cycles.
    info : dict
        ``tau_s``, ``n_cycles``, ``n_blocks``, ``chi2_reduced``, ``offset_sd_s``,
        ``drift_sd_ppm``.
    """
    t_g, o_g, sd_g, block = (np.asarray(a) for a in (t_g, o_g, sd_g, block))
    n = t_g.size
    if n < 2:
        return np.full((2, 2), np.nan), {"n_cycles": int(n)}
    r = o_g - (offset_c_s + drift_ppm * PPM * (t_g - t_c))
    ss, dof = 0.0, 0
    for b in np.unique(block):
        rb = r[block == b]
        if rb.size >= 2:
            ss += float(np.sum((rb - rb.mean()) ** 2))
            dof += rb.size - 1
    tau2 = ss / dof if dof >= 2 else float(np.mean(r**2))
    v = np.diag(sd_g**2) + tau2 * (block[:, None] == block[None, :])
    x = np.column_stack([np.ones(n), (t_g - t_c) * PPM]) if fit_drift else np.ones((n, 1))
    vi = np.linalg.inv(v)
    cov_p = np.linalg.pinv(x.T @ vi @ x)
    resid = r - x @ (cov_p @ x.T @ vi @ r)
    k = n - x.shape[1]
    chi2 = float(resid @ vi @ resid / k) if k > 0 else float("nan")
    if k > 0 and chi2 > 1:
        cov_p = cov_p * chi2
    cov = np.zeros((2, 2))
    cov[: x.shape[1], : x.shape[1]] = cov_p
    within = within_block_drift_var(t_g, r, sd_g, block) if fit_drift else float("nan")
    if np.isfinite(within):
        cov[1, 1] = max(cov[1, 1], within)
    info = {
        "tau_s": float(np.sqrt(tau2)),
        "n_cycles": int(n),
        "n_blocks": int(np.unique(block).size),
        "chi2_reduced": chi2,
        "within_block_drift_sd_ppm": float(np.sqrt(within)),
        "offset_sd_s": float(np.sqrt(cov[0, 0])),
        "drift_sd_ppm": float(np.sqrt(cov[1, 1])) if fit_drift else float("nan"),
    }
    return cov, info


def within_block_drift_var(
    t_g: np.ndarray, r: np.ndarray, sd_g: np.ndarray, block: np.ndarray
) -> float:
    """Variance (ppm^2) of the drift seen inside the blocks only (one free offset per block).

    The limit of :func:`block_bias_cov` for an unbounded block bias: whatever each block's
    bias, the drift is then measured by the spread of the cycles within a block, which
    is small when the blocks move one after the other (the Fig-5 order: yaw+, yaw-,
    pitch+, pitch-) and large when every block spans the recording. Weighted least
    squares with a column per block and the slope, scaled by the reduced chi-square
    when above 1; NaN without a block holding two cycles at different times.
    """
    blocks = np.unique(block)
    cols = [(block == b).astype(float) for b in blocks] + [(t_g - np.mean(t_g)) * PPM]
    x = np.column_stack(cols)
    w = 1.0 / np.asarray(sd_g, dtype=float) ** 2
    xtw = x.T * w
    a = xtw @ x
    if np.linalg.matrix_rank(a) < x.shape[1]:
        return float("nan")
    inv = np.linalg.inv(a)
    coef = inv @ (xtw @ r)
    k = t_g.size - x.shape[1]
    res = r - x @ coef
    chi2 = float(res @ (w * res) / k) if k > 0 else 1.0
    return float(inv[-1, -1] * max(chi2, 1.0))


def frames_series(series: list[AxisSeries]) -> list[AxisSeries]:
    """The measured frames of each series (finite angle), for the cross-correlation."""
    out = []
    for s in series:
        ok = np.isfinite(s.theta_deg)
        out.append(AxisSeries(s.axis, s.channel, s.t_cam_s[ok], s.theta_deg[ok]))
    return out


#: rounds of (drift by Gauss-Newton with the models held, offset profile refitted at it)
#: stop when the drift moves by less than DRIFT_TOL_PPM or DRIFT_TOL_SD of its sd, or after
#: DRIFT_MAX_ROUNDS: the models refitted at a drift absorb part of the drift the mapping
#: still lacks, so each round recovers only part of the rest (two fixed rounds left the
#: issue sessions 6-8 ppm short of a 45 ppm drift)
DRIFT_TOL_PPM = 0.2
DRIFT_TOL_SD = 0.1
DRIFT_MAX_ROUNDS = 10


def search_window(
    series: list[AxisSeries], log: EncoderLog, cfg: SyncConfig, t_c: float, prior: ClockModel | None
) -> tuple[float, float, float, float]:
    """Where the offset profile is scanned: ``(centre, halfwidth, step, margin)`` (s).

    Without ``prior`` the centre is the cross-correlation offset, the halfwidth
    ``profile_halfwidth_s`` (the scan extends beyond it as needed) and the frames keep a
    margin of 5 halfwidths; with ``prior`` (an event clock) the centre is its offset at
    ``t_c``, the halfwidth +-4 of its standard errors (at least 4 ``profile_tol_s``),
    the step at most half of that and the margin 2 halfwidths.
    """
    step = cfg.profile_step_s
    if prior is None:
        o_x = coarse_xcorr_offset(frames_series(series), log, cfg)
        halfwidth = cfg.profile_halfwidth_s
        margin = 5 * halfwidth
    else:
        o_x = prior.offset_at(t_c)
        halfwidth = max(4 * prior.offset_stderr_at(t_c), 4 * cfg.profile_tol_s)
        step = min(step, halfwidth / 2)
        margin = 2 * halfwidth
    return o_x, halfwidth, step, margin


def starting_drift(cfg: SyncConfig, prior: ClockModel | None) -> float:
    """The drift (ppm) the profile starts at: the event's when it has one (its window is
    that clock's offset at t_c; at drift 0 frames far from t_c would be mapped up to
    drift x half the recording away from it), else 0."""
    if prior is not None and cfg.estimate_drift and np.isfinite(prior.drift_stderr_ppm):
        return float(prior.drift_ppm)
    return 0.0


def profile_minimum(
    series: list[AxisSeries],
    log: EncoderLog,
    cfg: SyncConfig,
    fit_config,
    t_c: float,
    window: tuple[float, float, float, float],
    d0: float,
    extend: bool,
) -> tuple[OffsetProfile, list[DirectionBlock], float]:
    """The offset profile at drift ``d0``, its blocks and its minimum (offset at ``t_c``).

    The profile is scanned over ``window`` (:func:`search_window`; beyond it when
    ``extend``), its blocks' direction attribution redone at the scanned minimum, and
    the minimum refined by golden-section search with warm starts only. CalibError when
    no axis moves enough inside the encoder log.
    """
    o_x, halfwidth, step, margin = window

    def blocks_at(offset: float) -> list[DirectionBlock]:
        return model_blocks(
            series, log, offset, t_c, margin, fit_config, cfg.min_axis_range_counts,
        )  # fmt: skip

    blocks = blocks_at(o_x)
    if not blocks:
        raise CalibError(
            "sync (model): no axis moves enough inside the encoder log to fit the hysteresis "
            f"(need > {cfg.min_axis_range_counts:g} counts of motion; use a sync flash instead)"
        )
    profile = OffsetProfile(blocks, log, t_c, d0, cfg.model, fit_config)
    best = scan_profile(profile, o_x, halfwidth, step, extend=extend)
    # the direction attribution was made at the coarse offset: redo it at the minimum
    # (same frames, so only frames near a change of direction can change block)
    seeds = profile.best_fits()
    blocks = blocks_at(best)
    if [b.name for b in blocks] != [b.name for b in profile.blocks] or any(
        not np.array_equal(a.in_direction, b.in_direction)
        for a, b in zip(blocks, profile.blocks, strict=True)
    ):
        scanned = profile
        profile = OffsetProfile(blocks, log, t_c, d0, cfg.model, fit_config, seeds)
        for x in sorted(scanned.cache, key=lambda k: abs(k - best))[:3]:
            profile(x)
    profile.cold = False  # refinement: warm starts only
    best = golden_min(profile, best - step, best + step, cfg.profile_tol_s)
    return profile, blocks, best


@dataclass(frozen=True)
class DriftRounds:
    """What :func:`drift_by_rounds` returns: the profile refitted at the final drift and
    its minimum, the drift (ppm) and its Gauss-Newton sd, the rounds run and the last
    change of the drift (ppm; NaN without a round)."""

    profile: OffsetProfile
    best: float
    drift: float
    drift_sd: float
    rounds: int
    change: float


def drift_by_rounds(
    profile: OffsetProfile,
    blocks: list[DirectionBlock],
    log: EncoderLog,
    cfg: SyncConfig,
    fit_config,
    t_c: float,
    best: float,
    drift: float,
    step: float,
) -> DriftRounds:
    """Rounds of drift by Gauss-Newton with the models held, then the offset profile
    refitted at it, until the drift moves by less than DRIFT_TOL_PPM or DRIFT_TOL_SD of
    its sd, or after DRIFT_MAX_ROUNDS (none when ``[sync] estimate_drift`` is off)."""
    drift_sd = float("nan")
    rounds, change = 0, float("nan")
    if cfg.estimate_drift:
        while rounds < DRIFT_MAX_ROUNDS:
            # drift with the models held, then the offset profile refitted at it
            rounds += 1
            _, new_drift, cov = drift_gauss_newton(profile, best, drift)
            drift_sd = float(np.sqrt(cov[1, 1]))
            change, drift = abs(new_drift - drift), new_drift
            seeds = profile.best_fits()
            profile = OffsetProfile(blocks, log, t_c, drift, cfg.model, fit_config, seeds)
            best = golden_min(profile, best - step, best + step, cfg.profile_tol_s)
            if change < max(DRIFT_TOL_PPM, DRIFT_TOL_SD * drift_sd):
                break
    return DriftRounds(profile, best, drift, drift_sd, rounds, change)


def clock_sds(
    found: DriftRounds, cfg: SyncConfig, t_c: float, step: float
) -> tuple[float, float, dict]:
    """``(offset sd at t_c (s), drift sd (ppm), uncertainty evidence)`` of the minimum.

    The offset's sd is the profile's (:func:`offset_stderr`) with the golden-section
    search's resolution; both sds are at least those of the per-cycle offsets with a
    block bias (:func:`block_bias_cov`), and the drift's at least that of a line through
    the per-cycle offsets (evidence ``drift``).
    """
    profile, best, drift, drift_sd = found.profile, found.best, found.drift, found.drift_sd
    drift_scatter = {}
    sd_c, unc = offset_stderr(profile, best, 1.5 * step)
    # the golden-section search ends anywhere inside its last interval (profile_tol_s)
    unc["search_resolution_sd_s"] = cfg.profile_tol_s / np.sqrt(12.0)
    sd_c = float(np.hypot(sd_c, unc["search_resolution_sd_s"]))
    # per-cycle offsets: white sd inflated by F (misfit correlated within a cycle, as
    # for the offset)
    t_g, o_g, sd_g, blk = cycle_offsets(profile, best, drift)
    f_ac = unc.get("autocorr_factor_F", 1.0)
    sd_g = sd_g * np.sqrt(max(1.0, f_ac if np.isfinite(f_ac) else 1.0))
    # a misfit shared by all cycles of a block (axis-direction) biases offset and drift
    # alike: the sd of both is at least that of the per-cycle offsets with a block bias
    cov_b, block_info = block_bias_cov(t_g, o_g, sd_g, blk, t_c, best, drift, cfg.estimate_drift)
    if np.isfinite(cov_b[0, 0]):
        block_info["offset_sd_before_s"] = sd_c
        sd_c = max(sd_c, float(np.sqrt(cov_b[0, 0])))
        unc["blocks"] = block_info
    if cfg.estimate_drift:
        # the drift's sd is at least that of a line through the per-cycle offsets,
        # scaled by their reduced chi-square when they scatter more than their sd
        if t_g.size >= 3 and np.ptp(t_g) > 0:
            _, d_line, cov_line, chi2_line = clock_from_offsets(t_g, o_g, sd_g, True, "if_larger")
            line_sd = float(np.sqrt(cov_line[1, 1]))
            drift_scatter = {
                "rounds": found.rounds,
                "last_change_ppm": found.change,
                "n_cycles": int(t_g.size),
                "line_drift_ppm": float(d_line),
                "line_drift_sd_ppm": line_sd,
                "chi2_reduced": float(chi2_line),
                "gauss_newton_drift_sd_ppm": drift_sd,
            }
            drift_sd = max(drift_sd, line_sd)
        if np.isfinite(cov_b[1, 1]):
            drift_scatter["block_bias_drift_sd_ppm"] = float(np.sqrt(cov_b[1, 1]))
            drift_sd = max(drift_sd, float(np.sqrt(cov_b[1, 1])))
    return sd_c, drift_sd, unc | ({"drift": drift_scatter} if drift_scatter else {})


def clock_covariance(sd_c: float, drift_sd: float, t_c: float) -> np.ndarray:
    """Covariance of (offset at camera time 0 (s), drift (ppm)) from the offset's sd at
    ``t_c`` and the drift's (a drift sd of NaN: drift not estimated, variance 0)."""
    var_d = drift_sd**2 if np.isfinite(drift_sd) else 0.0
    return np.array(
        [[sd_c**2 + (t_c * PPM) ** 2 * var_d, -t_c * PPM * var_d], [-t_c * PPM * var_d, var_d]]
    )


def model_evidence(
    profile: OffsetProfile,
    blocks: list[DirectionBlock],
    cfg: SyncConfig,
    t_c: float,
    o_x: float,
    halfwidth: float,
    best: float,
    uncertainty: dict,
    with_prior: bool,
) -> dict:
    """The clock's evidence (sync.json ``evidence``): models, search window, blocks,
    the offset profile, RMSE at the minimum and the uncertainty terms."""
    x, y = profile.points()
    return {
        "model": cfg.model,
        "models": {b.name: profile.kind_of(b) for b in blocks},
        "model_choice": {b.name: b.why for b in blocks},
        "prior_offset_at_t_ref_s" if with_prior else "xcorr_offset_s": o_x,
        "search_halfwidth_s": halfwidth,
        "t_ref_cam_s": t_c,
        "blocks": [
            {"name": b.name, "n_frames": int(b.t_cam_s.size), "n_in_loss": b.n_loss} for b in blocks
        ],
        "profile": {"offset_at_t_ref_s": x, "rss_deg2": y},
        "n_samples": profile.n_samples,
        "rmse_deg": float(np.sqrt(profile(best) / TRIMMED_VARIANCE / max(profile.n_samples, 1))),
        "uncertainty": uncertainty,
        "note": "offset profile of the hysteresis-model residual over each axis's whole frame "
        "history; stderr from its curvature, inflated for misfit (chi2 vs the tracking "
        "noise) and residual autocorrelation (Newey-West)",
    }


#: Starts of each cold fit along the clock-offset profile when ``[fit] n_starts`` is 0
#: (by the data's size): the profile refits the models at tens of offsets, each warm
#: from its neighbours; the fit stage's own search runs on the synced result.
PROFILE_STARTS = 2


def profile_fit_config(fit_config: FitConfig | None) -> FitConfig:
    """The fit settings of the clock-offset profile: ``fit_config`` without held-out
    cycles or restarts, its starts by the data's size replaced by
    :data:`PROFILE_STARTS`."""
    cfg = replace(fit_config or FitConfig(), holdout_fraction=0.0)
    return replace(
        cfg,
        n_starts=cfg.n_starts or PROFILE_STARTS,
        n_starts_gpi=cfg.n_starts_gpi or PROFILE_STARTS,
        max_restarts=0,
    )


def clock_from_model(
    series: list[AxisSeries],
    log: EncoderLog,
    cfg: SyncConfig,
    fit_config=None,
    prior: ClockModel | None = None,
) -> ClockModel:
    """Offset and drift minimising the hysteresis-model residual (method ``model``).

    Without ``prior`` the offset grid is centred on the cross-correlation offset and
    extended as needed; with ``prior`` (an event clock) the search is confined to its
    +-4 standard errors and a minimum on the window's edge is a CalibError (model and
    event disagree).

    Parameters
    ----------
    series : list of AxisSeries
        Per axis every frame in time order, ``theta_deg`` NaN where not measured
        (:func:`i2ris_calib.sync.estimate.frame_series`); series of measured frames
        only also work (the model then sees the input at those frames only).
    log : EncoderLog
        Encoder channels.
    cfg : SyncConfig
        ``model`` (egpi/gpi), ``profile_*``, ``estimate_drift``, ``min_axis_range_counts``.
    fit_config : FitConfig, optional
        Fitting settings (``[fit]``: bands, ``signed``, ``min_block_samples``, starts);
        holdout is disabled for the profile.
    prior : ClockModel, optional
        A coarser clock (sync event) bounding the offset search.

    Returns
    -------
    ClockModel
        With the offset profile (offsets at ``t_c``, RSS) and the uncertainty terms
        (:func:`offset_stderr`) as evidence.
    """
    fit_config = profile_fit_config(fit_config)
    t_c = float(np.mean(np.concatenate([s.t_cam_s for s in series])))
    window = search_window(series, log, cfg, t_c, prior)
    o_x, halfwidth, step, _ = window
    d0 = starting_drift(cfg, prior)
    profile, blocks, best = profile_minimum(
        series, log, cfg, fit_config, t_c, window, d0, extend=prior is None
    )
    found = drift_by_rounds(profile, blocks, log, cfg, fit_config, t_c, best, d0, step)
    sd_c, drift_sd, unc = clock_sds(found, cfg, t_c, step)
    offset0 = found.best - found.drift * PPM * t_c  # offset at camera time 0 (t_ctrl - t_cam)
    cov = clock_covariance(sd_c, drift_sd, t_c)
    evidence = model_evidence(
        found.profile, blocks, cfg, t_c, o_x, halfwidth, found.best, unc, prior is not None
    )
    return clock_model(offset0, found.drift, cov, "model", evidence, cfg.estimate_drift)
