"""The plan of a compensation: per axis the fitted dataset it inverts, the sign, input
range, rate limit, start counts and start state (:class:`AxisPlan`), and the choices
made before any inversion: which dataset serves a target, which model kinds to invert,
which model the fit's decision gives (:func:`decided_kind`).

``compensate`` (:mod:`i2ris_calib.commands.compensate`) and the online
:class:`~i2ris_calib.io.online.Compensator` set their axes up here
(:func:`axis_plan`); the io layer only reads what a fit.json says
(:class:`FittedDataset`). Pure numbers and arrays (no files, no printing).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace

import numpy as np

from i2ris_calib.compensation.rate import RateLimit, rate_limit
from i2ris_calib.compensation.safety import MAX_RAMP_COMMANDS, conditioning_sweep, ramp_commands
from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.decision import Decision
from i2ris_calib.hysteresis.kinds import DIAGNOSED
from i2ris_calib.hysteresis.registry import INVERSE_KINDS, KINDS

#: Kinds that read the other motor's input (inverted only when both axes are compensated)
COUPLED_KINDS = tuple(k.kind for k in KINDS if k.coupled and k.inverse)


@dataclass(frozen=True)
class FittedDataset:
    """What compensation reads of one fit.json dataset record
    (:func:`i2ris_calib.io.fit_records.fitted_dataset`).

    Attributes
    ----------
    name : str
        Dataset name (``yaw+``, ``pitch±``, ...).
    where : str
        The fit.json it comes from (for messages).
    input_range : tuple of float
        Fitted input range (counts, model convention).
    recorded_rate : float or None
        The recording's fastest input move (counts/s; None in older files).
    kinds : tuple of str
        Its fitted model kinds, file order.
    holdout : mapping
        Kind -> held-out RMSE (deg; the fitted RMSE without one; None: neither).
    virgin : bool or None
        Whether the fit knows the model's state at rest: True when its recording
        started at rest, False when mid-loop (an ``initial_state`` was estimated), None
        when the file does not say (older files).
    decision : Decision
        The model the fit recommends and its ranking.
    """

    name: str
    where: str
    input_range: tuple[float, float]
    recorded_rate: float | None
    kinds: tuple[str, ...]
    holdout: Mapping[str, float | None]
    virgin: bool | None
    decision: Decision


@dataclass(frozen=True)
class StartState:
    """How the commands start, the same for every axis (:func:`start_state`).

    Attributes
    ----------
    sweep : bool
        A conditioning sweep is prepended.
    method : str
        ``rest``, ``conditioning_sweep``, ``history`` or ``history+conditioning_sweep``.
    reason : str
        Why (one sentence).
    """

    sweep: bool
    method: str
    reason: str


@dataclass(frozen=True)
class AxisPlan:
    """One axis's compensation plan, in the model's convention (the input ``v`` the model
    sees, its output angle; ``sign`` maps them to the robot's signed counts and angle).

    Attributes
    ----------
    axis : str
        ``yaw`` or ``pitch``.
    fit : FittedDataset
        The fitted dataset inverted.
    sign : float
        -1 for a ``-`` dataset, else +1.
    lo, hi : float
        Allowed input range (counts; a direction's range includes 0).
    rate : RateLimit
        The rate limit.
    v0 : float
        Start input (the motor's counts at rest, or the history's last row).
    start_source : str
        Where ``v0`` comes from.
    goal : ndarray, shape (n,)
        The target (deg, model convention).
    t : ndarray, shape (n,)
        Its times (s).
    hist : ndarray or None
        The inputs before the entry ramp: the history, then the conditioning sweep
        padded to the longest axis's (None when neither).
    n_pre : int
        The history's length (1 without one: the start input).
    v_entry : float
        Where the entry ramp starts.
    start : StartState or None
        The start state.
    sweep_ends : tuple of float or None
        The conditioning sweep's turning counts (robot's sign), or None without a sweep.
    """

    axis: str
    fit: FittedDataset
    sign: float
    lo: float
    hi: float
    rate: RateLimit
    v0: float = 0.0
    start_source: str = ""
    goal: np.ndarray | None = None
    t: np.ndarray | None = None
    hist: np.ndarray | None = None
    n_pre: int = 0
    v_entry: float = 0.0
    start: StartState | None = None
    sweep_ends: tuple[float, ...] | None = None

    @property
    def name(self) -> str:
        """The dataset's name."""
        return self.fit.name

    @property
    def max_rate(self) -> float | None:
        """The rate limit for the inverse (counts/s; None: none)."""
        rate = self.rate.counts_per_s
        return None if not np.isfinite(rate) else rate


def axis_plan(
    fit: FittedDataset,
    explicit_rate: float | None,
    configured_rate: float = 0.0,
    option: str = "--max-counts-per-s",
) -> AxisPlan:
    """The axis set-up of dataset ``fit``: sign (-1 for a ``-`` dataset), input range (a
    motion direction's includes 0) and rate limit (:func:`~.rate.rate_limit`; ``option``
    names the explicit rate in messages)."""
    sign = -1.0 if fit.name.endswith("-") else 1.0
    lo, hi = (float(x) for x in fit.input_range)
    if not fit.name.endswith("±"):
        lo = min(lo, 0.0)
    rate = rate_limit(fit.recorded_rate, explicit_rate, configured_rate, hi - lo, fit.name,
                      option)  # fmt: skip
    return AxisPlan(fit.name[:-1], fit, sign, lo, hi, rate)


def with_target(plan: AxisPlan, target_deg: np.ndarray, t: np.ndarray, start_counts) -> AxisPlan:
    """``plan`` with its goal (the target, deg in the robot's sign, in the model's
    convention) and start input (:func:`start_input`)."""
    v0, source = start_input(plan, start_counts)
    return replace(plan, v0=v0, start_source=source, goal=plan.sign * target_deg, t=t)


def start_input(plan: AxisPlan, start_counts: float | None) -> tuple[float, str]:
    """(start input in the model's convention, where it comes from): ``--start-counts``
    (refused outside the fitted range), else rest at 0 or the range's end nearest 0."""
    lo, hi, sign = plan.lo, plan.hi, plan.sign
    if start_counts is None:
        v0 = float(np.clip(0.0, lo, hi))
        if v0 != 0.0:
            return v0, "default (the fitted range's end nearest 0)"
        return v0, "default (rest at 0)"
    v0 = sign * float(start_counts)
    if not lo <= v0 <= hi:
        rng = sorted((sign * lo + 0.0, sign * hi + 0.0))
        raise CalibError(
            f"--start-counts {start_counts:g} is outside the {plan.name} fit's input range "
            f"{rng[0]:g}..{rng[1]:g} counts ({plan.fit.where}); give the encoder counts the "
            "motor rests at, inside that range"
        )
    return v0, "--start-counts"


def choose_dataset(names: list[str], axis: str, target_deg: np.ndarray, where: str) -> str:
    """The dataset of a fit (its dataset ``names``) that serves a target on ``axis``
    (``--dataset`` omitted): a target crossing zero needs the signed ``<axis>±``
    dataset; otherwise the direction of the target's median angle (``+`` when >= 0), or
    the signed dataset when that direction was not fitted. ``where``: the fit.json."""
    signed = f"{axis}±"
    lo, hi = float(np.min(target_deg)), float(np.max(target_deg))
    if lo < 0 < hi:
        if signed in names:
            return signed
        raise CalibError(
            f"{where}: the {axis} target crosses zero ({lo:.3g} to {hi:.3g} deg) but the fit "
            f"has only {', '.join(names)}; fit the axis with 'fit --signed' (one model across "
            "zero) or split the target"
        )
    name = f"{axis}{'+' if not np.median(target_deg) < 0 else '-'}"
    if name in names:
        return name
    if signed in names:
        return signed
    raise CalibError(
        f"{where}: no dataset for a {axis} target of that sign ({name}; it has "
        f"{', '.join(names)}); give --dataset or fit that direction"
    )


def check_ramp_lengths(plans: Mapping[str, AxisPlan], t: np.ndarray) -> None:
    """CalibError, before any ramp is built, when an axis's rate limit is so slow that
    a ramp across its fitted input range (the entry ramp or a leg of the conditioning
    sweep) would take more than :data:`~.safety.MAX_RAMP_COMMANDS` commands at the
    target's sample interval (``--max-counts-per-s 1e-9`` asked for 610 TiB)."""
    dt0 = float(t[1] - t[0]) if t.size > 1 else 1.0
    for a in plans.values():
        span = a.hi - a.lo
        rate = a.rate.counts_per_s
        need = ramp_commands(span, rate, dt0)
        if need > MAX_RAMP_COMMANDS:
            rng = sorted((a.sign * a.lo + 0.0, a.sign * a.hi + 0.0))
            raise CalibError(
                f"rate limit {rate:g} counts/s ({a.rate.source}) is too slow for the "
                f"{a.name} fit's input range {rng[0]:g}..{rng[1]:g} counts: a ramp across "
                f"it at one command every {dt0:g} s (the target's interval) would take "
                f"{need:.3g} commands (at most {MAX_RAMP_COMMANDS:.0e}); give a rate limit of "
                f"at least {span / (MAX_RAMP_COMMANDS * dt0):.3g} counts/s"
            )


def after_history(
    plans: dict[str, AxisPlan], past: Mapping[str, np.ndarray], start_counts, where: str
) -> dict[str, AxisPlan]:
    """The plans starting at the last row of the commands sent before (``past``: axis ->
    model-convention inputs, oldest first; ``where``: the history file);
    ``--start-counts``, if given, must be it."""
    out = {}
    for axis, a in plans.items():
        last = float(past[axis][-1])
        if start_counts is not None and last != a.v0:
            raise CalibError(
                f"--start-counts {start_counts:g} is not the history's last {axis} counts "
                f"{a.sign * last:g} ({where}); give one of them"
            )
        out[axis] = replace(a, v0=last, start_source=f"--history (its last row, {where})")
    return out


def start_state(plans: Mapping[str, AxisPlan], conditioning: str, history: bool) -> StartState:
    """How the commands start (``--conditioning``; ``history``: ``--history`` given), the
    same for every axis (with a coupled model one motor's history is part of the
    other's state).

    ``auto`` sweeps when some axis's fit cannot know the robot's state at rest: its
    recording started mid-loop (fit.json ``initial_state`` estimated), so the model's
    virgin state is not identified and no command can correct it. It does not sweep
    with ``--history`` (the state follows from it), when every recording started at rest
    (the model's state at rest is the relaxed robot's), or when fit.json does not say
    (older files; said in the reason)."""
    mid = [a.name for a in plans.values() if a.fit.virgin is False]
    unknown = [a.name for a in plans.values() if a.fit.virgin is None]
    if conditioning == "sweep":
        sweep, reason = True, "--conditioning sweep"
    elif conditioning == "none":
        sweep, reason = False, "--conditioning none"
    elif history:
        sweep, reason = False, "the state follows from --history"
    elif mid:
        sweep = True
        reason = (
            f"the {', '.join(mid)} fit's recording started mid-loop (fit.json initial_state "
            "estimated): the model's state at rest is not identified"
        )
    elif unknown:
        sweep = False
        reason = (
            f"fit.json ({', '.join(unknown)}) does not say whether its recording started at "
            "rest (an older fit): assumed relaxed at the start counts; --conditioning sweep "
            "if the robot may not be"
        )
    else:
        sweep = False
        reason = (
            "the fit's recording started at rest: the model knows the relaxed robot at the "
            "start counts (--conditioning sweep if it has moved since)"
        )
    if history:
        method = "history+conditioning_sweep" if sweep else "history"
    else:
        method = "conditioning_sweep" if sweep else "rest"
    return StartState(sweep, method, reason)


def sweep_last(goal: np.ndarray) -> str:
    """The end of the input range a conditioning sweep finishes at: ``lo`` when the
    target first rises (model convention: the entry ramp then approaches its first
    command from below, in the direction the target moves on), ``hi`` when it first
    falls; ``lo`` for a constant target."""
    d = np.asarray(goal, dtype=float) - float(goal[0])
    span = float(np.ptp(goal))
    moved = np.flatnonzero(np.abs(d) > 0.01 * span) if span > 0 else np.zeros(0, dtype=int)
    return "lo" if moved.size == 0 or d[moved[0]] > 0 else "hi"


def with_start(
    plans: Mapping[str, AxisPlan],
    start: StartState,
    past: Mapping[str, np.ndarray] | None,
    t: np.ndarray,
) -> dict[str, AxisPlan]:
    """The plans with the inputs before their entry ramps: ``hist`` (the history
    ``past``, then the conditioning sweep padded to the longest axis's; None when
    neither), ``n_pre`` (the history's length), ``v_entry`` (where the entry ramp
    starts), ``start`` and ``sweep_ends`` (the sweep's turning counts, robot's sign)."""
    dt0 = float(t[1] - t[0]) if t.size > 1 else 1.0
    sweeps = {
        axis: conditioning_sweep(
            a.v0, a.lo, a.hi, a.rate.counts_per_s, dt0, 1.0, last=sweep_last(a.goal)
        )
        if start.sweep
        else np.zeros(0)
        for axis, a in plans.items()
    }  # fmt: skip
    n_cond = max(x.size for x in sweeps.values())
    out = {}
    for axis, a in plans.items():
        cond = np.concatenate((np.full(n_cond - sweeps[axis].size, a.v0), sweeps[axis]))
        pre = past[axis] if past is not None else np.array([a.v0])
        hist = np.concatenate((pre, cond)) if (past is not None or n_cond) else None
        ends = (a.hi, a.lo) if sweep_last(a.goal) == "lo" else (a.lo, a.hi)
        out[axis] = replace(
            a, hist=hist, n_pre=pre.size, v_entry=float(hist[-1]) if hist is not None else a.v0,
            start=start,
            sweep_ends=tuple(float(a.sign * x) + 0.0 for x in ends) if sweeps[axis].size else None,
        )  # fmt: skip
    return out


def kinds_to_invert(
    plan: AxisPlan, both_axes: bool, model: str | None, model_file: bool
) -> list[str]:
    """The model kinds of ``plan``'s dataset to invert: ``model``'s (``--model``; a
    coupled one needs the other axis), else every invertible fitted kind (coupled ones
    only with ``both_axes``; ``diagnosed`` with a ``model_file``)."""
    name, kinds_fitted = plan.name, plan.fit.kinds
    if model is not None:
        if model in COUPLED_KINDS and not both_axes:
            o = "pitch" if plan.axis == "yaw" else "yaw"
            raise CalibError(
                f"--model {model} for {name} needs the {o} motor's commands: give the {o} "
                f"fit.json and a {o}_deg target column too (or another --model)"
            )
        return [model]
    kinds = [k for k in kinds_fitted if k in INVERSE_KINDS]
    if not both_axes:  # no other motor's commands: coupled models left out
        kinds = [k for k in kinds if k not in COUPLED_KINDS]
    if DIAGNOSED in kinds_fitted and model_file:
        kinds.append(DIAGNOSED)
    if not kinds:
        raise CalibError(
            f"{plan.fit.where} [{name}]: none of its models ({', '.join(kinds_fitted)}) "
            f"can be inverted; compensate inverts {', '.join(INVERSE_KINDS)} and "
            "diagnosed models (coupled ones with both axes)"
        )
    return kinds


def alternative_kinds(fit: FittedDataset, forced: str) -> list[str]:
    """The dataset's other uncoupled invertible kinds, ranked beside a ``--model``-forced
    one whose output steps (so the warning can name those that do not)."""
    return [k for k in fit.kinds if k != forced and k in INVERSE_KINDS and k not in COUPLED_KINDS]


def decided_kind(
    decision: Decision, refusal: Callable[[str], str | None], where: str
) -> tuple[str, str]:
    """(kind, note) of the recommended model for an entry point that cannot use every
    kind (``refusal(kind)``: why not, None when it can; :meth:`Decision.model_for`);
    ``note`` says which model it uses instead and why (empty: the recommended one). A
    one-line CalibError (``where``: the file and dataset) when it can use none."""
    kind, note = decision.model_for(refusal)
    if kind is None:
        raise CalibError(f"{where}: {note}")
    return kind, note


#: Kinds the online compensator inverts (``diagnosed``: with its model file): every
#: kind with an inverse in the registry, as the batch
ONLINE_KINDS = INVERSE_KINDS


def online_kind(fit: FittedDataset, model: str | None, coupled_ok: bool) -> tuple[str, str]:
    """(kind, note) the online compensator inverts for dataset ``fit``: ``model``
    checked, or the fit's decision (:func:`decided_kind`; a coupled kind only when
    ``coupled_ok``, both axes' fits given); ``note`` says which model instead and why."""
    if model is not None:
        if model not in ONLINE_KINDS and model != DIAGNOSED:
            raise CalibError(
                f"Compensator.from_fit: model must be one of {', '.join(ONLINE_KINDS)}, "
                f"got '{model}'"
            )
        return model, ""

    def refusal(kind: str) -> str | None:
        if kind not in ONLINE_KINDS:
            return (
                f"{kind} has no inverse (the online compensator inverts {', '.join(ONLINE_KINDS)})"
            )
        if kind in COUPLED_KINDS and not coupled_ok:
            return f"{kind} reads the other motor: give both axes' fit.json"
        return None

    return decided_kind(fit.decision, refusal, f"{fit.where} [{fit.name}]")
