"""Locate, name, add, repeat: the model-discrepancy workflow.

1. *Locate*: the current model's residual is analysed per branch, input range,
   time window, input rate, other axis, autocorrelation and lagged
   cross-correlation with the input (:mod:`i2ris_calib.diagnosis.locate`).
2. *Name*: every catalogue effect not yet in the model is fitted as an extension
   of the current fitted model (warm start from its values, a small grid over the
   effect's parameters, then a joint refit). A candidate is *significant* only if
   all three hold (defaults in :class:`~i2ris_calib.diagnosis.config.DiagnosisConfig`):

   - it lowers the RMSE on held-out loading cycles by at least
     ``min_rel_improvement`` (relative);
   - a one-sided z-test of the held-out SSE reduction (:func:`sse_reduction_z`,
     noise autocovariance from the fitted samples) rejects "no improvement" at
     level ``alpha``: the held-out cycles are fitted by neither model, so noise
     alone cannot make the reduction large;
   - BIC on the fitted samples falls by at least ``min_delta_bic`` (10 is "very
     strong" evidence on the Kass-Raftery scale).

   Warm fits that look promising (held-out z > ``promising_z``) are refitted
   globally (the fitting stage's multi-start fit) and judged again; only these
   finalists can be named. The winner must also beat, by the same rule, the
   current model refitted from its base values (so an effect is never credited
   with what was only a better optimum of the base model). Among significant
   finalists the lowest held-out RMSE wins, BIC breaking near-ties.
3. *Add and repeat* until no candidate is significant or ``max_steps`` is reached.

The data are one :class:`~i2ris_calib.data.Dataset` (one axis and motion direction
over the whole recording): every model runs over every sample in time order; the
fitted samples are the dataset's loss mask (``fit_mask``), the held-out samples its
held-out cycles (the fitting stage's one rule). See :func:`check_dataset` for the
least data the workflow can work with.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy import stats

from i2ris_calib.data.dataset import Dataset
from i2ris_calib.diagnosis.config import DiagnosisConfig
from i2ris_calib.diagnosis.cycles import dataset_cycles, holdout_units, loading_mask
from i2ris_calib.diagnosis.effects import (
    CATALOGUE,
    Effect,
    EffectModel,
    base_of,
    effects_of,
    model_values,
)
from i2ris_calib.diagnosis.locate import concentration_sentences, residual_analysis
from i2ris_calib.diagnosis.refit import refit, sse
from i2ris_calib.errors import CalibError
from i2ris_calib.hysteresis.model import Model, Signals
from i2ris_calib.hysteresis.models import ParametricModel


@dataclass(frozen=True)
class Metrics:
    """Fit quality of one model on one data set.

    Attributes
    ----------
    fit_rmse_deg, holdout_rmse_deg : float
        RMSE (deg, Eq25) on the fitted and on the held-out samples.
    bic : float
        ``n ln(SSE/n) + k ln n`` on the fitted samples of the search signal.
    n_free : int
        Free parameters k.
    """

    fit_rmse_deg: float
    holdout_rmse_deg: float
    bic: float
    n_free: int

    def as_dict(self) -> dict:
        """JSON-ready dict."""
        return {
            "fit_rmse_deg": self.fit_rmse_deg,
            "holdout_rmse_deg": self.holdout_rmse_deg,
            "bic": self.bic,
            "n_free": self.n_free,
        }


@dataclass(frozen=True)
class Comparison:
    """Evidence that ``after`` is better than ``before`` on held-out data.

    Attributes
    ----------
    rel_improvement : float
        ``1 - RMSE_after / RMSE_before`` on the held-out samples.
    z : float
        Held-out SSE reduction over its standard deviation under "the before
        model is adequate" (see :func:`sse_reduction_z`).
    p_value : float
        One-sided normal p-value of ``z``.
    units_improved, n_units : int
        Held-out units (loading cycles, halved until there are at least 6) whose
        mean squared error fell, out of all: descriptive, not the test.
    delta_bic : float
        BIC(after) - BIC(before) on the fitted samples (negative = better).
    significant : bool
        All three criteria met.
    """

    rel_improvement: float
    z: float
    p_value: float
    units_improved: int
    n_units: int
    delta_bic: float
    significant: bool

    def as_dict(self) -> dict:
        """JSON-ready dict."""
        return dict(self.__dict__)


@dataclass(frozen=True)
class Candidate:
    """One fitted candidate effect at one step."""

    effect: str
    model: Model | None
    metrics: Metrics | None
    comparison: Comparison | None
    skipped: str | None = None
    nfev: int = 0
    stage: str = "warm"

    def as_dict(self) -> dict:
        """JSON-ready dict (parameters of the effect only)."""
        if self.skipped:
            return {"effect": self.effect, "skipped": self.skipped}
        return {
            "effect": self.effect,
            "params": effects_of(self.model)[-1][2],
            "metrics": self.metrics.as_dict(),
            "evidence": self.comparison.as_dict(),
            "fit": self.stage,
            "nfev": self.nfev,
        }


@dataclass(frozen=True)
class Step:
    """One added effect, with the evidence and the residual analyses."""

    effect: str
    model_before: Model
    model_after: Model
    before: Metrics
    after: Metrics
    comparison: Comparison
    candidates: tuple[Candidate, ...]
    analysis_before: dict
    sentences_before: tuple[str, ...]
    alternatives: tuple[Alternative, ...] = ()


@dataclass(frozen=True)
class Alternative:
    """A finalist the held-out cycles could not rule out against the named effect.

    Attributes
    ----------
    effect : str
    holdout_rmse_deg : float
        Its held-out RMSE (deg).
    z : float
        Held-out SSE-reduction z of the named effect over it (:func:`sse_reduction_z`);
        below the ``alpha`` quantile the alternative is *not excluded*.
    p_value : float
    excluded : bool
        True when the named effect is significantly better on the held-out cycles.
    params : dict
        Its fitted effect parameters.
    experiment : str
        A recording that would separate it from the named effect ("" if none known).
    """

    effect: str
    holdout_rmse_deg: float
    z: float
    p_value: float
    excluded: bool
    params: dict
    experiment: str = ""

    def as_dict(self) -> dict:
        """JSON-ready dict."""
        return dict(self.__dict__)


_LONG_HOLDS = (
    "long holds (10 s or more) after fast ramps: creep keeps moving over seconds, a "
    "delay settles within its delay"
)

#: Recordings that separate two effects the held-out cycles could not tell apart.
SEPARATING_EXPERIMENTS: dict[frozenset, str] = {
    frozenset({"time_delay", "rate_dependent_thresholds"}): (
        "a slow and a fast ramp to the same level, and a triangle without a hold at the "
        "top: a delay overshoots a reversal taken at speed and lags by the same time at "
        "every speed, rate-dependent thresholds hold flat at the reversal"
    ),
    frozenset({"time_delay", "creep"}): _LONG_HOLDS,
    frozenset({"creep", "creep_log"}): (
        "holds of 30-60 s: first-order creep settles after a few time constants, "
        "logarithmic creep gains the same amount every decade of time"
    ),
    frozenset({"time_delay", "creep_log"}): _LONG_HOLDS,
    frozenset({"dead_zone", "backlash"}): (
        "a ramp that reverses mid-range and a return to zero: backlash holds the "
        "output after every reversal, a dead zone only near zero input"
    ),
    frozenset({"dead_zone", "multi_stage_backlash"}): (
        "partial unloading cycles that reverse above and below mid-range: a further "
        "backlash stage holds on falling input below its flag point, a dead zone holds "
        "only below its break point, rising or falling"
    ),
    frozenset({"backlash", "multi_stage_backlash"}): (
        "small reversals at several input levels: backlash holds at every reversal, a "
        "further stage only below its flag point"
    ),
    frozenset({"rate_dependent_thresholds", "rate_dependent_weights"}): (
        "ramps at three speeds to the same level with holds: rate-dependent weights "
        "change the slope of the loop while moving, rate-dependent thresholds its width"
    ),
    frozenset({"time_delay", "rate_dependent_weights"}): (
        "ramps at three speeds to the same level with holds: a delay shifts the loop in "
        "time, rate-dependent weights scale it with speed"
    ),
    frozenset({"saturation", "rate_dependent_weights"}): (
        "slow ramps to full scale: saturation flattens the top at any speed"
    ),
}


def separating_experiment(a: str, b: str) -> str:
    """A recording that separates effects ``a`` and ``b`` ("" if none is known)."""
    return SEPARATING_EXPERIMENTS.get(frozenset({a, b}), "")


@dataclass(frozen=True)
class Diagnosis:
    """Result of :func:`diagnose`.

    Attributes
    ----------
    start_model, final_model : Model
        Polished starting model and the final extended model (fitted values).
    baseline, final : Metrics
    steps : tuple of Step
        Effects added, in order.
    last_candidates : tuple of Candidate
        Candidates of the final (unsuccessful) round: why the search stopped.
    analysis_final : dict
        Residual analysis of the final model; ``sentences_final`` its summary.
    holdout : ndarray of bool, shape (n,)
        Held-out samples of the full signal that count (the dataset's held-out
        cycles, in direction, angle measured).
    decimation : int
        Step between the samples used in the search.
    """

    start_model: Model
    final_model: Model
    baseline: Metrics
    final: Metrics
    steps: tuple[Step, ...]
    last_candidates: tuple[Candidate, ...]
    analysis_final: dict
    sentences_final: tuple[str, ...]
    holdout: np.ndarray
    decimation: int
    notes: tuple[str, ...] = field(default_factory=tuple)

    @property
    def named_effects(self) -> list[str]:
        """Effect names in the order they were added (empty if nothing is missing)."""
        return [s.effect for s in self.steps]


@dataclass(frozen=True)
class _Data:
    """Search data: decimated signals, angle (0 where not counted), the fitted and
    held-out masks, held-out units and the loading branch."""

    signals: Signals
    theta: np.ndarray
    fit: np.ndarray
    hold: np.ndarray
    units: np.ndarray
    loading: np.ndarray


def metrics_of(model: Model, values: np.ndarray, d: _Data, n_free: int) -> Metrics:
    """Fitted/held-out RMSE (deg) and BIC of ``model`` at ``values`` on ``d``."""
    y = model.evaluate(d.signals, values)
    r = y - d.theta
    rf, rh = r[d.fit], r[d.hold]
    n = max(rf.size, 1)
    sse_f = float(np.dot(rf, rf))
    bic = n * np.log(max(sse_f, 1e-300) / n) + n_free * np.log(n)
    return Metrics(
        fit_rmse_deg=float(np.sqrt(sse_f / n)),
        holdout_rmse_deg=float(np.sqrt(np.mean(rh**2))) if rh.size else float("nan"),
        bic=float(bic),
        n_free=int(n_free),
    )


def autocovariance(e: np.ndarray, max_lag: int) -> np.ndarray:
    """Sample autocovariance of ``e`` (shape (n,)) at lags 0..L, Bartlett-tapered.

    ``L`` is the first lag where the autocorrelation drops below 0.1 (at most
    ``max_lag``); the taper ``1 - l/(L+1)`` keeps the implied variance positive
    (Newey-West).
    """
    e = np.asarray(e, float) - np.mean(e)
    n = e.size
    g0 = float(np.dot(e, e) / n) if n else 0.0
    gam = [g0]
    for lag in range(1, min(max_lag, n - 1) + 1):
        g = float(np.dot(e[lag:], e[:-lag]) / n)
        if g0 <= 0 or g / g0 < 0.1:
            break
        gam.append(g)
    L = len(gam) - 1
    return np.array([g * (1 - lag / (L + 1)) for lag, g in enumerate(gam)])


def sse_reduction_z(
    r_before: np.ndarray, delta: np.ndarray, gamma: np.ndarray
) -> tuple[float, float]:
    """z-score and one-sided p-value of the held-out SSE reduction.

    With ``r_b`` the held-out residual of the model before and ``delta`` the
    change of its prediction, ``SSE_b - SSE_a = sum(2 r_b delta - delta^2)``.
    If the model before is adequate, ``r_b`` is noise ``e`` (autocovariance
    ``gamma``) and ``2 sum(e delta)`` has variance ``4 delta' C delta``, so
    ``z = (SSE_b - SSE_a) / (2 sqrt(delta' C delta))`` exceeds the normal
    quantile with at most the nominal probability (its mean is ``-sum delta^2``
    <= 0: the test is conservative).

    Parameters
    ----------
    r_before, delta : ndarray, shape (m,)
        Held-out residual before (deg) and prediction change after - before (deg),
        in time order.
    gamma : ndarray, shape (L+1,)
        Noise autocovariance at lags 0..L (deg^2), from :func:`autocovariance`.
    """
    gain = float(np.sum(2 * r_before * delta - delta**2))
    var = gamma[0] * float(np.dot(delta, delta))
    for lag in range(1, gamma.size):
        var += 2 * gamma[lag] * float(np.dot(delta[lag:], delta[:-lag]))
    if var <= 0:
        return (np.inf if gain > 0 else 0.0), (0.0 if gain > 0 else 1.0)
    z = gain / (2 * np.sqrt(var))
    return float(z), float(stats.norm.sf(z))


def compare(
    before: tuple[Model, Metrics],
    after: tuple[Model, Metrics],
    d: _Data,
    cfg: DiagnosisConfig,
) -> Comparison:
    """Held-out evidence that ``after`` improves on ``before`` (see module doc).

    The noise autocovariance is estimated from the fitted-sample residual of
    ``after`` (the better model's residual is the closer one to pure noise).
    """
    mb, mtb = before
    ma, mta = after
    yb = mb.evaluate(d.signals, model_values(mb))
    ya = ma.evaluate(d.signals, model_values(ma))
    rb, ra = d.theta - yb, d.theta - ya
    gamma = autocovariance(ra[d.fit], max_lag=50)
    z, p = sse_reduction_z(rb[d.hold], (ya - yb)[d.hold], gamma)
    labels = np.unique(d.units[d.units >= 0])
    improved = sum(
        float(np.mean(ra[d.units == lab] ** 2)) < float(np.mean(rb[d.units == lab] ** 2))
        for lab in labels
    )
    rel = 1.0 - mta.holdout_rmse_deg / mtb.holdout_rmse_deg if mtb.holdout_rmse_deg > 0 else 0.0
    dbic = mta.bic - mtb.bic
    sig = bool(rel >= cfg.min_rel_improvement and p < cfg.alpha and dbic <= -cfg.min_delta_bic)
    return Comparison(
        rel_improvement=float(rel),
        z=z,
        p_value=p,
        units_improved=int(improved),
        n_units=int(labels.size),
        delta_bic=float(dbic),
        significant=sig,
    )


def _n_free(model: Model) -> int:
    return int(sum(not p.fixed for p in model.parameters))


def _restart_base(current: Model, x_cur: np.ndarray, effect, s0: np.ndarray, d: _Data):
    """A fresh base start for an input-side effect at ``s0`` (None if not applicable).

    The fitting stage's data-driven start of a GPI/EGPI computed on the input as
    the effect transforms it: a fit without the effect has bent its thresholds
    to absorb it, and a few profile iterations from there cannot undo that.
    """
    base = base_of(current)
    if type(effect).transform_input is Effect.transform_input or not isinstance(
        base, ParametricModel
    ):
        return None
    from i2ris_calib.fitting.initial import initial_values

    v_eff = effect.transform_input(d.signals, s0).v
    try:
        xb = initial_values(base, v_eff, np.where(d.fit, d.theta, np.nan))
    except (ValueError, CalibError, np.linalg.LinAlgError):
        return None
    if not np.all(np.isfinite(xb)):
        return None
    x = x_cur.copy()
    x[: xb.size] = xb
    return x


def fit_candidate(current: Model, name: str, d: _Data, cfg: DiagnosisConfig) -> Candidate:
    """Fit effect ``name`` as an extension of the fitted ``current`` model.

    Every start on the effect's grid is profiled (effect held, base parameters
    refitted for a few iterations, because the fitted base has already absorbed
    part of the effect); the two best profiles are refitted jointly.
    """
    effect = CATALOGUE[name]
    why = effect.available(d.signals)
    if why:
        return Candidate(name, None, None, None, skipped=why)
    x_cur = model_values(current)
    used = {lbl for _, lbl, _ in effects_of(current)}
    label = name if name not in used else f"{name}_2"
    proto = EffectModel(current, effect, tuple(effect.neutral()), label)
    y_cur = current.evaluate(d.signals, x_cur)
    m = x_cur.size
    base_only = np.ones(m + len(effect.params), dtype=bool)
    base_only[m:] = False

    def profile(x0: np.ndarray, nfev_cap: int):
        return refit(proto, d.signals, d.theta, d.fit, x0, free=base_only, max_nfev=nfev_cap)

    neutral = np.concatenate([x_cur, effect.neutral()])
    profiles = [refit(proto, d.signals, d.theta, d.fit, neutral, free=np.zeros_like(base_only))]
    profiles += [
        profile(np.concatenate([x_cur, s0]), cfg.profile_nfev)
        for s0 in effect.start_grid(d.signals, y_cur)
    ]
    profiles.sort(key=lambda r: r.sse_deg2)
    for top in profiles[: cfg.n_restarts]:
        xb = _restart_base(current, x_cur, effect, top.values[m:], d)
        if xb is not None:
            profiles.append(profile(np.concatenate([xb, top.values[m:]]), cfg.restart_nfev))
    nfev = sum(r.nfev for r in profiles)
    profiles.sort(key=lambda r: r.sse_deg2)
    best = None
    for start in profiles[:2]:
        r = refit(proto, d.signals, d.theta, d.fit, start.values, max_nfev=cfg.max_nfev)
        nfev += r.nfev
        if best is None or r.sse_deg2 < best.sse_deg2:
            best = r
    model = proto.with_values(best.values)
    return Candidate(
        name, model, metrics_of(model, best.values, d, _n_free(model)), None, nfev=nfev
    )


def _pick(passing: list[Candidate], d: _Data, cfg: DiagnosisConfig) -> Candidate:
    """The winner among significant finalists.

    ``choose_by = "holdout"`` (default): the lowest held-out RMSE wins unless a
    finalist with a BIC lower by at least ``min_delta_bic`` is not significantly
    worse on the held-out cycles (one-sided held-out z-test of the better one
    against it, level ``alpha``): the held-out cycles decide when they can tell
    two effects apart, BIC on the many fitted samples when they cannot.
    ``choose_by = "bic"``: lowest BIC.
    """
    if cfg.choose_by == "bic":
        return min(passing, key=lambda c: c.metrics.bic)
    ranked = sorted(passing, key=lambda c: c.metrics.holdout_rmse_deg)
    best = ranked[0]
    for c in ranked[1:]:
        if c.metrics.bic > best.metrics.bic - cfg.min_delta_bic:
            continue
        held_out_better = compare((c.model, c.metrics), (best.model, best.metrics), d, cfg)
        if not held_out_better.p_value < cfg.alpha:
            best = c
    return best


def _polished(c: Candidate, d: _Data, cfg: DiagnosisConfig) -> Candidate:
    """The named candidate refitted globally: the fitting stage's multi-start fit
    (:func:`i2ris_calib.fitting.fit.fit_model`, bounded) from the candidate's
    values and from data-driven base starts computed on the input as the effect
    transforms it. The base fitted without the effect has often absorbed part
    of it and sits in a poor basin; the best of all runs is kept."""
    model = c.model
    x = model_values(model)
    starts = [x]
    base = base_of(model)
    if cfg.n_global_starts > 0 and isinstance(base, ParametricModel):
        from i2ris_calib.fitting.initial import start_values

        sig_eff = model.effect.transform_input(d.signals, x[model.n_inner :])
        theta_fit = np.where(d.fit, d.theta, np.nan)
        rng = np.random.default_rng(cfg.seed)
        try:
            base_starts = start_values(base, sig_eff.v, theta_fit, cfg.n_global_starts, rng)
        except (ValueError, CalibError, np.linalg.LinAlgError):
            base_starts = []
        if model.n_inner == len(base.parameters):
            starts += [np.concatenate([b, x[model.n_inner :]]) for b in base_starts]
    from i2ris_calib.fitting.fit import fit_model

    try:
        res = fit_model(
            model,
            d.signals,
            d.theta,
            fit_mask=d.fit,
            holdout_mask=d.hold,
            starts=starts,
            method="trf",
            max_nfev=cfg.global_max_nfev,
            screen_nfev=cfg.global_max_nfev // 4,
        )
        x_new = model_values(res.model)
    except CalibError:
        x_new = x
    r = refit(model, d.signals, d.theta, d.fit, x_new, max_nfev=cfg.start_max_nfev)
    best = r.values if r.sse_deg2 <= sse(model, d.signals, d.theta, d.fit, x) else x
    model = model.with_values(best)
    return Candidate(
        c.effect,
        model,
        metrics_of(model, best, d, _n_free(model)),
        c.comparison,
        nfev=c.nfev,
        stage="global",
    )


def fit_start_model(kind: str, data: Dataset, fit_config=None) -> Model:
    """Starting model ``"gpi"`` or ``"egpi"`` fitted by the fitting stage
    (:func:`i2ris_calib.fitting.pipeline.fit_dataset`, multi-start) on the dataset's
    loss mask: exactly what ``fit`` fits on the same dataset."""
    from i2ris_calib.fitting.config import FitConfig
    from i2ris_calib.fitting.pipeline import fit_dataset

    if kind not in ("gpi", "egpi"):
        raise CalibError(f"starting model must be gpi or egpi, got '{kind}'")
    with single_threaded_blas():
        return fit_dataset(kind, data, fit_config or FitConfig()).model


#: Least fitted / held-out samples (angle measured, on the search signal) the
#: workflow accepts: the refits need many more residuals than parameters (a start
#: EGPI has 11 free, each effect adds up to 2), and the held-out test needs more
#: than a handful of held-out samples.
MIN_FITTED_SAMPLES = 50
MIN_HOLDOUT_SAMPLES = 20


def decimation_step(n: int, cfg: DiagnosisConfig) -> int:
    """Step k of the search signal (every k-th sample, at most ``max_samples``)."""
    return max(1, int(np.ceil(n / cfg.max_samples)))


def check_dataset(data: Dataset, config: DiagnosisConfig | None = None) -> None:
    """Raise a one-line CalibError unless the workflow can work with ``data``.

    The minimum (checked in this order):

    1. at least one held-out loading cycle. With the held-out rule
       (:func:`i2ris_calib.fitting.cycles.holdout_mask`) that means at least 2
       loading cycles, and one of them other than the first lying inside the input
       range of the others (a held-out cycle tests interpolation); the first cycle
       is never held out. Two such cycles are enough.
    2. at least :data:`MIN_FITTED_SAMPLES` fitted and :data:`MIN_HOLDOUT_SAMPLES`
       held-out samples with the angle measured on the search signal (every k-th
       sample, see :func:`decimation_step`).
    """
    cfg = config or DiagnosisConfig()
    where = f"{data.source} [{data.name}]" if data.source else data.name
    ok = np.isfinite(data.theta_deg)
    hold = data.holdout & ok
    if not hold.any():
        cyc = dataset_cycles(data.v)
        n_cyc = int(np.unique(cyc[data.in_direction]).size) if data.in_direction.any() else 0
        why = (
            "only 1 loading cycle"
            if n_cyc == 1
            else f"{n_cyc} loading cycles"
            + (
                ", but every cycle after the first leaves the input range of the others"
                if n_cyc >= 2
                else ""
            )
        )
        raise CalibError(
            f"{where}: {why}; diagnosis needs a held-out loading cycle, i.e. at least 2 "
            "loading cycles with the angle measured, one of them (not the first) inside "
            "the input range of the others: record more cycles (or check [fit] "
            "holdout_fraction > 0)"
        )
    step = decimation_step(data.n_samples, cfg)
    n_fit = int((data.fit_mask[::step]).sum())
    n_hold = int(hold[::step].sum())
    if n_fit < MIN_FITTED_SAMPLES or n_hold < MIN_HOLDOUT_SAMPLES:
        raise CalibError(
            f"{where}: {n_fit} fitted and {n_hold} held-out samples with the angle measured"
            + (f" (every {step}th sample)" if step > 1 else "")
            + f"; diagnosis needs at least {MIN_FITTED_SAMPLES} fitted and "
            f"{MIN_HOLDOUT_SAMPLES} held-out: record longer cycles or at a higher rate"
            + (" (or raise [diagnose] max_samples)" if step > 1 else "")
        )


def _search_data(data: Dataset, cfg: DiagnosisConfig) -> tuple[_Data, np.ndarray, int]:
    """Decimated search data, the full held-out mask and the decimation step."""
    check_dataset(data, cfg)
    theta_full = np.asarray(data.theta_deg, float)
    ok_full = np.isfinite(theta_full)
    hold_full = data.holdout & ok_full
    step = decimation_step(data.n_samples, cfg)
    idx = np.arange(0, data.n_samples, step)
    sig = data.signals.take(idx)
    th = theta_full[idx]
    ok = ok_full[idx]
    hold = hold_full[idx]
    fit = data.fit_mask[idx]
    units = holdout_units(dataset_cycles(data.v)[idx], hold)
    loading = loading_mask(data.v, data.bands.deadband)[idx]
    d = _Data(sig, np.where(ok, th, 0.0), fit, hold, units, loading)
    return d, hold_full, step


def _analysis(model: Model, d: _Data) -> tuple[dict, tuple[str, ...]]:
    res = d.theta - model.evaluate(d.signals, model_values(model))
    res = np.where(d.fit | d.hold, res, np.nan)
    a = residual_analysis(res, d.signals, d.loading)
    return a, tuple(concentration_sentences(a))


def _round(current, cur_m, names, d, cfg, progress) -> tuple[Candidate, ...]:
    """Every catalogue effect not yet in ``current``, warm-fitted and compared."""
    done = {e for e, _, _ in effects_of(current)}
    cands = []
    for name in names:
        if name in done:
            continue
        if progress:
            progress(name)
        c = fit_candidate(current, name, d, cfg)
        cands.append(_judged(c, current, cur_m, d, cfg))
    return tuple(cands)


def _judged(c: Candidate, current: Model, cur_m: Metrics, d: _Data, cfg) -> Candidate:
    """``c`` with its held-out comparison against the current model."""
    if c.model is None:
        return c
    comp = compare((current, cur_m), (c.model, c.metrics), d, cfg)
    return replace(c, comparison=comp)


def _finalists(cands, current, cur_m, d, cfg, progress) -> list[Candidate]:
    """The promising candidates (held-out z > ``promising_z`` and held-out RMSE
    lower), best ``n_finalists`` by held-out RMSE, refitted globally and judged
    again. A warm fit can miss an effect the base has absorbed (its comparison
    then looks weak); the global refit gives it a fair chance."""
    promising = [
        c
        for c in cands
        if c.comparison is not None
        and c.comparison.z > cfg.promising_z
        and c.comparison.rel_improvement > 0
    ]
    ranked = sorted(promising, key=lambda c: c.metrics.holdout_rmse_deg)[: cfg.n_finalists]
    out = []
    for c in ranked:
        if progress:
            progress(f"{c.effect} (global refit)")
        out.append(_judged(_polished(c, d, cfg), current, cur_m, d, cfg))
    return out


def _null_reference(current, cur_m, best: Candidate, d, cfg):
    """(reference model and metrics, note or None) for judging the winner.

    The current model is refitted from the winner's base values; if that alone is
    a significant improvement, the winner was partly a better optimum of the base
    model, and candidates are judged against the refit instead.
    """
    inner_x = model_values(best.model)[: best.model.n_inner]
    nul = refit(current, d.signals, d.theta, d.fit, inner_x, max_nfev=cfg.max_nfev)
    null_model = current.with_values(nul.values)
    null_m = metrics_of(null_model, nul.values, d, _n_free(null_model))
    if not compare((current, cur_m), (null_model, null_m), d, cfg).significant:
        return (current, cur_m), None
    note = (
        f"the base model refitted from {best.effect}'s values fits better (held-out RMSE "
        f"{null_m.holdout_rmse_deg:.3g} vs {cur_m.holdout_rmse_deg:.3g} deg); candidates "
        "were judged against it"
    )
    return (null_model, null_m), note


def _alternatives(best: Candidate, finals, d: _Data, cfg) -> tuple[Alternative, ...]:
    """The other finalists that improved the held-out error, best first, with the
    held-out z of the named effect over each (``excluded`` when it is significant
    at ``alpha``)."""
    out = []
    others = [
        c
        for c in finals
        if c.effect != best.effect and c.comparison is not None and c.comparison.rel_improvement > 0
    ]
    for c in sorted(others, key=lambda c: c.metrics.holdout_rmse_deg):
        comp = compare((c.model, c.metrics), (best.model, best.metrics), d, cfg)
        out.append(
            Alternative(
                effect=c.effect,
                holdout_rmse_deg=c.metrics.holdout_rmse_deg,
                z=comp.z,
                p_value=comp.p_value,
                excluded=bool(comp.p_value < cfg.alpha),
                params=effects_of(c.model)[-1][2],
                experiment=separating_experiment(best.effect, c.effect),
            )
        )
    return tuple(out)


def single_threaded_blas():
    """Context limiting BLAS to one thread (threadpoolctl), a no-op without it.

    The diagnosis runs thousands of small least-squares steps (Jacobians of
    ~10^3 x 13); multi-threaded BLAS only adds synchronisation to their SVDs and,
    on a loaded machine, made them ~10x slower (measured: 27 s vs 2.5 s per
    diagnosis on 2 shared cores).
    """
    import contextlib

    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - optional dependency
        return contextlib.nullcontext()
    return threadpool_limits(limits=1, user_api="blas")


def diagnose(
    start: Model,
    data: Dataset,
    config: DiagnosisConfig | None = None,
    progress=None,
) -> Diagnosis:
    """Run locate -> name -> add until no candidate effect helps.

    Parameters
    ----------
    start : Model
        Starting model with fitted (or at least sensible) values, e.g. a GPI or
        EGPI from :func:`fit_start_model`; it is polished on the fitted samples first.
    data : Dataset
        One axis and motion direction over the whole recording: ``signals`` (shape
        (n,) each, time order; ``t_s`` needed by the time-dependent effects,
        ``v_other``/``theta_other_deg`` by coupling), ``theta_deg`` (deg, the
        direction's convention, NaN where not measured or not in the direction),
        ``fit_mask`` and ``holdout`` (whole loading cycles). Every model runs over
        every sample; only the direction's measured samples are compared.
    config : DiagnosisConfig, optional
    progress : callable, optional
        ``progress(text)`` called before each candidate fit (for a progress bar).

    Returns
    -------
    Diagnosis
    """
    with single_threaded_blas():
        return _diagnose(start, data, config or DiagnosisConfig(), progress)


def _diagnose(start, data: Dataset, cfg, progress) -> Diagnosis:
    d, hold_full, step = _search_data(data, cfg)
    names = list(cfg.candidates or CATALOGUE)
    pol = refit(start, d.signals, d.theta, d.fit, model_values(start), max_nfev=cfg.start_max_nfev)
    current = start.with_values(pol.values)
    cur_m = metrics_of(current, pol.values, d, _n_free(current))
    baseline = cur_m
    start_polished = current
    steps: list[Step] = []
    last: tuple[Candidate, ...] = ()
    notes: list[str] = []
    for _ in range(cfg.max_steps):
        analysis, sentences = _analysis(current, d)
        cands = _round(current, cur_m, names, d, cfg, progress)
        finals = _finalists(cands, current, cur_m, d, cfg, progress)
        refitted = {c.effect: c for c in finals}
        cands = tuple(refitted.get(c.effect, c) for c in cands)
        last = cands
        passing = [c for c in finals if c.comparison.significant]
        if not passing:
            break
        best = min(passing, key=lambda c: c.metrics.holdout_rmse_deg)
        ref, note = _null_reference(current, cur_m, best, d, cfg)
        if note:
            notes.append(f"step {len(steps) + 1}: {note}")
            passing = [c for c in passing if compare(ref, (c.model, c.metrics), d, cfg).significant]
            if not passing:
                current, cur_m = ref
                continue
        best = _pick(passing, d, cfg)
        alternatives = _alternatives(best, finals, d, cfg)
        steps.append(
            Step(
                effect=best.effect,
                model_before=ref[0],
                model_after=best.model,
                before=ref[1],
                after=best.metrics,
                comparison=compare(ref, (best.model, best.metrics), d, cfg),
                candidates=cands,
                analysis_before=analysis,
                sentences_before=sentences,
                alternatives=alternatives,
            )
        )
        current, cur_m = best.model, best.metrics
        last = ()
    analysis, sentences = _analysis(current, d)
    return Diagnosis(
        start_model=start_polished,
        final_model=current,
        baseline=baseline,
        final=cur_m,
        steps=tuple(steps),
        last_candidates=last,
        analysis_final=analysis,
        sentences_final=sentences,
        holdout=hold_full,
        decimation=step,
        notes=tuple(notes),
    )


@dataclass(frozen=True)
class AutoDiagnosis:
    """Diagnoses from several starting models, reconciled into one answer.

    Attributes
    ----------
    start : str
        The starting model of the answer (``"gpi"`` or ``"egpi"``).
    diagnosis : Diagnosis
        The answer: the path whose final model has the lower held-out RMSE.
    paths : dict of str to Diagnosis
        Every path, by starting model.
    agree : bool
        All paths named the same effects.
    z : float
        Held-out SSE-reduction z of the answer's final model over the other path's
        (nan with one path); below the ``alpha`` quantile the other path's answer is
        not excluded.
    sentence : str
        The reconciliation in one sentence.
    """

    start: str
    diagnosis: Diagnosis
    paths: dict
    agree: bool
    z: float
    sentence: str


def diagnose_from_starts(
    data: Dataset,
    config: DiagnosisConfig | None = None,
    fit_config=None,
    starts: tuple[str, ...] = ("gpi", "egpi"),
    progress=None,
) -> AutoDiagnosis:
    """``--start auto``: diagnose from each starting model, reconcile one answer.

    Each start is fitted by the fitting stage (:func:`fit_start_model`) and
    diagnosed (:func:`diagnose`). The answer is the path whose final model has the
    lower held-out RMSE; the held-out z-test of it over the other path's final
    model says whether the other answer is excluded (p < ``alpha``) or not.

    Parameters
    ----------
    data : Dataset
    config : DiagnosisConfig, optional
    fit_config : FitConfig, optional
        Settings of the starting fits.
    starts : tuple of str
        Starting models (``"gpi"``, ``"egpi"``).
    progress : callable, optional
        ``progress(text)`` before each fit.
    """
    cfg = config or DiagnosisConfig()
    paths = {}
    for kind in starts:
        if progress:
            progress(f"fitting {kind}")
        base = fit_start_model(kind, data, fit_config)
        paths[kind] = diagnose(
            base,
            data,
            cfg,
            progress=(lambda x, k=kind: progress(f"{k}: {x}")) if progress else None,
        )
    order = sorted(paths, key=lambda k: paths[k].final.holdout_rmse_deg)
    best = order[0]
    diag = paths[best]
    named = {k: tuple(p.named_effects) for k, p in paths.items()}
    agree = len(set(named.values())) == 1

    def said(k):
        return ", ".join(named[k]) or "nothing missing"

    if len(order) == 1:
        return AutoDiagnosis(best, diag, paths, True, float("nan"), f"from {best}: {said(best)}")
    other = order[1]
    with single_threaded_blas():
        d, _, _ = _search_data(data, cfg)
        a, b = paths[best].final_model, paths[other].final_model
        ma = metrics_of(a, model_values(a), d, _n_free(a))
        mb = metrics_of(b, model_values(b), d, _n_free(b))
        comp = compare((b, mb), (a, ma), d, cfg)
    if agree:
        sentence = f"both starts agree: {said(best)} (answer from {best}, lower held-out RMSE)"
    elif comp.p_value < cfg.alpha:
        sentence = (
            f"{said(best)} (from {best}); the {other} start's answer ({said(other)}) is "
            f"excluded by the held-out cycles, z = {comp.z:.1f}"
        )
    else:
        sentence = (
            f"{said(best)} (from {best}); the {other} start's answer ({said(other)}) is not "
            f"excluded, z = {comp.z:.1f}"
        )
    return AutoDiagnosis(best, diag, paths, agree, float(comp.z), sentence)
