"""What a compensation sends and predicts: per axis every command (the history and
conditioning sweep, the entry ramps padded to a common length, the target's samples),
the model's angles over them, the flags of each sample, the summary and the warnings
(the target mostly out of reach, the chosen model's output stepping where the target
passes).

Takes :class:`~.plan.AxisPlan` and :class:`~.choice.AxisChoice`, returns
:class:`Outcome` (arrays; no files, no printing): ``compensate`` writes it as
COMMANDS.csv and compensate.json (docs/compensate.md).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from i2ris_calib.compensation.choice import STEP_SHARE, AxisChoice, family_switch_steps
from i2ris_calib.compensation.inverse import FLAG_NAMES, forward
from i2ris_calib.compensation.plan import COUPLED_KINDS, AxisPlan
from i2ris_calib.hysteresis.registry import KINDS
from i2ris_calib.interrupts import deferred

#: Kinds whose output steps at their flag point v_f (registry ``output_steps``)
STEP_AT_VF_KINDS = tuple(k.kind for k in KINDS if k.output_steps)
#: Share of the target outside the angles the model reaches above which compensate
#: says why, not only how many samples are unreachable (:func:`range_warning`).
OUTSIDE_SHARE = 0.5


@dataclass(frozen=True)
class AxisOutcome:
    """One axis's commands, predictions, flags and summary (robot's sign).

    Attributes
    ----------
    counts : ndarray of int64
        Signed counts of every row from the conditioning sweep on.
    predicted_deg : ndarray
        The model's angle after each (deg).
    reachable : ndarray of bool
        True for the sweep and entry rows and where the target was reached.
    flags : dict
        Flag -> bool per target sample (:data:`~.inverse.FLAG_NAMES`; ``output_step``
        with the paper EGPI's family switches).
    row_flags : list of list of str
        Each row's flags (``conditioning``, ``entry``, then the target's flags).
    summary : dict
        The result's summary, every flag counted, the fastest command move.
    reach : tuple of float
        (lowest, highest) angle the model shows over its input range (deg).
    warnings : list of str
        Lines to show (rate limit, range, output steps).
    """

    counts: np.ndarray
    predicted_deg: np.ndarray
    reachable: np.ndarray
    flags: dict
    row_flags: list
    summary: dict
    reach: tuple[float, float]
    warnings: list[str]


@dataclass(frozen=True)
class Outcome:
    """Every axis's :class:`AxisOutcome` over the common rows.

    Attributes
    ----------
    t : ndarray
        Row times (s): the conditioning sweep and entry rows one target interval apart
        before the target's.
    n_cond, n_entry, n_pre : int
        Rows of the conditioning sweep and of the (padded) entry ramp; inputs of the
        known history before them (not rows).
    dt0 : float
        The target's first interval (s; 1 for one sample).
    axes : dict
        Axis -> :class:`AxisOutcome`.
    """

    t: np.ndarray
    n_cond: int
    n_entry: int
    n_pre: int
    dt0: float
    axes: dict[str, AxisOutcome]


def outcome(
    plans: Mapping[str, AxisPlan], choices: Mapping[str, AxisChoice], t: np.ndarray
) -> Outcome:
    """The rows sent: the conditioning sweep (common length, each plan's ``hist`` after
    the known history's ``n_pre`` inputs), then every axis's entry ramp padded to the
    longest (holding the sweep's end, or the start counts, before its own ramp), then
    the target's samples ``t``. The predicted angles are the model run over the whole
    sequence (history included) from rest."""
    n_entry = max(c.result.entry_commands.size for c in choices.values())
    first = next(iter(plans.values()))
    n_pre = first.n_pre if first.hist is not None else 0
    n_cond = first.hist.size - n_pre if first.hist is not None else 0
    dt0 = float(t[1] - t[0]) if t.size > 1 else 1.0
    t_full = np.concatenate((t[0] - dt0 * np.arange(n_pre + n_cond + n_entry, 0, -1), t))
    t_all = t_full[n_pre:]
    seqs = _command_sequences(plans, choices, n_entry)
    axes = {}
    for axis, a in plans.items():
        c = choices[axis]
        res, sign = c.result, a.sign
        y = _predicted(plans, choices, axis, seqs, t_full, n_pre)
        seq = seqs[axis][n_pre:]
        fl = dict(res.flags)
        fl["output_step"] = fl["output_step"] | family_switch_steps(c.model, res, a.v0)
        sent = np.concatenate(([seqs[axis][n_pre - 1]] if n_pre else [], seq))
        t_sent = np.concatenate(([t_full[n_pre - 1]] if n_pre else [], t_all))
        summ, reach, warnings = _axis_summary(a, c, fl, _max_rate(sent, t_sent))
        axes[axis] = AxisOutcome(
            counts=np.rint(sign * seq).astype(np.int64),
            predicted_deg=sign * y,
            reachable=np.concatenate((np.ones(n_cond + n_entry, dtype=bool), res.reachable)),
            flags=fl,
            row_flags=[["conditioning"] for _ in range(n_cond)]
            + [["entry"] for _ in range(n_entry)]
            + [[f for f in FLAG_NAMES if fl[f][i]] for i in range(t.size)],
            summary=summ,
            reach=reach,
            warnings=warnings,
        )
    return Outcome(t_all, n_cond, n_entry, n_pre, dt0, axes)


def _command_sequences(plans, choices, n_entry: int) -> dict[str, np.ndarray]:
    """Axis -> every input the model sees (model convention): history and conditioning
    sweep, the entry ramp padded to ``n_entry`` by holding its start, the commands."""
    seqs = {}
    for axis, a in plans.items():
        res = choices[axis].result
        ramp = res.entry_commands
        hist = a.hist if a.hist is not None else np.zeros(0)
        seqs[axis] = np.concatenate(
            (hist, np.full(n_entry - ramp.size, a.v_entry), ramp, res.commands)
        )
    return seqs


def _predicted(plans, choices, axis: str, seqs: dict, t_full: np.ndarray, n_pre: int):
    """The axis's model output (deg, model convention) over its sequence from the
    conditioning sweep on (shape ``(seqs[axis].size - n_pre,)``): run from rest at the
    history's first input, or from the start counts; a coupled model given the other
    axis's sequence."""
    a, c = plans[axis], choices[axis]
    other = next((x for x in plans if x != axis), None)
    vo = vo0 = None
    if other is not None and c.kind in COUPLED_KINDS:
        vo = plans[other].sign * seqs[other]
        vo0 = plans[other].sign * plans[other].v0
    with deferred():
        if a.hist is not None:  # from rest at the history's first input
            return forward(c.model, seqs[axis], t_full, None, v_other=vo)[n_pre:]
        return forward(c.model, seqs[axis], t_full[n_pre:], a.v0, v_other=vo, v_other_initial=vo0)


def _max_rate(sent: np.ndarray, t_sent: np.ndarray) -> float:
    """The fastest command move (counts/s) over consecutive commands sent; 0 for one."""
    return float(np.max(np.abs(np.diff(sent)) / np.diff(t_sent))) if sent.size > 1 else 0.0


def _axis_summary(a: AxisPlan, c: AxisChoice, fl: dict, max_rate: float):
    """(summary, reachable angles, warnings) of one axis: the result's summary with
    every flag counted (``fl``: flag -> bool per target sample) and the fastest command
    move; the rate limit's, the range's and the output steps' warnings."""
    res = c.result
    summ = res.summary()
    summ["flags"] = {name: int(f.sum()) for name, f in fl.items()}
    summ.pop("n_history", None)
    summ["max_command_rate_per_s"] = max_rate
    step_warn = output_step_warning(c, summ, fl["output_step"] | fl["spike_removed"])
    reach = reachable_angles(c.model, (a.lo, a.hi), a.sign)
    warn = range_warning(
        a.name, c.kind, a.sign * a.goal, reach, res.tol_deg, float(res.reachable.mean())
    )
    warnings = [w for w in (a.rate.warning, warn, step_warn) if w is not None]
    return summ, reach, warnings


def reachable_angles(model, v_limits: tuple[float, float], sign: float) -> tuple[float, float]:
    """(lowest, highest) angle (deg, the robot's sign: ``sign`` -1 for a ``-`` dataset)
    the model shows over its input range ``v_limits``: its output along a slow sweep of
    the whole range up and back down (both branches of the loop)."""
    up = np.linspace(v_limits[0], v_limits[1], 1001)
    v = np.concatenate([up, up[::-1]])
    y = sign * forward(model, v, np.arange(v.size, dtype=float))
    return float(np.min(y)), float(np.max(y))


def range_warning(
    name: str,
    kind: str,
    target_deg: np.ndarray,
    reach: tuple[float, float],
    tol_deg: float,
    reached: float,
) -> str | None:
    """Why a target is mostly unreachable (the likely mistake), or None.

    Said when most of the target lies outside the angles the model reaches (``reach``,
    deg in the robot's sign, :func:`reachable_angles`), or when most of it is not
    reached (``reached``: the share reached) and it is a sliver of the model's range in
    radian-sized numbers. Gives the target's range against the model's and, when that
    brings the target inside, the fix: degrees instead of radians, the other sign (the
    other motion direction's dataset), or both.
    """
    lo, hi = reach
    pad = max(float(tol_deg), 1e-6 * max(1.0, abs(lo), abs(hi)))

    def inside(x: np.ndarray) -> float:
        return float(np.mean((x >= lo - pad) & (x <= hi + pad)))

    x = np.asarray(target_deg, dtype=float)
    t_lo, t_hi = float(np.min(x)), float(np.max(x))
    outside = 1.0 - inside(x)
    radian_sized = max(abs(t_lo), abs(t_hi)) <= 2 * np.pi
    sliver = radian_sized and t_hi - t_lo < 0.05 * (hi - lo)
    if not (outside > OUTSIDE_SHARE or (1.0 - reached > OUTSIDE_SHARE and sliver)):
        return None
    other = name[:-1] + ("-" if name.endswith("+") else "+")
    sign_fix = f"give --dataset {other} (the other motion direction) or negate the target"
    deg = np.degrees(x)
    in_deg = f"{np.degrees(t_lo):.3g} to {np.degrees(t_hi):.3g} deg"
    fixes = []
    if outside > OUTSIDE_SHARE:
        fixes.append((inside(-x), f"the target has the other sign: {sign_fix}"))
    if radian_sized:
        fixes += [
            (inside(deg), f"if the target is in radians, convert it to degrees ({in_deg})"),
            (inside(-deg), f"the target looks like radians ({in_deg}) of the other sign: "
                           f"convert it to degrees and {sign_fix}"),
        ]  # fmt: skip
    share, fix = max(fixes, key=lambda f: f[0], default=(0.0, ""))
    if share < 0.9:
        fix = "give a target within the model's angles, or fit recordings that reach the target's"
    if outside > OUTSIDE_SHARE:
        what = f"{outside:.0%} of the target lies outside the angles the model reaches"
    else:
        what = (
            f"{1.0 - reached:.0%} of the target is unreachable, and it is a sliver of the "
            "model's angles"
        )
    return (
        f"{name} ({kind}): {what}: the target spans {t_lo:.3g} to {t_hi:.3g} deg, the model "
        f"{lo:.3g} to {hi:.3g} deg; {fix}"
    )


def output_step_warning(c: AxisChoice, summ: dict, stepped: np.ndarray | None = None) -> str | None:
    """The line saying the chosen model's predicted output steps where the target passes
    (more than :data:`~.choice.STEP_SHARE` of the samples flagged ``output_step`` or
    ``spike_removed``; ``stepped``: those samples, shape (n,), for the largest miss
    there), naming the continuous models of the ranking with their predicted tracking
    error (``score_deg``, the chosen model's too). When the ranking chose the stepping
    model, the smooth ones track more than :data:`~.choice.STEP_PENALTY` x worse: they
    are named as the choice for when smoothness matters more, not as the better model.
    None when the model does not step."""
    n = summ["flags"]["output_step"] + summ["flags"]["spike_removed"]
    if n <= STEP_SHARE * summ["n_samples"]:
        return None
    kind = c.kind
    where = " at v_f" if kind in STEP_AT_VF_KINDS else ""
    res = c.result
    miss = ""
    if stepped is not None and stepped.any():
        err = np.abs(res.predicted_deg - res.target_deg)[stepped]
        miss = f", missing the target by up to {float(np.max(err)):.3g} deg there"
    smooth = [r for r in c.ranking if r["continuous"] and r["model"] != kind]
    mine = next((r["score_deg"] for r in c.ranking if r["model"] == kind), None)
    if smooth:
        names = " or ".join(f"{r['model']} ({r['score_deg']:.3g} deg)" for r in smooth)
        cost = "" if mine is None else f"; {kind} {mine:.3g} deg"
        if c.forced:
            alt = (
                f"{names} track it without steps (predicted tracking error{cost}): "
                f"--model {smooth[0]['model']}"
            )
        else:
            alt = (
                f"{names} track it without steps (predicted tracking error{cost}); "
                f"--model {smooth[0]['model']} if smooth output matters more"
            )
    elif c.forced:
        alt = "leave out --model to rank the other models on this target"
    else:
        alt = "no other model of the fit tracks it without steps"
    return (
        f"{kind} steps{where} where the target passes ({n} samples flagged output_step"
        f"{' or spike_removed' if summ['flags']['spike_removed'] else ''}{miss}); {alt}"
    )
