"""Clock offset (and drift) estimated jointly with the hysteresis model.

Without a sync event the only link between the clocks is the motion itself. Plain
cross-correlation mistakes the hysteresis lag for clock offset; here the offset is
the one at which the hysteresis model (EGPI or GPI, fitted anew at each candidate)
explains the measured angle best:

1. frames are mapped to the controller clock with a candidate clock, the encoder is
   interpolated there, and the model is fitted per axis and motion direction
   (``i2ris_calib.fitting``); the objective is the total residual sum of squares;
2. the offset profile is scanned on a grid around the cross-correlation offset and
   refined by golden-section search; its curvature gives the standard error;
3. drift: with the fitted models held fixed, a Gauss-Newton step on (offset, drift)
   over all frames, then the offset profile is refined again at the new drift.

The sample set (which frames, which direction block) is fixed once, so the objective
is a smooth function of the offset and not of which samples happen to be in range.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from i2ris_calib.errors import CalibError
from i2ris_calib.sync.clock import PPM, ClockModel, clock_model
from i2ris_calib.sync.config import SyncConfig
from i2ris_calib.sync.log import EncoderLog
from i2ris_calib.sync.xcorr import AxisSeries, coarse_xcorr_offset

GOLDEN = (np.sqrt(5.0) - 1.0) / 2.0


@dataclass(frozen=True)
class Block:
    """Frames of one axis and motion direction, fitted as one hysteresis dataset.

    Attributes
    ----------
    name : str
        e.g. ``"yaw+"``.
    channel : str
        Encoder channel of the axis.
    sign : float
        +1, or -1 for a negative-input dataset (|counts| -> |deg|, the paper's convention).
    t_cam_s, theta_deg : ndarray, shape (m,)
        Frame times (camera clock) and measured angles (sign applied).
    """

    name: str
    channel: str
    sign: float
    t_cam_s: np.ndarray
    theta_deg: np.ndarray


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
) -> list[Block]:
    """Split each moving axis into motion-direction blocks (fitting.direction_blocks).

    Only frames whose mapped time stays inside the log for every offset within
    ``margin_s`` are used, so the sample set does not change during the search.
    An axis whose encoder spans less than ``min_range_counts`` is skipped.
    """
    from i2ris_calib.fitting.pipeline import direction_blocks

    lo, hi = log.time_range()
    blocks = []
    for s in series:
        tc = map_times(s.t_cam_s, offset_c_s, 0.0, t_c_s)
        keep = (tc - margin_s >= lo) & (tc + margin_s <= hi) & np.isfinite(s.theta_deg)
        t, th = s.t_cam_s[keep], s.theta_deg[keep]
        enc = log.interpolate(s.channel, tc[keep])
        if enc.size == 0 or np.ptp(enc) < min_range_counts:
            continue
        for b in direction_blocks(enc, fit_config):
            sign = 1.0 if b.direction == "+" else -1.0
            blocks.append(
                Block(s.axis + b.direction, s.channel, sign, t[b.index], sign * th[b.index])
            )
    return blocks


class OffsetProfile:
    """Residual sum of squares of the hysteresis fits as a function of the offset.

    Each evaluation refits every block. Starts: the fits at the two nearest offsets
    evaluated so far and the best fit found anywhere (warm starts), plus, while
    ``cold`` is True (the coarse scan), the fitter's own data-driven multi-start; the
    lowest residual wins. A warm-start chain alone can stay in a poor local minimum
    found far from the true offset. Results are cached by offset.
    """

    def __init__(self, blocks, log, t_c_s, drift_ppm, kind, fit_config, seeds=None):
        self.blocks, self.log, self.t_c, self.drift = blocks, log, t_c_s, drift_ppm
        self.kind, self.fit_config = kind, fit_config
        self.cache: dict[float, tuple[float, list]] = {}
        self.n_samples = sum(int(np.isfinite(b.theta_deg).sum()) for b in blocks)
        self.n_params = 0
        self.cold = seeds is None
        self.seeds = seeds  # per-block parameter vectors to try as starts

    def inputs(self, block: Block, offset_c_s: float, drift_ppm: float | None = None) -> np.ndarray:
        """Encoder input (counts, sign applied) of ``block`` at a candidate clock."""
        d = self.drift if drift_ppm is None else drift_ppm
        tc = map_times(block.t_cam_s, offset_c_s, d, self.t_c)
        return block.sign * self.log.interpolate(block.channel, tc)

    def __call__(self, offset_c_s: float) -> float:
        key = round(float(offset_c_s), 9)
        if key not in self.cache:
            self.cache[key] = self._fit(key)
        return self.cache[key][0]

    def fits(self, offset_c_s: float) -> list:
        """FitResults of the blocks at an evaluated offset."""
        self(offset_c_s)
        return self.cache[round(float(offset_c_s), 9)][1]

    def best_params(self) -> list:
        """Per-block parameter vectors of the lowest-RSS evaluation (or the seeds)."""
        if not self.cache:
            return self.seeds
        k = min(self.cache, key=lambda x: self.cache[x][0])
        return [r.model.values for r in self.cache[k][1]]

    def _starts(self, i: int, offset_c_s: float) -> list:
        near = sorted(self.cache, key=lambda k: abs(k - offset_c_s))[:2]
        starts = [self.cache[k][1][i].model.values for k in near]
        best = self.best_params()
        if best is not None:
            starts.append(best[i])
        return starts

    def _fit(self, offset_c_s: float) -> tuple[float, list]:
        from i2ris_calib.fitting.fit import fit_model
        from i2ris_calib.fitting.pipeline import build_model, fit_kind

        total, results = 0.0, []
        for i, b in enumerate(self.blocks):
            v = self.inputs(b, offset_c_s)
            candidates = []
            starts = self._starts(i, offset_c_s)
            if starts:
                model = build_model(self.kind, v, self.fit_config)
                candidates.append(
                    fit_model(model, v, b.theta_deg, starts=starts, method=self.fit_config.method)
                )
            if self.cold or not starts:
                hold = np.zeros(v.size, bool)
                candidates.append(fit_kind(self.kind, v, b.theta_deg, self.fit_config, hold))
            # never worse than the warm starts themselves (a refit can wander off)
            candidates += [
                start_as_fit(self.kind, v, b.theta_deg, x, self.fit_config) for x in starts
            ]
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


@dataclass(frozen=True)
class StartEval:
    """A parameter vector evaluated without refitting (the parts of FitResult used here)."""

    model: object
    residuals: np.ndarray
    free: tuple

    def predict(self, v: np.ndarray) -> np.ndarray:
        """Model output (deg) for input ``v``."""
        return self.model.evaluate(v, self.model.values)


def start_as_fit(kind: str, v: np.ndarray, theta: np.ndarray, values: np.ndarray, fit_config):
    """:class:`StartEval` of ``values`` on (v, theta): the fallback when a refit is worse."""
    from i2ris_calib.fitting.pipeline import build_model

    model = build_model(kind, v, fit_config).with_values(values)
    free = tuple(p.name for p in model.parameters if not p.fixed)
    return StartEval(model, model.evaluate(v, model.values) - theta, free)


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


def profile_stderr(profile: OffsetProfile, best: float, halfwidth: float) -> float:
    """Standard error of the offset from the profile curvature, s.

    ``var = 2 sigma^2 / RSS''`` with ``sigma^2 = RSS_min / (n - p - 1)``, inflated by
    ``(1 + rho) / (1 - rho)`` for the lag-1 autocorrelation ``rho`` of the residuals
    (model misfit is correlated in time; white-noise errors would be too optimistic).
    The quadratic is fitted to the evaluated points within ``halfwidth`` of the
    minimum, widened twice (x2, x4) while there are too few or the fit is not convex;
    NaN if it never is.
    """
    x, y = profile.points()
    c2 = 0.0
    for width in (halfwidth, 2 * halfwidth, 4 * halfwidth):  # widen until curved
        sel = np.abs(x - best) <= width
        if sel.sum() >= 3:
            c2 = np.polyfit(x[sel] - best, y[sel], 2)[0]
            if c2 > 0:
                break
    if not c2 > 0:
        return float("nan")
    dof = max(profile.n_samples - profile.n_params - 1, 1)
    sigma2 = profile(best) / dof / TRIMMED_VARIANCE
    return float(np.sqrt(2 * sigma2 / (2 * c2) * residual_inflation(profile.fits(best))))


def residual_inflation(fits: list) -> float:
    """``(1 + rho) / (1 - rho)`` from the pooled lag-1 autocorrelation of the residuals."""
    num = den = 0.0
    for r in fits:
        e = r.residuals[np.isfinite(r.residuals)]
        if e.size < 3:
            continue
        e = e - e.mean()
        num += float(e[1:] @ e[:-1])
        den += float(e @ e)
    rho = min(max(num / den, 0.0), 0.95) if den > 0 else 0.0
    return (1 + rho) / (1 - rho)


def drift_gauss_newton(
    profile: OffsetProfile, offset_c_s: float, drift_ppm: float, iters: int = 4
) -> tuple[float, float, np.ndarray]:
    """(offset_c, drift) by Gauss-Newton with the fitted models held fixed.

    Returns the new offset at ``t_c``, drift (ppm) and their covariance (2, 2),
    inflated for residual autocorrelation like :func:`profile_stderr`.
    """
    fits = profile.fits(offset_c_s)
    o, d = offset_c_s, drift_ppm
    eps_o, eps_d = 1e-3, 50.0

    def predict(o_, d_):
        out = [
            f.predict(profile.inputs(b, o_, d_)) for b, f in zip(profile.blocks, fits, strict=True)
        ]
        return np.concatenate(out)

    theta = np.concatenate([b.theta_deg for b in profile.blocks])
    ok = np.isfinite(theta)
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
        cov = np.linalg.inv(a.T @ a) * float(r @ r) / dof
        if abs(step[0]) < 1e-5 and abs(step[1]) < 0.1:
            break
    return o, d, cov * residual_inflation(fits)


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
        Measured angles per axis.
    log : EncoderLog
        Encoder channels.
    cfg : SyncConfig
        ``model`` (egpi/gpi), ``profile_*``, ``estimate_drift``, ``min_axis_range_counts``.
    fit_config : FitConfig, optional
        Fitting settings (``[fit]``); holdout is disabled for the profile.
    prior : ClockModel, optional
        A coarser clock (sync event) bounding the offset search.

    Returns
    -------
    ClockModel
        With the offset profile (offsets at ``t_c``, RSS) as evidence.
    """
    from dataclasses import replace

    from i2ris_calib.fitting.config import FitConfig

    fit_config = replace(fit_config or FitConfig(), holdout_fraction=0.0)
    t_c = float(np.mean(np.concatenate([s.t_cam_s for s in series])))
    step = cfg.profile_step_s
    if prior is None:
        o_x, halfwidth = coarse_xcorr_offset(series, log, cfg), cfg.profile_halfwidth_s
        margin = 5 * halfwidth
    else:
        o_x = prior.offset_at(t_c)
        halfwidth = max(4 * prior.offset_stderr_at(t_c), 4 * cfg.profile_tol_s)
        step = min(step, halfwidth / 2)
        margin = 2 * halfwidth
    blocks = model_blocks(series, log, o_x, t_c, margin, fit_config, cfg.min_axis_range_counts)
    if not blocks:
        raise CalibError(
            "sync (model): no axis moves enough inside the encoder log to fit the hysteresis "
            f"(need > {cfg.min_axis_range_counts:g} counts of motion; use a sync flash instead)"
        )
    profile = OffsetProfile(blocks, log, t_c, 0.0, cfg.model, fit_config)
    best = scan_profile(profile, o_x, halfwidth, step, extend=prior is None)
    profile.cold = False  # refinement: warm starts only
    best = golden_min(profile, best - step, best + step, cfg.profile_tol_s)
    drift, drift_sd = 0.0, float("nan")
    if cfg.estimate_drift:
        for _ in range(2):  # drift with the models fixed, then the offset refitted at it
            _, drift, cov = drift_gauss_newton(profile, best, drift)
            drift_sd = float(np.sqrt(cov[1, 1]))
            seeds = profile.best_params()
            profile = OffsetProfile(blocks, log, t_c, drift, cfg.model, fit_config, seeds)
            best = golden_min(profile, best - step, best + step, cfg.profile_tol_s)
    sd_c = profile_stderr(profile, best, 1.5 * step)
    offset0 = best - drift * PPM * t_c  # offset at camera time 0 (t_ctrl - t_cam)
    var_d = drift_sd**2 if np.isfinite(drift_sd) else 0.0
    cov = np.array(
        [[sd_c**2 + (t_c * PPM) ** 2 * var_d, -t_c * PPM * var_d], [-t_c * PPM * var_d, var_d]]
    )
    x, y = profile.points()
    evidence = {
        "model": cfg.model,
        "xcorr_offset_s" if prior is None else "prior_offset_at_t_ref_s": o_x,
        "search_halfwidth_s": halfwidth,
        "t_ref_cam_s": t_c,
        "blocks": [{"name": b.name, "n_frames": int(b.t_cam_s.size)} for b in blocks],
        "profile": {"offset_at_t_ref_s": x, "rss_deg2": y},
        "n_samples": profile.n_samples,
        "rmse_deg": float(np.sqrt(profile(best) / TRIMMED_VARIANCE / max(profile.n_samples, 1))),
        "note": "offset profile of the hysteresis-model residual (formal stderr, inflated "
        "for residual autocorrelation)",
    }
    return clock_model(offset0, drift, cov, "model", evidence, cfg.estimate_drift)
