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

This module is the search loop; the pieces live by job in
:mod:`~i2ris_calib.diagnosis.data` (search data, :func:`check_dataset`),
:mod:`~i2ris_calib.diagnosis.stats` (scores, the held-out test),
:mod:`~i2ris_calib.diagnosis.candidates` (fitting one candidate) and
:mod:`~i2ris_calib.diagnosis.results` (the result types).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from i2ris_calib._validate import check_callable, check_choices, check_instance, check_model
from i2ris_calib.data.coupling import motors_together
from i2ris_calib.data.dataset import Dataset, checked_dataset, other_axis
from i2ris_calib.diagnosis.blas import single_threaded_blas
from i2ris_calib.diagnosis.candidates import fit_candidate, refit_globally
from i2ris_calib.diagnosis.config import DiagnosisConfig
from i2ris_calib.diagnosis.data import (
    SearchData,
    check_dataset,
    search_data,
    start_rule,
)
from i2ris_calib.diagnosis.locate import concentration_sentences, residual_analysis
from i2ris_calib.diagnosis.refit import refit
from i2ris_calib.diagnosis.results import (
    SEPARATING_FROM_BASE,
    Alternative,
    AutoDiagnosis,
    BaseRefit,
    Candidate,
    Diagnosis,
    ModelScore,
    Step,
    separating_experiment,
)
from i2ris_calib.diagnosis.stats import (
    RATE_EFFECTS,
    SPEED_EXPERIMENT,
    autocovariance,
    compare,
    n_free_of,
    score_of,
    speed_follows_level,
)
from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.config import FitConfig
from i2ris_calib.fitting.pipeline import (
    ModelChoice,
    checked_fit_config,
    fit_dataset,
    pick_after_fit,
)
from i2ris_calib.fitting.prehistory import InitialState
from i2ris_calib.hysteresis.effects import CATALOGUE, effects_of, model_values
from i2ris_calib.hysteresis.registry import (
    DIAGNOSIS_STARTS,
    SIGNED_DEFAULT,
    SIGNED_KINDS,
    diagnosis_starts,
    fit_order,
)
from i2ris_calib.model import Model

__all__ = [
    "AutoDiagnosis",
    "Diagnosis",
    "check_dataset",
    "diagnose",
    "diagnose_from_starts",
    "fit_start_model",
    "single_threaded_blas",
]


def _pick(passing: list[Candidate], d: SearchData, cfg: DiagnosisConfig) -> Candidate:
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


def _analysis(model: Model, d: SearchData) -> tuple[dict, tuple[str, ...]]:
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


def _judged(c: Candidate, current: Model, cur_m: ModelScore, d: SearchData, cfg) -> Candidate:
    """``c`` with its held-out comparison against the current model."""
    if c.model is None:
        return c
    comp = compare((current, cur_m), (c.model, c.metrics), d, cfg)
    return replace(c, comparison=comp)


def _finalists(cands, current, cur_m, d, cfg, progress) -> list[Candidate]:
    """The promising candidates (held-out z > ``promising_z`` and held-out RMSE
    lower), best ``n_finalists`` by held-out RMSE, refitted globally and judged
    again. A warm fit can miss an effect the base has absorbed (its comparison
    then looks weak); the global refit gives it a fair chance.

    A finalist whose warm held-out RMSE is more than ``global_refit_ratio`` x the
    best refitted finalist's keeps its warm fit (it is still judged and listed): a
    global refit does not close such a gap (measured over bench_diagnosis's 56 cases,
    424 refits: at most 1.14x lower; on a coupled two-motor recording the warm creep
    fits sat at 27x the coupling's and their refits cost 6 s of 22)."""
    promising = [
        c
        for c in cands
        if c.comparison is not None
        and c.comparison.z > cfg.promising_z
        and c.comparison.rel_improvement > 0
    ]
    ranked = sorted(promising, key=lambda c: c.metrics.holdout_rmse_deg)[: cfg.n_finalists]
    out: list[Candidate] = []
    best_global = np.inf
    for c in ranked:
        if c.metrics.holdout_rmse_deg > cfg.global_refit_ratio * best_global:
            out.append(c)  # hopeless: kept as warm-fitted (already judged)
            continue
        if progress:
            progress(f"{c.effect} (global refit)")
        out.append(_judged(refit_globally(c, d, cfg), current, cur_m, d, cfg))
        best_global = min(best_global, out[-1].metrics.holdout_rmse_deg)
    return out


def _null_reference(current, cur_m, best: Candidate, d, cfg):
    """(reference model and metrics, note or None, the refit as a :class:`BaseRefit`)
    for judging the winner.

    The current model is refitted from the winner's base values; if that alone is
    a significant improvement, the winner was partly a better optimum of the base
    model, and candidates are judged against the refit instead.
    """
    inner_x = model_values(best.model)[: best.model.n_inner]
    nul = refit(current, d.signals, d.theta, d.fit, inner_x, max_nfev=cfg.max_nfev)
    null_model = current.with_values(nul.values)
    null_m = score_of(null_model, nul.values, d, n_free_of(null_model))
    refitted = BaseRefit(null_model, f"refit from {best.effect}'s values")
    if not compare((current, cur_m), (null_model, null_m), d, cfg).significant:
        return (current, cur_m), None, refitted
    note = (
        f"the base model refitted from {best.effect}'s values fits better (held-out RMSE "
        f"{null_m.holdout_rmse_deg:.3g} vs {cur_m.holdout_rmse_deg:.3g} deg); candidates "
        "were judged against it"
    )
    return (null_model, null_m), note, refitted


def _alternatives(best: Candidate, finals, d: SearchData, cfg) -> tuple[Alternative, ...]:
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
            _alternative(
                c,
                comp,
                excluded=bool(comp.p_value < cfg.alpha),
                experiment=separating_experiment(best.effect, c.effect),
            )
        )
    return tuple(out)


def _alternative(c: Candidate, comp, excluded: bool, experiment: str, **extra) -> Alternative:
    """Candidate ``c`` as an :class:`Alternative` with the held-out comparison ``comp``."""
    return Alternative(
        effect=c.effect,
        holdout_rmse_deg=c.metrics.holdout_rmse_deg,
        z=comp.z,
        p_value=comp.p_value,
        excluded=excluded,
        params=effects_of(c.model)[-1][2],
        experiment=experiment,
        **extra,
    )


def _not_excluded(
    current: Model, cands: tuple[Candidate, ...], d: SearchData, cfg: DiagnosisConfig
) -> tuple[Alternative, ...]:
    """Candidates of the last round the data cannot tell from ``current``.

    A candidate is listed when (1) ``current`` is not significantly better on the
    held-out cycles (one-sided held-out z-test at ``alpha``) and (2) its fitted
    effect is material: the candidate with its effect set neutral (base values
    kept) moves the angle by more than the noise (RMS over the counted samples
    above the noise sd from the fitted-sample residual of ``current``). Both hold
    when the base absorbs the effect by moving its own parameters, e.g. a backlash
    on the input of a GPI/EGPI, whose envelope offsets shift by the slope times
    the half-width (docs/diagnosis.md).
    """
    if not cands:
        return ()
    y_cur = current.evaluate(d.signals, model_values(current))
    counted = d.fit | d.hold
    gamma = autocovariance((d.theta - y_cur)[d.fit], max_lag=50)
    noise_sd = float(np.sqrt(gamma[0])) if gamma.size else 0.0
    cur_m = score_of(current, model_values(current), d, n_free_of(current))
    out = []
    for c in cands:
        if c.model is None or c.comparison is None:
            continue
        x = model_values(c.model)
        m = c.model.n_inner
        x0 = x.copy()
        x0[m:] = c.model.effect.neutral()
        y_c = c.model.evaluate(d.signals, x)
        size = float(np.sqrt(np.mean((y_c - c.model.evaluate(d.signals, x0))[counted] ** 2)))
        if not size > noise_sd:
            continue
        comp = compare((c.model, c.metrics), (current, cur_m), d, cfg)
        if comp.p_value < cfg.alpha:
            continue
        out.append(
            _alternative(
                c,
                comp,
                excluded=False,
                experiment=SEPARATING_FROM_BASE.get(c.effect, ""),
                effect_rms_deg=size,
            )
        )
    return tuple(sorted(out, key=lambda a: a.holdout_rmse_deg))


def _rate_or_static(confounded: list[Candidate], current: Model) -> str:
    """The note of a recording whose input speed is a function of its level."""
    rate = sorted({c.effect for c in confounded})
    return (
        "not separable on this recording: a static (rate-independent) loop shape and "
        f"{' or '.join(rate)} fit it alike, because the input's speed is a function of "
        f"its level (one speed at each level on each branch, e.g. a one-frequency sine); "
        f"neither is named (the model stays {current.name}). To separate them, " + SPEED_EXPERIMENT
    )


def _rate_untestable(current: Model) -> str:
    """The note of a recording whose input speed is a function of its level when no
    rate effect fitted better: the static shape stands, but the recording could not
    have shown rate dependence either."""
    return (
        "rate dependence cannot be tested on this recording: the input's speed is a "
        "function of its level (one speed at each level on each branch, e.g. a "
        "one-frequency sine), so a static (rate-independent) loop shape and a rate effect "
        f"would fit it alike; the static shape stands (the model stays {current.name}). "
        "To test for rate dependence, " + SPEED_EXPERIMENT
    )


def _with_rate_alternatives(not_excluded, confounded, current, d, cfg):
    """``not_excluded`` with the confounded rate candidates (once each), listed with
    the separating recording (:data:`SPEED_EXPERIMENT`)."""
    out = list(not_excluded)
    seen: set[str] = set()
    cur_m = score_of(current, model_values(current), d, n_free_of(current))
    for c in sorted(confounded, key=lambda c: c.metrics.holdout_rmse_deg):
        if c.effect in seen:
            continue
        seen.add(c.effect)
        out = [a for a in out if a.effect != c.effect]
        comp = compare((c.model, c.metrics), (current, cur_m), d, cfg)
        out.append(_alternative(c, comp, excluded=False, experiment=SPEED_EXPERIMENT))
    return tuple(out)


#: Catalogue effects that model coupling to the other motor
COUPLING_EFFECTS = ("axis_coupling",)


def _coupling_note(data: Dataset) -> str:
    """The diagnosis's sentence on coupling to the other motor, or "" (the other motor
    does not move with this one, or its input is unknown):
    "coupling cannot be separated ..." when the two motors move in lockstep
    (:attr:`~i2ris_calib.data.coupling.MotorsTogether.cannot_separate`; the coupling
    effects are then not tried), else "coupling to the <other> motor: ..." (added when
    a coupling effect is named)."""
    other = other_axis(data.axis) if data.axis in ("yaw", "pitch") else "other"
    together = motors_together(data.enc, data.signals.v_other, other)
    if together is None or not together.moves_together:
        return ""
    if together.cannot_separate:
        return f"coupling cannot be separated on this recording: {together.reason}"
    return (
        f"coupling to the {other} motor: {together.reason}; the default fit models it "
        "(two-tendon GPI + hysteretic coupling, on the signed input)"
    )


def fit_start_model(kind: str, data: Dataset, fit_config=None) -> Model:
    """Starting model ``"gpi"`` or ``"egpi"`` fitted by the fitting stage
    (:func:`i2ris_calib.fitting.pipeline.fit_dataset`, multi-start) on the dataset's
    loss mask: exactly what ``fit`` fits on the same dataset."""
    if kind not in DIAGNOSIS_STARTS:
        raise CalibError(f"starting model must be {' or '.join(DIAGNOSIS_STARTS)}, got '{kind}'")
    with single_threaded_blas():
        return fit_dataset(kind, data, fit_config or FitConfig()).model


def diagnose(
    start: Model,
    data: Dataset,
    config: DiagnosisConfig | None = None,
    progress=None,
    initial_state: InitialState | None = None,
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
    initial_state : InitialState, optional
        The state the fit estimated at the first sample of a recording that does not
        start at rest (:attr:`FitResult.initial_state`): every model runs after its
        pre-history. Without it such a recording's burn-in (the samples until the
        input has reached both ends of its range) is left out of the loss. Ignored
        on a recording that starts at rest. ``notes`` says which.

    Returns
    -------
    Diagnosis

    Raises
    ------
    CalibError
        On a misuse, naming the argument: ``start`` not a model (a factory not
        called, a FitResult: its ``.model``), ``data`` not a Dataset (a list from
        ``load_synced``: one of it), ``config`` not a DiagnosisConfig.
    """
    func = "diagnose"
    check_model(func, "start", start, usage="diagnose(start, data)")
    checked_dataset(func, "data", data)
    config = _diagnosis_config(func, config)
    check_callable(func, "progress", progress)
    if initial_state is not None:
        check_instance(func, "initial_state", initial_state, InitialState,
                       hint="the fit's FitResult.initial_state, or None")  # fmt: skip
    with single_threaded_blas():
        return _diagnose(start, data, config, progress, initial_state)


def _diagnosis_config(func: str, config: object) -> DiagnosisConfig:
    """``config`` if a :class:`DiagnosisConfig`, the defaults for None, else CalibError."""
    if config is None:
        return DiagnosisConfig()
    return check_instance(
        func, "config", config, DiagnosisConfig,
        hint="e.g. DiagnosisConfig(max_steps=2); from a TOML file: load_config(path).diagnose",
    )  # fmt: skip


def _diagnose(start, data: Dataset, cfg, progress, initial_state=None) -> Diagnosis:
    d, hold_full, step = search_data(data, cfg, initial_state)
    coupling_note = _coupling_note(data)
    names = _candidate_names(cfg, coupling_note)
    current, cur_m = _polished(start, d, cfg)
    baseline, start_polished = cur_m, current
    base_refits = [BaseRefit(current, "refit of its starting fit")]
    steps: list[Step] = []
    last: tuple[Candidate, ...] = ()
    start_note = start_rule(data, initial_state)[1]
    notes: list[str] = [start_note] if start_note else []
    one_speed = speed_follows_level(d.signals, d.fit | d.hold)
    confounded: list[Candidate] = []
    for _ in range(cfg.max_steps):
        analysis, sentences = _analysis(current, d)
        cands, finals, passing, rate = _round_result(
            current, cur_m, names, one_speed, d, cfg, progress
        )
        last = cands
        confounded += rate
        if not passing:
            break
        ref, passing, note, refitted = _against_reference(current, cur_m, passing, d, cfg)
        if not effects_of(current):  # the starting model itself, refitted
            base_refits.append(refitted)
        if note:
            notes.append(f"step {len(steps) + 1}: {note}")
        if not passing:
            current, cur_m = ref
            continue
        best = _pick(passing, d, cfg)
        steps.append(_step_record(best, ref, finals, cands, (analysis, sentences), d, cfg))
        current, cur_m = best.model, best.metrics
        last = ()
    analysis, sentences = _analysis(current, d)
    more, not_excluded = _closing_notes(
        current, steps, last, coupling_note, confounded, one_speed, d, cfg
    )
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
        notes=tuple(notes + more),
        not_excluded=not_excluded,
        base_refits=tuple(base_refits),
    )


def _polished(start: Model, d: SearchData, cfg) -> tuple[Model, ModelScore]:
    """(``start`` refitted on the search data from its own values, its score)."""
    pol = refit(start, d.signals, d.theta, d.fit, model_values(start), max_nfev=cfg.start_max_nfev)
    polished = start.with_values(pol.values)
    return polished, score_of(polished, pol.values, d, n_free_of(polished))


def _against_reference(current, cur_m, passing: list[Candidate], d, cfg):
    """(reference = (model, metrics), the finalists still significant against it, note
    or None, the base refit as a :class:`BaseRefit`): the reference is ``current`` unless the base refitted from the best
    finalist's values is itself significantly better (:func:`_null_reference`); the
    finalists are then judged against that refit."""
    best = min(passing, key=lambda c: c.metrics.holdout_rmse_deg)
    ref, note, refitted = _null_reference(current, cur_m, best, d, cfg)
    if note:
        passing = [c for c in passing if compare(ref, (c.model, c.metrics), d, cfg).significant]
    return ref, passing, note, refitted


def _candidate_names(cfg, coupling_note: str) -> list[str]:
    """The catalogue effects to try: ``cfg.candidates`` (default all), without coupling
    when the recording cannot separate it (:func:`_coupling_note`)."""
    names = list(cfg.candidates or CATALOGUE)
    if coupling_note and coupling_note.startswith("coupling cannot"):
        names = [n for n in names if n not in COUPLING_EFFECTS]  # not identifiable here
    return names


def _round_result(current, cur_m, names, one_speed: bool, d, cfg, progress):
    """(candidates, finalists, significant finalists, confounded rate finalists) of one
    round from ``current``: every effect fitted, the finalists refitted globally (the
    candidates carry their refits). On a recording whose speed is a function of its
    level a rate effect fits as a static shape would: significant rate finalists are
    set apart (neither is named; both are listed with the separating recording)."""
    cands = _round(current, cur_m, names, d, cfg, progress)
    finals = _finalists(cands, current, cur_m, d, cfg, progress)
    refitted = {c.effect: c for c in finals}
    cands = tuple(refitted.get(c.effect, c) for c in cands)
    passing = [c for c in finals if c.comparison.significant]
    if not one_speed:
        return cands, finals, passing, []
    rate = [c for c in passing if c.effect in RATE_EFFECTS]
    return cands, finals, [c for c in passing if c.effect not in RATE_EFFECTS], rate


def _step_record(best, ref, finals, cands, analysis, d, cfg) -> Step:
    """The :class:`Step` that adds ``best`` to the reference ``ref`` = (model, metrics),
    with its comparison, the round's candidates, the alternatives among ``finals`` and
    the residual ``analysis`` = (numbers, sentences) before it."""
    alternatives = _alternatives(best, finals, d, cfg)
    return Step(
        effect=best.effect,
        model_before=ref[0],
        model_after=best.model,
        before=ref[1],
        after=best.metrics,
        comparison=compare(ref, (best.model, best.metrics), d, cfg),
        candidates=cands,
        analysis_before=analysis[0],
        sentences_before=analysis[1],
        alternatives=alternatives,
    )


def _closing_notes(current, steps, last, coupling_note, confounded, one_speed, d, cfg):
    """(notes, not excluded alternatives) at the end of a diagnosis: the coupling note
    when coupling was named or cannot be separated; the rate-vs-static note on a
    recording whose speed is a function of its level (the confounded rate candidates
    listed as not excluded, with the separating recording)."""
    notes = []
    if coupling_note:
        named = any(st.effect in COUPLING_EFFECTS for st in steps)
        if named or coupling_note.startswith("coupling cannot"):
            notes.append(coupling_note)
    not_excluded = _not_excluded(current, last, d, cfg)
    if confounded:
        notes.append(_rate_or_static(confounded, current))
        not_excluded = _with_rate_alternatives(not_excluded, confounded, current, d, cfg)
    elif one_speed:
        notes.append(_rate_untestable(current))
    return notes, not_excluded


def diagnose_from_starts(
    data: Dataset,
    config: DiagnosisConfig | None = None,
    fit_config=None,
    starts: tuple[str, ...] | None = None,
    progress=None,
) -> AutoDiagnosis:
    """``--start auto``: diagnose from each starting model, reconcile one answer.

    Each start is fitted by the fitting stage (:func:`fit_start_model`; the GPI fit,
    EGPI's nested start, only once) and diagnosed (:func:`diagnose`). The answer is the path whose final model has the
    lower held-out RMSE; the held-out z-test of it over the other path's final
    model says whether the other answer is excluded (p < ``alpha``) or not.

    Parameters
    ----------
    data : Dataset
    config : DiagnosisConfig, optional
    fit_config : FitConfig, optional
        Settings of the starting fits.
    starts : tuple of str, optional
        Starting models (``"gpi"``, ``"egpi"``, ``"agpi"``); default: on a signed
        dataset the one model ``fit`` picks after fitting its default kinds
        (:func:`~i2ris_calib.fitting.pipeline.pick_after_fit`: GPI or the two-tendon
        GPI, both fitted, the pick said in ``sentence``; the two-tendon GPI, the base of
        the coupled model, when the other motor moves with this one and coupling can be
        separated), GPI and EGPI on a direction's.
    progress : callable, optional
        ``progress(text)`` before each fit.
    """
    func = "diagnose_from_starts"
    checked_dataset(func, "data", data)
    cfg = _diagnosis_config(func, config)
    fit_config = checked_fit_config(func, fit_config, "fit_config")
    fitted: dict = {}  # start fits so far: GPI's is the nested start of EGPI's (fitted once)
    picked = ""
    if starts is None:
        starts, picked = _default_starts(data, fit_config, fitted, progress)
    starts = check_choices(func, "starts", starts, DIAGNOSIS_STARTS, repr(DIAGNOSIS_STARTS))
    if not starts:
        raise CalibError(
            f"{func}: starts is empty; give "
            f"{', '.join(repr((k,)) for k in DIAGNOSIS_STARTS)} or both"
        )
    signed_only = [k for k in starts if k not in diagnosis_starts(False)]
    if data.direction != "±" and signed_only:
        raise CalibError(
            f"{func}: starts {tuple(signed_only)!r} fit the signed input (one model across "
            f"zero), but data is {data.name}, one motion direction; give starts from "
            f"{diagnosis_starts(False)!r}, or the signed dataset of a recording whose "
            "input crosses zero"
        )
    check_callable(func, "progress", progress)
    for kind in starts:
        if kind not in fitted:
            if progress:
                progress(f"fitting {kind}")
            with single_threaded_blas():
                fitted[kind] = fit_dataset(kind, data, fit_config, dict(fitted))
    state = recording_start_state([fitted[k] for k in starts])
    paths = {}
    for kind in starts:
        paths[kind] = diagnose(
            fitted[kind].model,
            data,
            cfg,
            progress=(lambda x, k=kind: progress(f"{k}: {x}")) if progress else None,
            initial_state=state,
        )
    return _reconciled(paths, picked, data, cfg, state)


def recording_start_state(fits) -> InitialState | None:
    """The start state of the recording for every path of a diagnosis: the one the
    best-fitting start (lowest fitted RMSE) estimated (None: it starts at rest). One
    state for all paths, so their final models are compared on the same samples."""

    def rmse(r) -> float:
        x = float(r.metrics.rmse_deg)
        return x if np.isfinite(x) else float("inf")

    return min(fits, key=rmse).initial_state


def _default_starts(data: Dataset, fit_config, fitted: dict, progress) -> tuple:
    """(starting kinds, why picked) of ``--start auto``: on a signed dataset where the
    other motor moves with this one, the coupled model's base; on another signed
    dataset the model ``fit`` picks after fitting its signed kinds (fitted here, into
    ``fitted``); on a direction dataset GPI and EGPI."""
    other = other_axis(data.axis) if data.axis in ("yaw", "pitch") else "other"
    together = motors_together(data.enc, data.signals.v_other, other)
    coupled = together is not None and together.moves_together and together.coupled
    if data.direction == "±" and coupled:
        # fit's candidates include the coupled two-tendon GPI: start from its base, the
        # diagnosis tries the coupling (axis_coupling) as an effect
        return (SIGNED_DEFAULT,), "the other motor moves with this one: the coupled model's base"
    if data.direction != "±":
        return diagnosis_starts(False), ""
    for kind in fit_order(SIGNED_KINDS):  # the default model fit picks there
        if progress:
            progress(f"fitting {kind}")
        with single_threaded_blas():
            fitted[kind] = fit_dataset(kind, data, fit_config, dict(fitted))
    choice = ModelChoice(True, tuple(fit_order(SIGNED_KINDS)), "the signed input")
    choice = pick_after_fit(choice, [(data, fitted)])
    picked = choice.why[choice.why.find("picked after fitting") :] if choice.picked else ""
    return (choice.main,), picked


def _reconciled(paths: dict, picked: str, data: Dataset, cfg, state=None) -> AutoDiagnosis:
    """One answer from the diagnoses of each start (``paths``: kind -> Diagnosis): the
    path whose final model has the lower held-out RMSE, the other path's answer
    excluded or not by the held-out z-test (p < ``cfg.alpha``)."""
    order = sorted(paths, key=lambda k: paths[k].final.holdout_rmse_deg)
    best = order[0]
    diag = paths[best]
    named = {k: tuple(p.named_effects) for k, p in paths.items()}
    agree = len(set(named.values())) == 1

    def said(k):
        return ", ".join(named[k]) or "nothing missing"

    if len(order) == 1:
        how = f"from {best} ({picked})" if picked else f"from {best}"
        return AutoDiagnosis(best, diag, paths, True, float("nan"), f"{how}: {said(best)}")
    other = order[1]
    with single_threaded_blas():
        d, _, _ = search_data(data, cfg, state)
        a, b = paths[best].final_model, paths[other].final_model
        ma = score_of(a, model_values(a), d, n_free_of(a))
        mb = score_of(b, model_values(b), d, n_free_of(b))
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
    excluded = bool(comp.p_value < cfg.alpha)
    return AutoDiagnosis(best, diag, paths, agree, float(comp.z), sentence, excluded)
