"""Which model compensates an axis: every candidate model inverted on the target (coupled
ones jointly with the other axis), ranked by its predicted tracking error, and the one
chosen: ``--model``, else the fit's decision (:func:`~.plan.decided_kind`; when that one
cannot be inverted here, the next of its ranking, and ``substitute`` says which and why).

Takes :class:`~.plan.AxisPlan` and fitted models, returns :class:`AxisChoice` (no files,
no printing); docs/compensate.md ("Which model").
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from i2ris_calib.compensation.inverse import CompensationResult, compensate
from i2ris_calib.compensation.plan import COUPLED_KINDS, AxisPlan, decided_kind
from i2ris_calib.errors import CalibError
from i2ris_calib.hysteresis.effects import model_values
from i2ris_calib.hysteresis.kinds import DIAGNOSED
from i2ris_calib.hysteresis.registry import INVERSE_KINDS
from i2ris_calib.interrupts import deferred
from i2ris_calib.model import Signals

#: Smallest output jump (deg) at a switch of the shown operator family that counts as an
#: output step: ``max(STEP_MIN_DEG, 10 tol_deg)`` (as the spike repair's output test)
STEP_MIN_DEG = 0.05
#: Share of the target's samples with an output step (or a removed spike) above which a
#: model counts as stepping where the target passes (ranked down: :data:`STEP_PENALTY`)
STEP_SHARE = 0.005
#: Factor on a stepping model's score in the ranking: it ranks after a continuous model
#: unless its predicted tracking error is below 1/STEP_PENALTY of that model's (an
#: uncoupled model 14x worse held out must not beat the coupled one for a few steps)
STEP_PENALTY = 2.0
#: Gauss-Seidel rounds of the joint two-motor solve (each coupled axis re-inverted with
#: the other axis's latest commands)
JOINT_ROUNDS = 3


@dataclass(frozen=True)
class AxisChoice:
    """The model chosen for one axis and its inversion.

    Attributes
    ----------
    kind : str
        The model kind chosen.
    model : object
        The fitted model.
    result : CompensationResult
        Its inversion of the axis's goal.
    ranking : list of dict
        Every candidate ranked (:func:`rank_models`), the chosen one marked ``chosen``.
    recommended : str or None
        The model the fit's decision recommends.
    substitute : str or None
        Why another model than the recommended one is used (None: it is not).
    forced : bool
        The kind was forced (``--model``).
    """

    kind: str
    model: object
    result: CompensationResult
    ranking: list[dict]
    recommended: str | None
    substitute: str | None
    forced: bool


def family_switch_steps(model, res: CompensationResult, v0: float) -> np.ndarray:
    """Samples (shape (n,), bool) where the commands sent make the paper EGPI's shown
    output change family (Eq20: ``y2`` while unloading at ``v <= v_f``, else ``y1``) with
    a jump of more than ``max(STEP_MIN_DEG, 10 tol_deg)`` that the predicted output
    shows against the target's change: an output step the kernel's
    status leaves as ``rate_limit`` (or ``reached``) when the rate-limited command crosses
    the switch. All False for models without such a switch."""
    n = res.commands.size
    fam = getattr(model, "flag_point_families", None)
    if fam is None or n == 0:
        return np.zeros(n, dtype=bool)
    pre = res.history_commands if res.history_commands.size else np.array([float(v0)])
    v = np.concatenate((pre, res.entry_commands, res.commands))
    vals = model_values(model)
    with deferred():
        y1, y2, unloading = fam(Signals(v=v), vals)
    v_f = float(model.named(vals)["v_f"])
    shown2 = unloading & (v <= v_f)
    switch = np.concatenate(([False], shown2[1:] != shown2[:-1]))
    thr = max(STEP_MIN_DEG, 10.0 * res.tol_deg)
    jump = (switch & (np.abs(y1 - y2) > thr))[-n:]
    # ... where the predicted output leaves the target's change by more than thr (the
    # inverse often jumps the input across the switch so that the output does not step)
    dy = np.diff(np.concatenate(([res.predicted_deg[0]], res.predicted_deg)))
    dt = np.diff(np.concatenate(([res.target_deg[0]], res.target_deg)))
    return jump & (np.abs(dy - dt) > thr)


def _score(pred_rmse: float, holdout: float | None) -> float:
    """Predicted tracking error that ranks a model: its error on the target (its own
    prediction) and its held-out fit error, combined in quadrature (deg)."""
    h = 0.0 if holdout is None or not np.isfinite(holdout) else float(holdout)
    return float(np.hypot(pred_rmse, h))


def rank_models(
    candidates: Mapping, holdout: Mapping, models: Mapping | None = None, v0: float = 0.0
) -> list[dict]:
    """Ranking of the models that can serve this target (best first), by the predicted
    tracking error (:func:`_score`: the model's own error on this target and its
    held-out fit error in quadrature), multiplied by :data:`STEP_PENALTY` for models
    whose output steps where the target passes (more than :data:`STEP_SHARE` of the
    samples flagged ``output_step`` or ``spike_removed``): ``rank_score_deg``.
    ``candidates``: kind -> CompensationResult; ``holdout``: kind -> held-out RMSE (deg)
    or None; ``models`` (kind -> model) and ``v0`` (start input): the paper EGPI's stage
    switches that step the predicted output (:func:`family_switch_steps`) count as
    output steps too."""
    rows = []
    for kind, res in candidates.items():
        s = res.summary()
        stepped = res.flags["output_step"] | res.flags["spike_removed"]
        if models is not None and kind in models:
            stepped = stepped | family_switch_steps(models[kind], res, v0)
        steps = int(stepped.sum())
        hold = holdout[kind]
        rows.append({
            "model": kind,
            "predicted_rmse_deg": s["rmse_deg"],
            "holdout_rmse_deg": hold,
            "score_deg": _score(s["rmse_deg"], hold),
            "output_steps": int(steps),
            "continuous": steps <= STEP_SHARE * s["n_samples"],
        })  # fmt: skip
    for r in rows:
        r["rank_score_deg"] = r["score_deg"] * (1.0 if r["continuous"] else STEP_PENALTY)
    rows.sort(key=lambda r: r["rank_score_deg"])
    for i, r in enumerate(rows):
        r["rank"] = i + 1
    return rows


def invert_axis(
    model, a: AxisPlan, v_other=None, v_other_initial=None, hist_other=None
) -> CompensationResult:
    """``a``'s goal inverted by ``model`` from rest at its start input, or (a history or
    conditioning sweep: model convention, its first input at rest) from the state they
    leave; a coupled model given the other motor's signed inputs (``v_other``, its start
    ``v_other_initial`` and its history ``hist_other``)."""
    hist = a.hist
    return compensate(
        model, a.goal, a.t, v_limits=(a.lo, a.hi), max_rate=a.max_rate, quantum=1.0,
        v_initial=a.v0 if hist is None else None, v_other=v_other,
        v_other_initial=v_other_initial, v_history=hist,
        v_other_history=None if hist is None or v_other is None else hist_other,
    )  # fmt: skip


def _other(plans: Mapping[str, AxisPlan], axis: str) -> AxisPlan | None:
    """The other axis's plan (or None)."""
    return next((p for x, p in plans.items() if x != axis), None)


def _other_hist(plans: Mapping[str, AxisPlan], axis: str):
    """The other axis's history in signed counts (or None)."""
    o = _other(plans, axis)
    if o is None or o.hist is None:
        return None
    return o.sign * o.hist


class _Axis:
    """One axis's candidates while they are inverted and ranked (private, mutable)."""

    def __init__(self, plan: AxisPlan, models: dict):
        self.plan = plan
        self.models = dict(models)
        self.candidates: dict[str, CompensationResult] = {}
        coupled = [k for k in self.models if k in COUPLED_KINDS]
        self.coupled = coupled[-1] if coupled else None

    def ranking(self) -> list[dict]:
        return rank_models(self.candidates, self.plan.fit.holdout, self.models, self.plan.v0)

    def refusal(self, kind: str) -> str | None:
        """Why compensate cannot invert ``kind`` for this axis (None: it can)."""
        if kind in self.candidates or (kind in COUPLED_KINDS and kind == self.coupled):
            return None
        if kind == DIAGNOSED:
            return "the diagnosed model needs its final_model.json (--model-file)"
        if kind not in INVERSE_KINDS:
            return f"{kind} has no inverse (compensate inverts {', '.join(INVERSE_KINDS)})"
        if kind in COUPLED_KINDS:
            return f"{kind} reads the other motor: give both axes' fit.json and target columns"
        return f"{kind} could not be inverted"


def choose_models(
    plans: Mapping[str, AxisPlan],
    models: Mapping[str, dict],
    model: str | None,
    where: str,
    alternatives: Mapping[str, dict] | None = None,
) -> dict[str, AxisChoice]:
    """Axis -> the model chosen and its inversion.

    Parameters
    ----------
    plans : mapping
        Axis -> its plan (start state included).
    models : mapping
        Axis -> kind -> fitted model to invert (:func:`~.plan.kinds_to_invert`); coupled
        kinds are solved jointly with the other axis.
    model : str or None
        The forced kind (``--model``), or None: the fit's decision.
    where : str
        The target file (for messages).
    alternatives : mapping, optional
        Axis -> kind -> fitted model of :func:`~.plan.alternative_kinds`: inverted and
        ranked when the forced model steps where the target passes.
    """
    axes = {axis: _Axis(p, models[axis]) for axis, p in plans.items()}
    for ax in axes.values():
        _add_candidates(ax, where)
    if any(ax.coupled for ax in axes.values()):
        _add_joint_candidates(axes, where)
    chosen = {}
    for axis, ax in axes.items():
        chosen[axis] = _choose_kind(ax, model, (alternatives or {}).get(axis, {}))
    _reinvert_coupled_choice(axes, chosen)
    out = {}
    for axis, ax in axes.items():
        kind, ranking, recommended, substitute = chosen[axis]
        out[axis] = AxisChoice(kind, ax.models[kind], ax.candidates[kind], ranking,
                               recommended, substitute, forced=model is not None)  # fmt: skip
    return out


def _add_candidates(ax: _Axis, where: str) -> None:
    """Invert the axis's uncoupled models (a coupled one is solved jointly later)."""
    for kind, fitted in ax.models.items():
        if kind in COUPLED_KINDS:
            continue
        try:
            ax.candidates[kind] = invert_axis(fitted, ax.plan)
        except CalibError as exc:
            raise CalibError(f"{where} [{ax.plan.name}] {kind}: {exc}") from None


def _add_joint_candidates(axes: dict[str, _Axis], where: str) -> None:
    """Add the coupled candidates, solved jointly (:func:`_solve_coupled`) from each
    axis's best uncoupled commands (or a hold at its entry counts)."""
    current = {}
    for axis, ax in axes.items():
        p = ax.plan
        best = ax.ranking()[0]["model"] if ax.candidates else None
        cmds = ax.candidates[best].commands if best else np.full(p.t.size, p.v_entry)
        current[axis] = (p.sign * cmds, p.sign * p.v_entry)
    try:
        joint = _solve_coupled(axes, current)
    except CalibError as exc:
        raise CalibError(f"{where} (coupled, both axes): {exc}") from None
    for axis, res in joint.items():
        axes[axis].candidates[axes[axis].coupled] = res


def _solve_coupled(axes: dict[str, _Axis], current: dict) -> dict:
    """Coupled candidates (axis -> CompensationResult) solved jointly: each coupled axis
    is inverted given the other motor's latest commands (``current``: axis -> (signed
    commands, signed start counts)), :data:`JOINT_ROUNDS` rounds, yaw first (its first
    round given the other axis's best uncoupled commands)."""
    plans = {axis: ax.plan for axis, ax in axes.items()}
    out = {}
    for _ in range(JOINT_ROUNDS):
        for axis, ax in axes.items():
            if ax.coupled is None:
                continue
            other = next(x for x in axes if x != axis)
            vo, vo0 = current[other]
            res = invert_axis(ax.models[ax.coupled], ax.plan, vo, vo0, _other_hist(plans, axis))
            out[axis] = res
            current[axis] = (ax.plan.sign * res.commands, ax.plan.sign * ax.plan.v_entry)
    return out


def _choose_kind(ax: _Axis, model: str | None, alternatives: dict) -> tuple:
    """(kind, ranking, recommended, substitute) of one axis: rank its candidates
    (:func:`rank_models`, information: the predicted tracking error on this target) and
    choose ``model``, else the model the fit's decision recommends (when that one cannot
    be inverted here, the next of the decision's ranking that can, and ``substitute``
    says which and why); each ranking row marked ``chosen``."""
    ranking = ax.ranking()
    if model is not None and not ranking[0]["continuous"] and model not in COUPLED_KINDS:
        _rank_alternatives(ax, alternatives)  # the forced model steps: name the others
        ranking = ax.ranking()
    fit = ax.plan.fit
    substitute = None
    if model is None:
        kind, note = decided_kind(fit.decision, ax.refusal, f"{fit.where} [{fit.name}]")
        substitute = note or None
    else:
        kind = model
    for r in ranking:
        r["chosen"] = r["model"] == kind
    return kind, ranking, fit.decision.model, substitute


def _rank_alternatives(ax: _Axis, alternatives: dict) -> None:
    """Add the dataset's other (uncoupled, fitted) invertible models to the axis's
    candidates when the forced one steps, so the warning can name those that do not; a
    model that cannot be inverted is left out."""
    for kind, fitted in alternatives.items():
        try:
            ax.candidates[kind] = invert_axis(fitted, ax.plan)
        except CalibError:
            continue
        ax.models[kind] = fitted


def _reinvert_coupled_choice(axes: dict[str, _Axis], chosen: dict) -> None:
    """Invert a chosen coupled model once more, given the other axis's final commands."""
    plans = {axis: ax.plan for axis, ax in axes.items()}
    for axis, ax in axes.items():
        kind = chosen[axis][0]
        if kind in COUPLED_KINDS:
            other = next(x for x in axes if x != axis)
            o = axes[other]
            vo = o.plan.sign * o.candidates[chosen[other][0]].commands
            ax.candidates[kind] = invert_axis(
                ax.models[kind], ax.plan, vo, o.plan.sign * o.plan.v_entry,
                _other_hist(plans, axis),
            )  # fmt: skip
