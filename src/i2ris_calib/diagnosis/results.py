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
from i2ris_calib.hysteresis.effects import CATALOGUE, effects_of
from i2ris_calib.model import Model


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


#: Recordings that separate two effects the held-out cycles could not tell apart: each
#: effect's ``separating`` (:class:`~i2ris_calib.hysteresis.effects.Effect`), by pair.
SEPARATING_EXPERIMENTS: dict[frozenset, str] = {
    frozenset({name, other}): text
    for name, e in CATALOGUE.items()
    for other, text in e.separating.items()
}


def separating_experiment(a: str, b: str) -> str:
    """A recording that separates effects ``a`` and ``b`` ("" if none is known)."""
    return SEPARATING_EXPERIMENTS.get(frozenset({a, b}), "")


#: What would show an effect the start model absorbs (the ``not_excluded`` entries):
#: each effect's ``separating_from_base``.
SEPARATING_FROM_BASE: dict[str, str] = {
    name: e.separating_from_base for name, e in CATALOGUE.items() if e.separating_from_base
}


@dataclass(frozen=True)
class BaseRefit:
    """The starting model (no effect) refitted by the diagnosis: another end of the
    same model on the same data, which ``diagnose`` compares with the stored fit by
    the fit's own cost (a lower one replaces it: docs/diagnosis.md).

    Attributes
    ----------
    model : Model
        The starting model's kind with the refitted values.
    how : str
        Where the diagnosis refitted it: ``"refit of its starting fit"`` (the start
        polished on the search data) or ``"refit from creep_log's values"`` (the base
        refitted from a finalist's base values, :func:`_null_reference` of the workflow).
    """

    model: Model
    how: str


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
    base_refits : tuple of BaseRefit
        The starting model refitted on the search data (its polish, and the base
        refitted from the best finalist's values before the first effect is named):
        ends of the starting model that a stored fit of it may not have reached.
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
    base_refits: tuple[BaseRefit, ...] = ()

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
