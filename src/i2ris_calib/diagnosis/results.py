"""Result types of the diagnosis: scores, held-out comparisons, candidates, steps,
alternatives and the diagnosis itself, plus the recordings that separate two
effects the held-out cycles could not tell apart.

All are frozen dataclasses without behaviour beyond JSON-ready views; the search
that fills them is :mod:`i2ris_calib.diagnosis.workflow`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

import i2ris_calib._display as _display
from i2ris_calib.diagnosis.effects import effects_of
from i2ris_calib.hysteresis.model import Model


@dataclass(frozen=True)
class ModelScore:
    """Fit quality of one model on the search data: fitted and held-out RMSE, BIC.

    Not the paper's Eq25-27 set (:class:`i2ris_calib.fitting.metrics.Metrics`): the
    diagnosis compares models by held-out RMSE and BIC on the same samples.

    Attributes
    ----------
    fit_rmse_deg, holdout_rmse_deg : float
        RMSE (deg, Eq25) on the fitted and on the held-out samples.
    bic : float
        ``n ln(SSE/n) + k ln n`` on the fitted samples of the search signal
        (:func:`i2ris_calib.fitting.metrics.information_criteria`).
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
    metrics: ModelScore | None
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
    before: ModelScore
    after: ModelScore
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
    effect_rms_deg : float
        RMS (deg, counted samples) of what its fitted effect moves the angle: its
        model with the effect set neutral vs with it (nan where not computed).
    """

    effect: str
    holdout_rmse_deg: float
    z: float
    p_value: float
    excluded: bool
    params: dict
    experiment: str = ""
    effect_rms_deg: float = float("nan")

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


#: What would show an effect the start model absorbs (the ``not_excluded`` entries).
SEPARATING_FROM_BASE: dict[str, str] = {
    "backlash": (
        "no input-angle recording while the model's operator bands are not inverted: a "
        "play of half-width h on the input of a GPI/EGPI with linear envelopes is again "
        "one, its envelope offsets moved by slope x h (a2 - a1 h, a4 + a3 h, a6 + a5 h); "
        "measure the slack itself (motor travel after a reversal before the tendon "
        "tension changes)"
    ),
    "multi_stage_backlash": SEPARATING_EXPERIMENTS[
        frozenset({"dead_zone", "multi_stage_backlash"})
    ],
    "dead_zone": (
        "returns to zero input and small moves near zero: a dead zone holds the angle "
        "only below its break point"
    ),
    "time_delay": (
        "a fast ramp that stops without a hold-in: a delay keeps the angle moving for "
        "its delay after the input stops"
    ),
    "creep": _LONG_HOLDS,
    "creep_log": _LONG_HOLDS,
    "rate_dependent_thresholds": (
        "ramps at three speeds to the same level with holds: the loop widens with speed"
    ),
    "rate_dependent_weights": (
        "ramps at three speeds to the same level with holds: the loop's slope changes with speed"
    ),
    "saturation": "slow ramps to the largest safe input: saturation flattens the top",
    "axis_coupling": "move the other axis alone while this one holds its input",
}


@dataclass(frozen=True)
class Diagnosis:
    """Result of :func:`diagnose`.

    Attributes
    ----------
    start_model, final_model : Model
        Polished starting model and the final extended model (fitted values).
    baseline, final : ModelScore
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
    notes : tuple of str
    not_excluded : tuple of Alternative
        Candidates of the last round (nothing more named) that fit the held-out
        cycles as well as the final model although their fitted effect moves the
        angle by more than the noise: the data cannot tell them from the final
        model (e.g. a backlash that the base's envelope offsets absorb). ``z`` is
        the final model's held-out z over the candidate.
    """

    start_model: Model
    final_model: Model
    baseline: ModelScore
    final: ModelScore
    steps: tuple[Step, ...]
    last_candidates: tuple[Candidate, ...]
    analysis_final: dict
    sentences_final: tuple[str, ...]
    holdout: np.ndarray
    decimation: int
    notes: tuple[str, ...] = field(default_factory=tuple)
    not_excluded: tuple[Alternative, ...] = ()

    @property
    def named_effects(self) -> list[str]:
        """Effect names in the order they were added (empty if nothing is missing)."""
        return [s.effect for s in self.steps]

    def __repr__(self) -> str:
        named = ", ".join(self.named_effects) or "nothing"
        b, f = self.baseline.holdout_rmse_deg, self.final.holdout_rmse_deg
        text = (
            f"<Diagnosis {self.start_model.name}: named {named}; held-out RMSE "
            f"{_display.num(b)} -> {_display.num(f)} deg"
            + (f"; {len(self.not_excluded)} not excluded" if self.not_excluded else "")
            + ">"
        )
        return _display.clip(text)

    def _repr_html_(self) -> str:
        """Notebook display: each added effect with the held-out RMSE before and after
        and its evidence, then what the data cannot exclude."""
        rows = [
            (s.effect, s.before.holdout_rmse_deg, s.after.holdout_rmse_deg,
             s.comparison.z, s.comparison.p_value, s.comparison.delta_bic)
            for s in self.steps
        ]  # fmt: skip
        title = (
            f"<b>Diagnosis</b> from {_display.esc(self.start_model.name)}: final model "
            f"{_display.esc(self.final_model.name)}, held-out RMSE "
            f"{_display.num(self.baseline.holdout_rmse_deg)} -> "
            f"{_display.num(self.final.holdout_rmse_deg)} deg"
        )
        header = ("effect", "held-out RMSE before", "after", "z", "p", "delta BIC")
        out = _display.table(header, rows, title) if rows else f"<p>{title}; no effect named</p>"
        if self.not_excluded:
            names = ", ".join(a.effect for a in self.not_excluded)
            out += f"<p>not excluded by the held-out cycles: {_display.esc(names)}</p>"
        return out


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
    other_excluded : bool
        The answer's final model is significantly better on the held-out cycles
        than the other path's (p < ``alpha``).
    """

    start: str
    diagnosis: Diagnosis
    paths: dict
    agree: bool
    z: float
    sentence: str
    other_excluded: bool = False

    def __repr__(self) -> str:
        d = self.diagnosis
        named = ", ".join(d.named_effects) or "nothing"
        text = (
            f"<AutoDiagnosis: start {self.start}, named {named}; held-out RMSE "
            f"{_display.num(d.final.holdout_rmse_deg)} deg; paths {', '.join(self.paths)} "
            f"{'agree' if self.agree else 'disagree'}>"
        )
        return _display.clip(text)

    def _repr_html_(self) -> str:
        """Notebook display: the reconciling sentence and the answer's diagnosis."""
        return f"<p>{_display.esc(self.sentence)}</p>" + self.diagnosis._repr_html_()

    @property
    def not_excluded(self) -> tuple[tuple[str, Alternative], ...]:
        """(start, alternative) of what the answer cannot rule out, over every path.

        The answer's own ``not_excluded`` first, then, unless the held-out cycles
        exclude the other path's final model (``other_excluded``: its entries were
        judged against a model the answer beats), its entries for effects neither
        listed yet nor named in the answer. An effect the base absorbs (a backlash
        on a GPI/EGPI input) has an undetermined size along the absorbed direction,
        so whether one path's fit makes it material (listed) depends on that path's
        start fit; the union over the paths does not.
        """
        out = [(self.start, a) for a in self.diagnosis.not_excluded]
        seen = {a.effect for _, a in out} | set(self.diagnosis.named_effects)
        for kind, d in self.paths.items():
            if kind == self.start or self.other_excluded:
                continue
            for a in d.not_excluded:
                if a.effect not in seen:
                    out.append((kind, a))
                    seen.add(a.effect)
        return tuple(out)
