"""Fit GPI and EGPI to one motion-direction dataset: build, start, split, fit.

A dataset (:class:`i2ris_calib.data.Dataset`) is the whole recording with the
direction's input and a loss mask: every model runs over every sample in time order.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from i2ris_calib._validate import (
    as_1d_bool,
    as_1d_float,
    check_instance,
    check_model,
    describe,
    same_length,
)
from i2ris_calib.data.coupling import MotorsTogether
from i2ris_calib.data.cycles import cycle_index, holdout_mask
from i2ris_calib.data.dataset import Dataset, checked_dataset
from i2ris_calib.data.excursions import Excursions
from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.config import FitConfig
from i2ris_calib.fitting.decision import Evidence, decide, decide_fits, output_jump, pooled
from i2ris_calib.fitting.fit import LARGE_ROWS, fit_cost, fit_model, lower_optimum
from i2ris_calib.fitting.prehistory import innermost
from i2ris_calib.fitting.result import FitResult, fit_notices
from i2ris_calib.hysteresis.models import ParametricModel
from i2ris_calib.hysteresis.registry import (
    COUPLED_DEFAULT,
    DEFAULT_DEADBAND_COUNTS,
    MODEL_KINDS,
    SIGNED_DEFAULT,
    SIGNED_KINDS,
    fit_order,
    kind_info,
    kind_of,
    model_for_kind,
    signed_kinds,
    start_recipe,
)
from i2ris_calib.hysteresis.start import default_deadband, keep_fixed
from i2ris_calib.model import Signals

__all__ = [
    "MODEL_KINDS",
    "ModelChoice",
    "choose_model",
    "dataset_cost",
    "output_jump",
    "pick_after_fit",
    "unfitted_model",
    "deadband_for",
    "fit",
    "fit_all",
    "fit_dataset",
    "fit_dataset_all",
    "fit_kind",
    "fit_warnings",
    "model_from_params",
    "split_masks",
]


@dataclass(frozen=True)
class ModelChoice:
    """Which models ``fit`` fits, on which input, and why (docs/fit.md, "Which model").

    The kinds and the input are chosen from the recording before fitting
    (:func:`choose_model`); on the signed input the default model among them is picked
    after fitting from the held-out errors (:func:`pick_after_fit`).

    Attributes
    ----------
    signed : bool
        One model per axis over the whole signed input (dataset ``"±"``); else the
        paper's split into motion directions.
    kinds : tuple of str
        Model kinds to fit (registry names), in fitting order.
    why : str
        The reason, in a few words (the recording's zero crossings and rests, or the
        option that forced it; whether the other motor moves with this one; after
        fitting, the held-out figures that decided the default model).
    coupling : MotorsTogether or None
        How the other motor moves with this one (:mod:`i2ris_calib.data.coupling`);
        None when the recording has no other motor's input.
    picked : str or None
        The default model picked after fitting (:func:`pick_after_fit`); None before
        fitting (then :attr:`main` is :attr:`prefit_main`).
    held_out : tuple of (str, float)
        Held-out RMSE (deg) per candidate kind that decided :attr:`picked`.
    """

    signed: bool
    kinds: tuple[str, ...]
    why: str
    coupling: MotorsTogether | None = None
    picked: str | None = None
    held_out: tuple[tuple[str, float], ...] = ()

    @property
    def prefit_main(self) -> str:
        """The default model known before fitting: the coupled two-tendon GPI when
        fitted, else the two-tendon GPI on a signed input, else the last kind (what the
        model clock-sync method fits: :mod:`i2ris_calib.sync.joint`)."""
        for kind in (COUPLED_DEFAULT, SIGNED_DEFAULT):
            if self.signed and kind in self.kinds:
                return kind
        return self.kinds[-1]

    @property
    def main(self) -> str:
        """The default model: picked after fitting (:func:`pick_after_fit`), else
        :attr:`prefit_main`."""
        return self.picked if self.picked is not None else self.prefit_main

    @property
    def line(self) -> str:
        """One line for the terminal and the report, e.g. ``model: two-tendon GPI over
        the signed input (the input crosses zero 14 times; ...)``."""
        if self.signed:
            what = f"{kind_info(self.main).report_name} over the signed input"
        else:
            what = " / ".join(kind_info(k).report_name for k in self.kinds)
            what += " per motion direction (the paper's split)"
        return f"model: {what} ({self.why})"

    def as_dict(self) -> dict:
        """The fit.json ``model_choice`` record (``main``: the default model, picked
        after fitting on the signed input (None on the paper's split: each dataset's
        ``decision`` names its model); ``prefit_main``: the one known before;
        ``held_out_rmse_deg``: the figures that decided, by kind)."""
        return {"input": "signed" if self.signed else "split", "kinds": list(self.kinds),
                # the paper's split: each direction dataset has its own ``decision``
                "main": self.main if self.signed else None, "prefit_main": self.prefit_main,
                "picked_after_fit": self.picked is not None,
                "held_out_rmse_deg": dict(self.held_out),
                "why": self.why, "line": self.line,
                "coupling": None if self.coupling is None else self.coupling.as_dict()}  # fmt: skip


def pick_after_fit(
    choice: ModelChoice,
    fitted: Sequence[tuple[Dataset, dict[str, FitResult]]],
    evidence: Sequence[dict[str, Evidence]] | None = None,
) -> ModelChoice:
    """The choice with its default model picked from the fits (signed input only).

    The one rule of :func:`i2ris_calib.fitting.decision.decide` on the fits of
    ``choice.kinds`` pooled over the datasets (:func:`~i2ris_calib.fitting.decision.pooled`):
    the lowest held-out RMSE among the usable models, a simpler one within 5 %
    preferred; with none usable, the lowest held-out RMSE. ``why`` gets the figures
    that decided, e.g. ``picked after fitting: agpi: held-out 0.21 deg vs gpi 1.4 deg``.
    The paper's split (and one kind) is returned unchanged.

    ``fitted``: (dataset, {kind: FitResult}) per dataset, as :func:`fit_dataset` gives;
    ``evidence``: each dataset's :func:`~i2ris_calib.fitting.decision.decide_fits`
    evidence when already measured.
    """
    kinds = [k for k in choice.kinds if all(k in res for _, res in fitted)]
    if not choice.signed or len(kinds) < 2 or not fitted:
        return choice
    if evidence is None:
        evidence = [decide_fits(d, {k: res[k] for k in kinds})[1] for d, res in fitted]
    dec = decide("all", [pooled([ev[k] for ev in evidence]) for k in kinds])
    pick = dec.model or dec.fallback
    if pick is None:
        return choice
    text = f"picked after fitting: {dec.why}"
    held = tuple((k, v) for k, v in dec.held_out_rmse_deg if k in kinds)
    return replace(choice, why=f"{choice.why}; {text}", picked=pick, held_out=held)


def choose_model(
    recording: Excursions | None,
    config: FitConfig = FitConfig(),
    model: str = "all",
    together: MotorsTogether | None = None,
) -> ModelChoice:
    """The models of a fit and their input: the paper's per-direction split, or one
    model per axis over the whole signed input (the two-tendon GPI).

    Signed when ``config.signed`` (``--signed``), when ``model`` needs the signed input,
    or - unless ``config.split`` (``--split``) - when the recording calls for it
    (:attr:`Excursions.signed`: both sides move, and the input crosses zero or an
    excursion does not start at rest). ``model``: ``"all"`` (the default kinds of that
    input: :data:`MODEL_KINDS` split, :data:`SIGNED_KINDS` signed) or one kind.

    ``together``: how the other motor moves with this one
    (:func:`i2ris_calib.data.coupling.motors_together`). On a signed input with
    ``model = "all"``, when the other motor moves while this one does and the recording
    can separate coupling (:attr:`MotorsTogether.coupled`), the two-tendon GPI with
    coupling to the other motor (:data:`COUPLED_DEFAULT`) is fitted too and is the
    default model, and the one-loop kinds (PI / Maxwell slip, Bouc-Wen: no input of
    the other motor) are left out (:func:`~i2ris_calib.hysteresis.registry.signed_kinds`);
    ``why`` says so, or why not.

    Raises
    ------
    CalibError
        ``model`` needs the signed input but ``config.split`` is set.
    """
    needs_signed = model != "all" and kind_info(model).signed
    if needs_signed and config.split:
        raise CalibError(f"--model {model} is fitted on the signed input; drop --split")
    seen = "" if recording is None else recording.reason
    if config.signed:
        signed, why = True, "--signed"
    elif needs_signed:
        signed, why = True, f"--model {model}"
    elif config.split:
        signed, why = False, "--split" + (f"; the recording: {seen}" if seen else "")
    else:
        signed, why = bool(recording is not None and recording.signed), seen
    if model == "all":
        kinds = SIGNED_KINDS if signed else MODEL_KINDS
    else:
        kinds = (model,)
    why = why or "default"
    if together is not None and together.moves_together:
        if signed and model == "all" and together.coupled:
            # a tendon axis moved by two motors: the coupled model and its bases (the
            # one-loop kinds, without the other motor's input, are left out)
            kinds = (*signed_kinds(coupled=True), COUPLED_DEFAULT)
            why += f"; with coupling: {together.reason}"
        elif together.cannot_separate and model != "all" and kind_info(model).coupled:
            why += (
                f"; coupling terms fitted as --model asks, though {together.reason}: "
                "expect their values not to be identified"
            )
        elif together.cannot_separate:
            why += f"; no coupling term: {together.reason}"
        elif not signed:
            why += f"; {together.reason} (coupling is modelled on the signed input: --signed)"
    return ModelChoice(signed, tuple(fit_order(kinds)), why, together)


def deadband_for(v: np.ndarray, config: FitConfig) -> float:
    """The ``v'`` dead band (input unit): configured, or derived from the input
    (:func:`i2ris_calib.data.dataset.input_bands`)."""
    if config.deadband_counts >= 0:
        return float(config.deadband_counts)
    return default_deadband(v)


def unfitted_model(
    kind: str, v: np.ndarray, config: FitConfig = FitConfig(), deadband: float | None = None
) -> ParametricModel:
    """An unfitted model of ``kind`` set up from ``config`` (``deadband``: the ``v'``
    dead band in input units, default :func:`deadband_for`; ``[fit] n_operators``
    thresholds unless the kind has its own number, as the PI / Maxwell-slip kind)."""
    db = deadband_for(v, config) if deadband is None else float(deadband)
    info = kind_info(kind)
    m = model_for_kind(kind, n=info.n_operators or config.n_operators, deadband_counts=db)
    fixed = set(info.fixed(config))
    if not config.fit_flag_point and "v_f" in m.names:
        fixed.add("v_f")
    return m.with_fixed(fixed=tuple(fixed), free=tuple(n for n in m.names if n not in fixed))


def model_from_params(
    kind: str,
    params: dict[str, float],
    n_operators: int | None = None,
    deadband_counts: float = DEFAULT_DEADBAND_COUNTS,
) -> ParametricModel:
    """A fitted model rebuilt from a fit.json record's ``params`` (and its
    ``n_operators`` / ``deadband_counts``; ``n_operators`` None: the kind's default):
    :func:`~i2ris_calib.hysteresis.registry.model_for_kind`."""
    return model_for_kind(kind, n=n_operators, deadband_counts=deadband_counts, **params)


def split_masks(v: np.ndarray, config: FitConfig = FitConfig()) -> tuple[np.ndarray, np.ndarray]:
    """(cycle index (n,), held-out mask (n,)) for ``v``: the one held-out rule
    (:func:`i2ris_calib.data.cycles.holdout_mask`, cycles with a 1 % dead band)."""
    cyc = cycle_index(v)
    return cyc, holdout_mask(cyc, config.holdout_fraction, v)


#: With ``n_starts = 0`` a fit gets START_ROWS // fitted samples starts, between
#: :data:`MIN_AUTO_STARTS` and :data:`MAX_AUTO_STARTS` (8 up to 5,000 fitted samples,
#: 2 from 20,000): screening a start costs about one model run per LM iteration, so
#: the search's time grows with starts x samples, and a long recording's cost surface
#: is the better determined one.
START_ROWS = 40_000
MIN_AUTO_STARTS = 2
MAX_AUTO_STARTS = 8


#: A coupled fit of at most this many fitted samples also gets the joint starts of
#: :func:`~i2ris_calib.hysteresis.coupled.coupled_starts` (both motors' parts from the
#: angle alone, not from the base fit without the other motor's input): a short
#: recording (a few loops at 5 Hz) leaves that base ill-determined, so when the
#: coupling is a large share of the angle it ends in a degenerate basin every start
#: made from it inherits (bench_optimum agpi_coupled:112, n = 362: 36,756 x the truth's
#: cost, 0.87 x with them). The limit is where a fit gets :data:`MAX_AUTO_STARTS` and
#: affords every start and its hops: above it each more start takes a polish or a hop
#: from the others (agpi_coupled:108, 5,986 fitted samples: 1.0008 -> 1.44 x with
#: them) or, on a long recording, costs a screening over the whole input
#: (bench_speed's coupled fit: +330 evaluations, +3 s CPU per start).
JOINT_ROWS = START_ROWS // MAX_AUTO_STARTS


def search_starts(n_config: int, n_fitted: int) -> int:
    """Number of data-driven starts of a fit: ``n_config`` when set (> 0), else by the
    number of fitted samples ``n_fitted`` (:data:`START_ROWS`). The one rule, read by
    the CLI's fit and by :func:`fit`."""
    if n_config > 0:
        return int(n_config)
    return int(np.clip(START_ROWS // max(n_fitted, 1), MIN_AUTO_STARTS, MAX_AUTO_STARTS))


def fit_kind(
    kind: str,
    signals: Signals | np.ndarray,
    theta_deg: np.ndarray,
    config: FitConfig = FitConfig(),
    holdout: np.ndarray | None = None,
    gpi_fit: FitResult | None = None,
    *,
    deadband: float | None = None,
    related: tuple[FitResult, ...] = (),
    given: tuple[dict[str, float], ...] = (),
) -> FitResult:
    """Fit one model kind with data-driven, seeded multi-start (docs/fit.md).

    EGPI nests GPI (``a5 = a3, a6 = a4, kappa = 1``, any ``v_f``: same output), so
    one EGPI start is the GPI fit mapped into EGPI (:func:`nested_gpi_start`); the
    EGPI result is never worse than it (fit_model keeps the best start as a floor).
    The same holds for the continuous EGPI, which also starts from the EGPI fit
    (``related``).

    Parameters
    ----------
    kind : {"gpi", "egpi", "egpi_c"}
    signals : Signals or ndarray, shape (n,)
        Input of the whole recording in time order (a direction dataset's input).
    theta_deg : ndarray, shape (n,)
        Measured angle (deg); NaN leaves the loss (not measured, or another
        direction's sample) while the model still runs over the sample.
    holdout : ndarray of bool, shape (n,), optional
        Held-out samples; default from :func:`split_masks`.
    gpi_fit : FitResult, optional
        GPI fit on the same samples and holdout (EGPI kinds only); fitted here
        when not given.
    deadband : float, optional
        ``v'`` dead band (input unit); default :func:`deadband_for`.
    related : tuple of FitResult
        Fits of models with the same parameter names, tried as further starts.
    given : tuple of dict
        Further starts, ``{parameter: value}`` in the input's own unit (missing names:
        the default start): a lower cost of this kind that a later stage found on the
        same data (``diagnose``'s refit of its base), the fit rerun from it.
    """
    s = signals if isinstance(signals, Signals) else Signals(v=np.asarray(signals, dtype=float))
    v = np.asarray(s.v, dtype=float)
    theta = np.asarray(theta_deg, dtype=float)
    if holdout is None:
        holdout = split_masks(v, config)[1]
    db = deadband_for(v, config) if deadband is None else float(deadband)
    scale = input_scale(v)
    if scale != 1.0:
        v_other = None if s.v_other is None else np.asarray(s.v_other, float) / scale
        s_in = replace(s, v=v / scale, v_other=v_other)
        res = fit_kind(
            kind, s_in, theta, config, holdout,
            None if gpi_fit is None else _scaled_fit(gpi_fit, 1.0 / scale, signals=s_in),
            deadband=db / scale,
            related=tuple(_scaled_fit(r, 1.0 / scale, signals=s_in) for r in related),
            given=tuple(_scaled_params(g, unfitted_model(kind, v, config, db), 1.0 / scale)
                        for g in given),
        )  # fmt: skip
        return _scaled_fit(res, scale, unfitted_model(kind, v, config, db), signals=s)
    model = unfitted_model(kind, v, config, db)
    info = kind_info(kind)
    rng = np.random.default_rng(config.seed)
    fit_sel = np.isfinite(theta) & ~holdout
    n_starts = search_starts(getattr(config, info.n_starts), int(fit_sel.sum()))
    theta_fit = np.where(fit_sel, theta, np.nan)
    if info.coupled:
        if s.v_other is None:
            raise CalibError(
                f"model {kind} needs the other motor's input (enc_other / the other enc_ column)"
            )
        if gpi_fit is None:
            gpi_fit = fit_kind(info.nested, s, theta, config, holdout, deadband=db)
        model, starts = info.start(
            model, s, theta_fit, gpi_fit.params, n_starts, rng, db,
            joint=int(fit_sel.sum()) <= JOINT_ROWS,
        )  # fmt: skip
        if gpi_fit.initial_state is not None and v.size <= LARGE_ROWS:
            # also from the base's residual without its start-state effect (the silent
            # start, first, is the same); a long recording's start state weighs little
            # against its many loops (and its searches keep their time: bench_speed)
            theta_rest = rested_angle(theta_fit, gpi_fit, s)
            starts += info.start(
                model, s, theta_rest, gpi_fit.params, n_starts, rng, db, joint=False
            )[1][1:]
        starts += [model.vector(g) for g in given]
        starts = [keep_fixed(model, x) for x in starts]
        res = _fit_configured(model, s, theta, holdout, starts, config)
        if JOINT_ROWS < int(fit_sel.sum()) <= SECOND_JOINT_ROWS:
            res = _joint_search(res, info.start, model, s, theta, theta_fit, holdout,
                                gpi_fit, n_starts, config, db, given)  # fmt: skip
        return res
    starts = info.start(model, v, theta_fit, n_starts, rng, db) if fit_sel.sum() > 2 else None
    if starts is not None and info.nested is not None:
        if gpi_fit is None:
            gpi_fit = fit_kind(info.nested, s, theta, config, holdout, deadband=db)
        starts.append(nested_gpi_start(model, gpi_fit.params, starts[0]))
        for other in related:
            if set(other.params) == set(model.names):
                starts.append(model.vector(other.params))
    if given:
        starts = [*(starts or [model.vector({})]), *(model.vector(g) for g in given)]
    if starts is not None:
        starts = [keep_fixed(model, x) for x in starts]
    return _fit_configured(model, s, theta, holdout, starts, config, kind)


def rested_angle(theta: np.ndarray, base: FitResult, signals: Signals) -> np.ndarray:
    """The angle ``theta`` less the start-state effect of the fit ``base`` (its output
    after its fitted pre-history minus its output from rest): the angle as it would read
    had the recording started at rest, by that fit; ``theta`` itself when ``base`` has
    no fitted start state.

    The coupled model's starts are made from its base's residual, and their recipes run
    the models from rest: on a recording that starts mid-loop the base's residual from
    rest holds its start-state error, which the coupling's starts then fit. Starts from
    this angle are added to those (measured on bench_optimum's circles_mid cases, each
    in a fresh process: agpi_coupled:31 1.017 -> 0.994 x the truth's cost; in place of
    those starts, agpi_coupled:23 and 33 failed: 1.005, 1.14).
    """
    if base.initial_state is None:
        return theta
    shift = base.predict(signals, initial_state=True) - base.predict(signals, initial_state=False)
    return theta - shift


#: Up to this many fitted samples, a coupled fit beyond :data:`JOINT_ROWS` also runs a
#: second search of its own from the joint starts and keeps the lower end
#: (:func:`_joint_search`).
SECOND_JOINT_ROWS = 2 * JOINT_ROWS


def _joint_search(
    res, start, model, s, theta, theta_fit, holdout, gpi_fit, n_starts, config, db, given
):  # fmt: skip
    """``res`` or, when lower by more than the certificate's tolerance, the fit from the
    joint coupled starts (``start``: the kind's start recipe,
    :func:`~i2ris_calib.hysteresis.coupled.coupled_starts`, with ``joint=True``)
    searched with a budget of its own.

    Among the first search's starts they would take the polishes and hops the others
    need (agpi_coupled:108 of bench_optimum, 5,986 fitted samples: 1.0008 -> 1.437x the
    truth's cost), yet without them a recording whose coupling is a large share of the
    angle can end in the degenerate basin every base-made start inherits
    (agpi_coupled:121, 5,750 fitted samples: 2216x; from them 0.9965x).
    """
    rng = np.random.default_rng(config.seed)
    _, starts = start(model, s, theta_fit, gpi_fit.params, n_starts, rng, db, joint=True)
    starts = [keep_fixed(model, x) for x in [*starts, *(model.vector(g) for g in given)]]
    other = _fit_configured(model, s, theta, holdout, starts, config)
    return other if lower_optimum(res.certificate.best_cost, other.certificate.best_cost) else res


def _fit_configured(
    model, signals, theta, holdout, starts, config: FitConfig, kind: str | None = None
) -> FitResult:
    """:func:`fit_model` with the method, limits and loss of ``config`` (the method of
    ``kind`` when its registry row names one: bounded parameters)."""
    method = (kind_info(kind).method if kind is not None else None) or config.method
    return fit_model(
        model,
        signals,
        theta,
        holdout_mask=holdout,
        starts=starts,
        method=method,
        max_nfev=config.max_nfev,
        loss=config.loss,
        f_scale_deg=config.f_scale_deg,
        basin_hops=config.max_restarts,
    )


def input_scale(v: np.ndarray) -> float:
    """Factor the fit divides the input by: 1 for inputs up to 1e2-1e6 in magnitude
    (encoder counts), else the power of ten that brings max |v| to about 1e4.

    Parameter bounds and start recipes are set for such inputs; a fit in volts (max
    150) or in units of 1e-12 would otherwise meet slope bounds of 1 deg per unit or
    lose precision. The fitted parameters are returned in the input's own unit.
    """
    peak = float(np.max(np.abs(v))) if np.size(v) else 0.0
    if peak == 0.0 or not np.isfinite(peak) or 1e2 <= peak <= 1e6:
        return 1.0
    return float(10.0 ** np.round(np.log10(peak / 1e4)))


def _scaled_params(params: dict[str, float], model, scale: float) -> dict[str, float]:
    """``params`` for the input ``v * scale`` (as :func:`_scaled_fit` converts a fit)."""
    unit = {p.name: p.unit for p in model.parameters}
    factor = {"deg/count": 1.0 / scale, "1/count": 1.0 / scale, "count": scale}
    return {k: float(x * factor.get(unit.get(k, ""), 1.0)) for k, x in params.items()}


def _scaled_fit(
    res: FitResult,
    scale: float,
    model: ParametricModel | None = None,
    signals: Signals | None = None,
) -> FitResult:
    """``res`` with its parameters expressed for the input ``v * scale`` (slopes, in
    deg per input unit, divided by ``scale``; inputs such as the flag point multiplied
    by it), its start state's levels too
    (:meth:`~i2ris_calib.fitting.prehistory.InitialState.scaled`); ``model``: the model
    to carry the converted values (default: ``res.model``);
    ``signals``: the input ``v * scale``, whose first values the start state takes as
    its ``v0`` and ``v0_other`` exactly (default: the products)."""
    names = tuple(res.params)
    unit = {p.name: p.unit for p in res.model.parameters}
    factor = {"deg/count": 1.0 / scale, "1/count": 1.0 / scale, "count": scale}
    d = np.array([factor.get(unit.get(k, ""), 1.0) for k in names])
    params = {k: float(x * f) for (k, x), f in zip(res.params.items(), d, strict=True)}
    stderr = {k: float(res.stderr[k] * f) for k, f in zip(names, d, strict=True)}
    cov = (
        res.covariance * d[:, None] * d[None, :]
        if res.covariance.shape == (d.size, d.size)
        else res.covariance
    )
    base = res.model if model is None else model
    start = {k: float(x * factor.get(unit.get(k, ""), 1.0)) for k, x in res.start.items()}
    state = res.initial_state
    if state is not None:
        v0 = v0_other = None
        if signals is not None:
            v0 = float(np.asarray(signals.v, dtype=float)[0])
            if signals.v_other is not None and state.v0_other is not None:
                v0_other = float(np.asarray(signals.v_other, dtype=float)[0])
        state = state.scaled(scale, v0, v0_other)
    return replace(
        res, params=params, stderr=stderr, covariance=cov, model=base.with_values(params),
        start=start, initial_state=state,
    )  # fmt: skip


def fit_dataset(
    kind: str,
    data: Dataset,
    config: FitConfig = FitConfig(),
    earlier: dict[str, FitResult] | None = None,
    given: tuple[dict[str, float], ...] = (),
) -> FitResult:
    """Fit one model kind to a direction dataset (whole history, its loss mask and
    held-out cycles). ``earlier``: fits of other kinds on the same dataset, used as
    starts (GPI nested in EGPI, EGPI for the continuous EGPI); ``given``: further
    starts (:func:`fit_kind`)."""
    earlier = earlier or {}
    db = data.bands.deadband if config.deadband_counts < 0 else float(config.deadband_counts)
    nested = kind_info(kind).nested
    related = tuple(r for k, r in earlier.items() if k not in (nested, kind))
    return fit_kind(
        kind, data.signals, data.theta_deg, config, data.holdout,
        None if nested is None else earlier.get(nested), deadband=db, related=related,
        given=tuple(given),
    )  # fmt: skip


def dataset_cost(model, data: Dataset, config: FitConfig, initial_state=None) -> float:
    """The cost :func:`fit_dataset` minimises (``config``'s loss over the dataset's
    fitted samples, :func:`~i2ris_calib.fitting.fit.fit_cost`) at ``model``'s values,
    run after ``initial_state`` (a fit's; None: from rest)."""
    return fit_cost(
        model, data.signals, data.theta_deg, holdout_mask=data.holdout,
        initial_state=initial_state, loss=config.loss, f_scale_deg=config.f_scale_deg,
    )  # fmt: skip


def nested_gpi_start(
    model: ParametricModel, gpi_params: dict[str, float], start: np.ndarray
) -> np.ndarray:
    """EGPI start vector, shape (p,), giving exactly the GPI output of ``gpi_params``:
    ``a5 = a3``, ``a6 = a4``, ``kappa = 1`` (both families equal, so the flag point
    ``v_f``, taken from ``start``, does not matter)."""
    vals = dict(zip(model.names, np.asarray(start, dtype=float), strict=True))
    vals |= {k: float(x) for k, x in gpi_params.items() if k in vals}
    vals |= {"a5": vals["a3"], "a6": vals["a4"], "kappa": 1.0}
    return model.vector(vals)


def fit_all(
    signals: Signals | np.ndarray,
    theta_deg: np.ndarray,
    config: FitConfig = FitConfig(),
    kinds: tuple[str, ...] = MODEL_KINDS,
) -> dict[str, FitResult]:
    """``{kind: FitResult}`` on one input/angle pair with one shared held-out split."""
    v = np.asarray(signals.v if isinstance(signals, Signals) else signals, dtype=float)
    holdout = split_masks(v, config)[1]
    out: dict[str, FitResult] = {}
    for k in kinds:
        nested = kind_info(k).nested
        related = tuple(r for kk, r in out.items() if kk != nested)
        out[k] = fit_kind(
            k, signals, theta_deg, config, holdout,
            gpi_fit=None if nested is None else out.get(nested), related=related,
        )  # fmt: skip
    return out


def fit_dataset_all(
    data: Dataset, config: FitConfig = FitConfig(), kinds: tuple[str, ...] = MODEL_KINDS
) -> dict[str, FitResult]:
    """``{kind: FitResult}`` for every kind on one direction dataset (GPI first: the
    EGPI kinds start from it)."""
    out: dict[str, FitResult] = {}
    for k in fit_order(kinds):
        out[k] = fit_dataset(k, data, config, out)
    return {k: out[k] for k in kinds}


#: Below this explained variance on the fitted samples a fit is flagged (a good
#: hysteresis fit explains > 99 % of the angle's variance).
MIN_EXPLAINED_VARIANCE = 0.9


def fit_warnings(res: FitResult, v: np.ndarray) -> tuple[str, ...]:
    """Plain-language warnings about a fit that looks wrong though it "converged".

    * the model explains < ``MIN_EXPLAINED_VARIANCE`` of the angle's variance (an angle
      that does not follow this input: wrong column, axes swapped, lost tracking);
    * the loading slope ``a1`` is ~0 (the angle does not grow with the input);
    * the fit did not converge.
    """
    out = []
    ev = res.metrics.explained_variance
    if np.isfinite(ev) and ev < MIN_EXPLAINED_VARIANCE:
        share = 100 * max(ev, 0.0)
        than = (
            "a constant does almost as well"
            if share < 50
            else f"a hysteresis model of the right input explains {100 * MIN_EXPLAINED_VARIANCE:.0f} % or more"
        )
        out.append(
            f"the model explains only {share:.0f} % of the angle's variance ({than}): "
            "the angle may not follow this input (check the axis, the columns and the tracking)"
        )
    a1 = res.params.get("a1")
    span_v = float(np.ptp(v)) if np.size(v) else 0.0
    if a1 is not None and span_v > 0:
        # deg over the whole input range: a slope that moves the angle < 0.01 deg
        if abs(a1) * span_v < 0.01:
            out.append(
                f"loading slope a1 = {a1:.3g} deg per input unit: the angle does not grow "
                "with the input"
            )
    out += fit_notices(res)  # a fitted initial state, standard errors missing and why
    if not res.converged:
        out.append("not converged: " + res.message)
    return tuple(out)


def checked_fit_config(func: str, config: object, name: str = "config") -> FitConfig:
    """``config`` if it is a :class:`FitConfig`, the defaults for None, else CalibError
    (a str, a DataFrame, the class not called, a whole PipelineConfig: its ``.fit``)."""
    if config is None:
        return FitConfig()
    return check_instance(
        func, name, config, FitConfig,
        hint="e.g. FitConfig(method='trf'); from a TOML file: load_config(path).fit",
    )  # fmt: skip


def _fit_inputs(model, data, config, holdout):
    """(signals, theta, held-out mask, dead band, v, config) of :func:`fit`'s arguments,
    checked; CalibError naming the argument on a misuse."""
    func = "fit"
    check_model(func, "model", model, usage="fit(model, data)")
    config = checked_fit_config(func, config)
    if isinstance(data, Dataset):
        checked_dataset(func, "data", data)
        if holdout is not None:
            raise CalibError(
                "fit: holdout is for (v, theta_deg) data; a Dataset carries its held-out "
                "cycles: fit(model, dataclasses.replace(data, holdout=mask))"
            )
        v = np.asarray(data.signals.v, dtype=float)
        db = data.bands.deadband if config.deadband_counts < 0 else float(config.deadband_counts)
        return data.signals, data.theta_deg, data.holdout, db, v, config
    if not isinstance(data, tuple):
        checked_dataset(func, "data", data)  # raises: says what data is and what to give
    if len(data) != 2:
        raise CalibError(
            f"fit: data is {describe(data)}; give a Dataset or a pair (v, theta_deg) "
            "(times and the other axis go in a Dataset: make_dataset(...))"
        )
    v = as_1d_float(func, "data[0] (the input v)", data[0], min_size=2)
    theta = as_1d_float(
        func, "data[1] (theta_deg)", data[1], nan_ok=True,
        hint="mark an unmeasured angle with NaN, never inf",
    )  # fmt: skip
    same_length(func, **{"data[0] (the input v)": v, "data[1] (theta_deg)": theta})
    hold = (
        split_masks(v, config)[1]
        if holdout is None
        else as_1d_bool(func, "holdout", holdout, v.size)
    )
    return Signals(v=v), theta, hold, deadband_for(v, config), v, config


def _signature(model) -> tuple:
    """What makes two models of one kind fit alike: class, thresholds, parameter names,
    fixed flags and bounds (not values)."""
    params = tuple(
        (p.name, bool(p.fixed), float(p.lower), float(p.upper)) for p in model.parameters
    )
    return (type(model), getattr(model, "n", None), params)


def _is_kind_model(model, info, v: np.ndarray, config: FitConfig, db: float) -> bool:
    """True when ``model`` is its registry kind's model as the registry builds it (the
    factory's, or the fit's own fixed flags and bounds): :func:`fit` then fits it by the
    kind's path (:func:`fit_kind`), as the command line does."""
    if info.factory is None or type(model) is not info.model_class:
        return False
    n = getattr(model, "n", None)
    if info.n_operators is None and isinstance(n, int):
        config = replace(config, n_operators=n)
    mine = _signature(model)
    return mine in (
        _signature(model_for_kind(info.kind, n=n if isinstance(n, int) else None)),
        _signature(unfitted_model(info.kind, v, config, db)),
    )


def fit(
    model: ParametricModel,
    data: Dataset | tuple[np.ndarray, np.ndarray],
    config: FitConfig | None = None,
    *,
    holdout: np.ndarray | None = None,
) -> FitResult:
    """Fit ``model`` to ``data``: the call a notebook user writes.

    Parameters
    ----------
    model : ParametricModel
        Any model (``gpi_model()``, ``i2ris_egpi_model()``, ``continuous_egpi_model()``,
        a model extended by diagnosed effects); its fixed flags and bounds are kept.
    data : Dataset or (v, theta_deg)
        A direction dataset (whole history, loss mask, held-out cycles; see
        :func:`i2ris_calib.data.make_dataset` / :func:`i2ris_calib.io.synced.load_datasets`),
        or an input array and an angle array of shape (n,) (NaN angles leave the loss).
    config : FitConfig or None
        Method, starts, seed, robust loss (None: the defaults).
    holdout : ndarray of bool, shape (n,), optional
        Held-out samples for (v, theta) data; default: whole loading cycles
        (:func:`split_masks`). A Dataset carries its own (``data.holdout``).

    Returns
    -------
    FitResult
        A new result; ``model`` is not changed. A registry kind's model as the registry
        builds it (``model_for_kind(kind)``, ``gpi_model()``, ``i2ris_egpi_model()``,
        ``continuous_egpi_model()``, ...: its own fixed flags and bounds, any values)
        is fitted by the kind's own path, exactly as ``i2ris-calib fit --model KIND``
        on the same dataset: the kind's data-driven starts, method and input scaling,
        the dataset's ``v'`` dead band (``[fit] deadband_counts`` overrides it), its
        nested kind first (EGPI from the GPI fit); its values are not a start (give
        starts to :func:`~i2ris_calib.fitting.fit.fit_model`). Any other model (fixed
        flags or bounds of your own, a general EGPI, effects added): the model's own
        values and the data-driven starts of its base (:meth:`guess`).

    Raises
    ------
    CalibError
        On a misuse, naming the argument (checked before any work): ``model`` not a
        model (a factory not called: ``i2ris_egpi_model`` for ``i2ris_egpi_model()``),
        ``data`` neither a Dataset nor a pair of 1-D arrays of one length, NaN or inf in
        the input, inf in the angle, ``config`` not a FitConfig, ``holdout`` not a bool
        mask of the data's length.
    """
    signals, theta, hold, db, v, config = _fit_inputs(model, data, config, holdout)
    info = kind_of(model)
    if info is not None and _is_kind_model(model, info, v, config, db):
        # the kind's own path, exactly as ``i2ris-calib fit --model KIND`` (one fitting
        # path: its starts, method, input scaling, the other motor's start for coupling)
        n = getattr(model, "n", None)
        if info.n_operators is None and isinstance(n, int) and n != config.n_operators:
            config = replace(config, n_operators=n)
        return fit_kind(info.kind, signals, theta, config, hold, deadband=db)
    if info is not None and info.coupled:
        raise CalibError(
            f"fit: a {info.kind} model with its own fixed flags or bounds has no generic "
            "start recipe; fit the kind's model as the registry builds it "
            f"(model_for_kind('{info.kind}')), or give starts: fit_model(model, signals, "
            "theta, starts=[...])"
        )
    starts = [model.values]
    theta_fit = np.where(np.isfinite(theta) & ~hold, theta, np.nan)
    base = innermost(model)  # an extended model: the data-driven starts of its base
    recipe = start_recipe(base)
    if recipe is not None and np.isfinite(theta_fit).sum() > 2:
        rng = np.random.default_rng(config.seed)
        tail = model.values[len(base.parameters) :]
        n_starts = search_starts(config.n_starts, int(np.isfinite(theta_fit).sum()))
        starts += [np.append(x, tail) for x in recipe(base, v, theta_fit, n_starts, rng, db)]
        starts = [keep_fixed(model, x) for x in starts]
    return _fit_configured(model, signals, theta, hold, starts, config)
