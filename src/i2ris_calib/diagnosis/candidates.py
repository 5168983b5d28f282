"""Candidate fitting: one catalogue effect fitted as an extension of the current
model (warm profiles on the effect's grid, data-driven base restarts, a joint
refit), and the global multi-start refit of a finalist.
"""

from __future__ import annotations

import numpy as np

from i2ris_calib.diagnosis.config import DiagnosisConfig
from i2ris_calib.diagnosis.data import SearchData
from i2ris_calib.diagnosis.refit import refit, sse
from i2ris_calib.diagnosis.results import Candidate
from i2ris_calib.diagnosis.stats import n_free_of, score_of
from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.fit import fit_model
from i2ris_calib.hysteresis.effects import (
    CATALOGUE,
    Effect,
    EffectModel,
    base_of,
    effects_of,
    model_values,
)
from i2ris_calib.hysteresis.models import ParametricModel
from i2ris_calib.hysteresis.start import initial_values, start_values
from i2ris_calib.model import Model


def _restart_base(current: Model, x_cur: np.ndarray, effect, s0: np.ndarray, d: SearchData):
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


def fit_candidate(current: Model, name: str, d: SearchData, cfg: DiagnosisConfig) -> Candidate:
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
        name, model, score_of(model, best.values, d, n_free_of(model)), None, nfev=nfev
    )


def refit_globally(c: Candidate, d: SearchData, cfg: DiagnosisConfig) -> Candidate:
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
        sig_eff = model.effect.transform_input(d.signals, x[model.n_inner :])
        theta_fit = np.where(d.fit, d.theta, np.nan)
        rng = np.random.default_rng(cfg.seed)
        try:
            base_starts = start_values(base, sig_eff.v, theta_fit, cfg.n_global_starts, rng)
        except (ValueError, CalibError, np.linalg.LinAlgError):
            base_starts = []
        if model.n_inner == len(base.parameters):
            starts += [np.concatenate([b, x[model.n_inner :]]) for b in base_starts]
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
            # the candidate's own start x already holds the base fit with the effect
            # profiled from neutral; a further nested refit of the base would cost a
            # base fit per candidate and, on a tie, hide an effect the base absorbs
            nested=False,
            # after the fit's pre-history the models start relaxed, as every other
            # evaluation of the diagnosis runs them: no second start state on top
            initial_state="rest" if d.relaxed else "auto",
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
        score_of(model, best, d, n_free_of(model)),
        c.comparison,
        nfev=c.nfev,
        stage="global",
    )
