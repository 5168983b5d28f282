"""``i2ris-calib compensate``: fit.json + target CSV -> COMMANDS.csv + compensate.json.

Formats are documented in docs/compensate.md (schema ``i2ris-calib.compensate/1``).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from i2ris_calib.compensation import STATUS_NAMES, compensate
from i2ris_calib.compensation.config import CONDITIONING
from i2ris_calib.compensation.inverse import FLAG_NAMES, forward
from i2ris_calib.compensation.safety import (
    MAX_RAMP_COMMANDS,
    conditioning_sweep,
    ramp_commands,
)
from i2ris_calib.errors import CalibError
from i2ris_calib.hysteresis.effects import model_values
from i2ris_calib.hysteresis.kinds import DIAGNOSED
from i2ris_calib.hysteresis.registry import INVERSE_KINDS
from i2ris_calib.hysteresis.registry import KINDS as KIND_ROWS
from i2ris_calib.interrupts import deferred
from i2ris_calib.io.atomic import atomic_path, write_json
from i2ris_calib.io.csv_file import read_csv_header
from i2ris_calib.io.fit import read_fit_json
from i2ris_calib.io.fit_records import (
    dataset_names,
    dataset_record,
    decided_kind,
    holdout_rmse,
    load_model,
    rate_limit,
    record_decision,
)
from i2ris_calib.io.outputs import claim_output_file, output_lock
from i2ris_calib.io.provenance import provenance
from i2ris_calib.io.target_csv import read_history, read_target
from i2ris_calib.model import Signals

SCHEMA = "i2ris-calib.compensate/1"
#: ``--model`` choices: the kinds with an inverse (registry) and ``"diagnosed"``
KINDS = (*INVERSE_KINDS, DIAGNOSED)
#: ``--dataset`` choices (``yaw+-`` is accepted for ``yaw±``)
DATASETS = ("yaw+", "yaw-", "yaw±", "pitch+", "pitch-", "pitch±")

METHOD_NOTE = (
    "exact inversion of the stateful model sample by sample (one root find per branch "
    "region); where the model's output has a step (the paper EGPI's switch at v_f, a "
    "reversal jump) the command whose output is nearest the target is chosen; among "
    "commands that all meet the target (within tol_deg) the one that keeps the motion "
    "direction, then the smallest move; in a dead zone the largest move toward the "
    "target; a rate limit slews toward the unconstrained inverse; commands are whole "
    "counts (the better of the two neighbours of the chosen real-valued inverse, or the "
    "hold) and the predicted angles are the forward model evaluated over them"
)


def choose_dataset(doc: dict, axis: str, target_deg: np.ndarray, path: Path) -> str:
    """The dataset of ``doc`` that serves a target on ``axis`` (``--dataset`` omitted):
    a target crossing zero needs the signed ``<axis>±`` dataset; otherwise the
    direction of the target's median angle (``+`` when >= 0), or the signed dataset
    when that direction was not fitted."""
    names = dataset_names(doc)
    signed = f"{axis}±"
    lo, hi = float(np.min(target_deg)), float(np.max(target_deg))
    if lo < 0 < hi:
        if signed in names:
            return signed
        raise CalibError(
            f"{path}: the {axis} target crosses zero ({lo:.3g} to {hi:.3g} deg) but the fit "
            f"has only {', '.join(names)}; fit the axis with 'fit --signed' (one model across "
            "zero) or split the target"
        )
    name = f"{axis}{'+' if not np.median(target_deg) < 0 else '-'}"
    if name in names:
        return name
    if signed in names:
        return signed
    raise CalibError(
        f"{path}: no dataset for a {axis} target of that sign ({name}; it has "
        f"{', '.join(names)}); give --dataset or fit that direction"
    )


#: Share of the target outside the angles the model reaches above which compensate
#: says why, not only how many samples are unreachable (:func:`range_warning`).
OUTSIDE_SHARE = 0.5


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


def _virgin_identified(record: dict) -> bool | None:
    """Whether the fit knows the model's state at rest: True when its recording started
    at rest (no model of the dataset has an estimated ``initial_state``), False when it
    started mid-loop (an ``initial_state`` was estimated), None when fit.json does not
    say (older files)."""
    models = record.get("models", {}).values()
    if not any("initial_state" in m for m in models):
        return None
    return not any(m.get("initial_state") for m in models)


def start_state(setup: dict, conditioning: str, history) -> dict:
    """How the commands start (``--conditioning``, ``--history``): ``{"sweep": bool,
    "method": ..., "reason": ...}``, the same for every axis (with a coupled model one
    motor's history is part of the other's state).

    ``auto`` sweeps when some axis's fit cannot know the robot's state at rest: its
    recording started mid-loop (fit.json ``initial_state`` estimated), so the model's
    virgin state is not identified and no command can correct it. It does not sweep
    with ``--history`` (the state follows from it), when every recording started at rest
    (the model's state at rest is the relaxed robot's), or when fit.json does not say
    (older files; said in the reason)."""
    known = {axis: _virgin_identified(a["record"]) for axis, a in setup.items()}
    mid = [a["name"] for axis, a in setup.items() if known[axis] is False]
    unknown = [a["name"] for axis, a in setup.items() if known[axis] is None]
    if conditioning == "sweep":
        sweep, reason = True, "--conditioning sweep"
    elif conditioning == "none":
        sweep, reason = False, "--conditioning none"
    elif history is not None:
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
    if history is not None:
        method = "history+conditioning_sweep" if sweep else "history"
    else:
        method = "conditioning_sweep" if sweep else "rest"
    return {"sweep": sweep, "method": method, "reason": reason}


def sweep_last(goal: np.ndarray) -> str:
    """The end of the input range a conditioning sweep finishes at: ``lo`` when the
    target first rises (model convention: the entry ramp then approaches its first
    command from below, in the direction the target moves on), ``hi`` when it first
    falls; ``lo`` for a constant target."""
    d = np.asarray(goal, dtype=float) - float(goal[0])
    span = float(np.ptp(goal))
    moved = np.flatnonzero(np.abs(d) > 0.01 * span) if span > 0 else np.zeros(0, dtype=int)
    return "lo" if moved.size == 0 or d[moved[0]] > 0 else "hi"


def _flag_column(per_axis: dict[str, list[list[str]]], prefix: bool) -> list[str]:
    """The ``flags`` column: the sample's flags joined by ``;`` (``axis:flag`` with two
    axes), empty when none."""
    axes = list(per_axis)
    n = len(per_axis[axes[0]])
    out = []
    for i in range(n):
        names = []
        for a in axes:
            names += [f"{a}:{f}" if prefix else f for f in per_axis[a][i]]
        out.append(";".join(names))
    return out


#: Smallest output jump (deg) at a switch of the shown operator family that counts as an
#: output step: ``max(STEP_MIN_DEG, 10 tol_deg)`` (as the spike repair's output test)
STEP_MIN_DEG = 0.05


def family_switch_steps(model, res, v0: float) -> np.ndarray:
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


#: Share of the target's samples with an output step (or a removed spike) above which a
#: model counts as stepping where the target passes (ranked down: :data:`STEP_PENALTY`)
STEP_SHARE = 0.005
#: Factor on a stepping model's score in the ranking: it ranks after a continuous model
#: unless its predicted tracking error is below 1/STEP_PENALTY of that model's (an
#: uncoupled model 14x worse held out must not beat the coupled one for a few steps)
STEP_PENALTY = 2.0


#: Predicted tracking error that ranks a model: its error on the target (its own
#: prediction) and its held-out fit error, combined in quadrature (deg)
def _score(pred_rmse: float, holdout: float | None) -> float:
    h = 0.0 if holdout is None or not np.isfinite(holdout) else float(holdout)
    return float(np.hypot(pred_rmse, h))


def _invert_axis(
    fitted, goal, t, lo, hi, rate, v0, v_other=None, v_other_initial=None, hist=None,
    hist_other=None,
):  # fmt: skip
    """One axis inverted from rest at ``v0``, or (``hist``: model convention, its first
    input at rest) from the state its history and conditioning sweep leave."""
    return compensate(
        fitted, goal, t, v_limits=(lo, hi), max_rate=None if not np.isfinite(rate) else rate,
        quantum=1.0, v_initial=v0 if hist is None else None, v_other=v_other,
        v_other_initial=v_other_initial, v_history=hist,
        v_other_history=None if hist is None or v_other is None else hist_other,
    )  # fmt: skip


def _other_hist(setup: dict, axis: str):
    """The other axis's history in signed counts (or None)."""
    other = next((x for x in setup if x != axis), None)
    if other is None or setup[other]["hist"] is None:
        return None
    return setup[other]["sign"] * setup[other]["hist"]


#: Kinds that read the other motor's input (inverted only when both axes are compensated)
COUPLED_KINDS = tuple(k.kind for k in KIND_ROWS if k.coupled and k.inverse)
#: Kinds whose output steps at their flag point v_f (registry ``output_steps``)
STEP_AT_VF_KINDS = tuple(k.kind for k in KIND_ROWS if k.output_steps)
#: Gauss-Seidel rounds of the joint two-motor solve (each coupled axis re-inverted with
#: the other axis's latest commands)
JOINT_ROUNDS = 3


def _solve_coupled(setup: dict, current: dict) -> dict:
    """Coupled candidates (axis -> CompensationResult) solved jointly: each coupled axis
    is inverted given the other motor's latest commands (``current``: axis -> (signed
    commands, signed start counts)), :data:`JOINT_ROUNDS` rounds, yaw first (its first
    round given the other axis's best uncoupled commands)."""
    out = {}
    for _ in range(JOINT_ROUNDS):
        for axis, a in setup.items():
            if a["coupled"] is None:
                continue
            other = next(x for x in setup if x != axis)
            vo, vo0 = current[other]
            res = _invert_axis(a["coupled_model"], a["goal"], a["t"], a["lo"], a["hi"],
                               a["rate"], a["v0"], vo, vo0, a["hist"],
                               _other_hist(setup, axis))  # fmt: skip
            out[axis] = res
            current[axis] = (a["sign"] * res.commands, a["sign"] * a["v_entry"])
    return out


def rank_models(
    candidates: dict, record: dict, models: dict | None = None, v0: float = 0.0
) -> list[dict]:
    """Ranking of the models that can serve this target (best first), by the predicted
    tracking error (:func:`_score`: the model's own error on this target and its
    held-out fit error in quadrature), multiplied by :data:`STEP_PENALTY` for models
    whose output steps where the target passes (more than :data:`STEP_SHARE` of the
    samples flagged ``output_step`` or ``spike_removed``): ``rank_score_deg``. ``candidates``: kind -> CompensationResult; ``models`` (kind ->
    model) and ``v0`` (start input): the paper EGPI's stage switches that step the
    predicted output (:func:`family_switch_steps`) count as output steps too."""
    rows = []
    for kind, res in candidates.items():
        s = res.summary()
        stepped = res.flags["output_step"] | res.flags["spike_removed"]
        if models is not None and kind in models:
            stepped = stepped | family_switch_steps(models[kind], res, v0)
        steps = int(stepped.sum())
        hold = holdout_rmse(record["models"][kind])
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


def _rank_alternatives(a: dict, forced: str) -> None:
    """Add the dataset's other (uncoupled, fitted) invertible models to ``a``'s candidates
    when the ``--model``-forced one steps, so the warning can name those that do not; a
    model that cannot be loaded or inverted is left out."""
    for kind in a["record"].get("models", {}):
        if kind == forced or kind not in INVERSE_KINDS or kind in COUPLED_KINDS:
            continue
        try:
            fitted = load_model(a["doc"], a["record"], kind, a["path"], None)
            a["candidates"][kind] = _invert_axis(
                fitted, a["goal"], a["t"], a["lo"], a["hi"], a["rate"], a["v0"], hist=a["hist"]
            )
        except CalibError:
            continue
        a["models"][kind] = fitted


def compensate_files(
    fit_paths: Sequence[str | Path],
    datasets: Sequence[str] | None,
    target: str | Path,
    out: str | Path,
    config=None,
    model: str | None = None,
    max_counts_per_s: float | None = None,
    start_counts: float | None = None,
    model_file: str | Path | None = None,
    time_unit_s: float | None = None,
    conditioning: str | None = None,
    history: str | Path | None = None,
) -> dict[str, Any]:
    """Command body of ``i2ris-calib compensate``; returns the compensate.json document.

    Parameters
    ----------
    fit_paths : sequence of path
        fit.json file(s), one per axis; each dataset is looked up in the one whose axis
        matches.
    datasets : sequence of str or None
        ``yaw+``, ``yaw-``, ``yaw±``, ``pitch+``, ...: at most one per axis. Empty: per
        axis of the target with a fit.json, :func:`choose_dataset`.
    target : path
        Target CSV (``time_s``, ``<axis>_deg`` per axis).
    out : path
        COMMANDS.csv to write; compensate.json is written beside it.
    model : str, optional
        Force a model kind; default: the model fit.json recommends (:func:`_choose_model`).
    max_counts_per_s : float, optional
        Motor rate limit (counts/s; ``inf``: none); default ``[compensate]
        max_counts_per_s``, else the fit's fastest input move (:func:`rate_limit`).
    start_counts : float, optional
        Signed encoder counts before the first target sample; default 0 (rest), or the
        fitted range's nearest end when 0 is outside it. Outside the fitted input range:
        refused.
    model_file : path, optional
        final_model.json (``--model diagnosed``); must match the fit's diagnosed model.
    time_unit_s : float, optional
        Seconds per unit of the target's ``time_s`` (default ``[compensate]
        time_unit_s``, else 1).
    conditioning : {"auto", "sweep", "none"}, optional
        The start state (:func:`start_state`): ``sweep`` prepends a conditioning sweep
        (:func:`~i2ris_calib.compensation.safety.conditioning_sweep`) to the commands,
        ``none`` starts from the model's state at rest (or after ``history``), ``auto``
        sweeps when the model's state at rest is not identified; default
        ``[compensate] conditioning`` (``auto``; also in ``run``).
    history : path, optional
        CSV of the commands sent before (``enc_<axis>`` per compensated axis, oldest
        first, from rest; e.g. an earlier COMMANDS.csv or the encoder log): the model
        starts from the state they leave; the start counts are its last row.
    """
    cc = getattr(config, "compensate", None)
    datasets, unit, conditioning = _checked_options(
        fit_paths, datasets, model, time_unit_s, conditioning, history, cc
    )
    extra = [*([model_file] if model_file else []), *([history] if history is not None else [])]
    out = _claimed_output(out, [*fit_paths, target, *extra])
    # one compensate at a time writes this COMMANDS.csv and the compensate.json beside it
    with output_lock(out, out.with_name("compensate.json"), command="compensate"):
        return _compensate_into(
            fit_paths, target, out, config, datasets, model, max_counts_per_s, start_counts,
            model_file, unit, conditioning, history, extra,
        )  # fmt: skip


def _compensate_into(
    fit_paths, target, out: Path, config, datasets, model, max_counts_per_s, start_counts,
    model_file, unit, conditioning, history, extra,
) -> dict:  # fmt: skip
    """The body of :func:`compensate_files` once ``out`` is claimed and locked."""
    docs = [(Path(p), read_fit_json(p)) for p in fit_paths]
    _check_one_fit_per_axis(docs)
    given = bool(datasets)
    if not datasets:
        datasets = _chosen_datasets(docs, target, unit)
    axes = [n[:-1] for n in datasets]
    if len(set(axes)) != len(axes) and given:
        raise CalibError("give at most one --dataset per axis (the direction of each motor)")
    frame = read_target(target, axes, unit)
    t = frame["time_s"].to_numpy()
    configured = float(getattr(getattr(config, "compensate", None), "max_counts_per_s", 0.0) or 0.0)
    setup = {
        axis: _axis_setup(name, axis, docs, frame, start_counts, max_counts_per_s, configured)
        for name, axis in zip(datasets, axes, strict=True)
    }
    _check_ramp_lengths(setup, t)
    past = None if history is None else _history_start(setup, history, start_counts)
    _prepend_start(setup, start_state(setup, conditioning, history), past, t)
    _choose_models(setup, t, target, model, None if model_file is None else Path(model_file))
    for a in setup.values():
        a.update(history_file=None if history is None else str(history))
    table, axes_doc = _outputs(setup, frame, t, target, unit)
    inputs = [*(p for p, _ in docs), Path(target), *(Path(x) for x in extra)]
    doc_out = {
        "schema": SCHEMA,
        "commands_csv": out.name,
        "method": METHOD_NOTE,
        "axes": axes_doc,
        "provenance": provenance(inputs, config),
    }
    _write_outputs(out, table, doc_out)
    return doc_out


def _claimed_output(out, inputs: list) -> Path:
    """``out`` as a Path after checking it is a .csv the tool may write (not one of the
    ``inputs``; compensate.json beside it likewise)."""
    out = Path(out)
    if out.suffix.lower() != ".csv":
        raise CalibError(f"--out {out}: give the COMMANDS.csv file to write (ending in .csv)")
    claim_output_file(out, inputs, companions=[out.with_name("compensate.json")])
    return out


def _choose_models(setup: dict, t: np.ndarray, target, model: str | None, mf) -> None:
    """Each axis's candidate inversions (jointly for coupled models), the model chosen
    (``model`` forces one kind) and its result, into ``setup``'s axis records."""
    axes = list(setup)
    for axis, a in setup.items():
        _add_candidates(a, axis, axes, model, mf, target)
    if any(a["coupled"] for a in setup.values()):
        _add_joint_candidates(setup, t, target)
    for a in setup.values():
        _choose_model(a, model)
    _reinvert_coupled_choice(setup, t)
    for a in setup.values():
        a.update(
            res=a["candidates"][a["kind"]], model=a["models"][a["kind"]], forced=model is not None
        )


def _write_outputs(out: Path, table, doc: dict) -> None:
    """COMMANDS.csv and compensate.json beside it, both or neither: compensate.json is
    renamed into place after the CSV. ``time_s`` is written exactly (the shortest text
    that reads back to the same float): an epoch clock (~1.7e9 s) keeps its fraction of
    a second; the other numbers with 10 significant digits."""
    table = table.assign(time_s=[repr(float(x)) for x in table["time_s"].to_numpy()])
    with atomic_path(out.with_name("compensate.json")) as tmp_json:
        write_json(tmp_json, doc)
        with atomic_path(out) as tmp_csv:
            table.to_csv(tmp_csv, index=False, float_format="%.10g")


def _checked_options(fit_paths, datasets, model, time_unit_s, conditioning, history, cc):
    """(datasets with ``+-`` read as ``±``, seconds per target time unit, conditioning)
    after checking the options that need no file read; a bad one raises a one-line
    :class:`CalibError`."""
    if model is not None and model not in KINDS:
        raise CalibError(f"--model must be one of {', '.join(KINDS)}, got '{model}'")
    if not fit_paths:
        raise CalibError("give at least one fit.json")
    datasets = [d.replace("+-", "±") for d in (datasets or [])]
    for name in datasets:
        if name not in DATASETS:
            raise CalibError(f"--dataset must be one of {', '.join(DATASETS)}, got '{name}'")
    unit = time_unit_s if time_unit_s is not None else getattr(cc, "time_unit_s", 1.0)
    if conditioning is None:
        conditioning = getattr(cc, "conditioning", "auto")
    if conditioning not in CONDITIONING:
        raise CalibError(
            f"--conditioning must be one of {', '.join(CONDITIONING)}, got '{conditioning}'"
        )
    if history is not None and not Path(history).is_file():
        raise CalibError(
            f"--history {history}: file not found (a CSV of the commands sent before, "
            "enc_<axis> per axis)"
        )
    if not (np.isfinite(unit) and unit > 0):
        raise CalibError(f"--time-unit-s {unit:g}: give seconds per unit of time_s (> 0)")
    return datasets, unit, conditioning


def _check_one_fit_per_axis(docs: list) -> None:
    """CalibError when a fit.json is given twice, or two fit.json files fit one axis
    (compensate takes one fit per motor)."""
    seen: dict[str, Path] = {}
    for path, doc in docs:
        axis = str(doc.get("axis"))
        if axis not in seen:
            seen[axis] = path
            continue
        first = seen[axis]
        if first.resolve() == path.resolve():
            raise CalibError(
                f"{path} is given twice; give each fit.json once (one per axis: a yaw fit "
                "and a pitch fit)"
            )
        raise CalibError(
            f"{first} and {path} are both {axis} fits; give one fit.json per axis (a yaw "
            "fit and a pitch fit)"
        )


def _chosen_datasets(docs: list, target, unit: float) -> list[str]:
    """The datasets ``--dataset`` omitted: one per axis with a fit.json and an
    ``<axis>_deg`` column in the target (:func:`choose_dataset`)."""
    head = read_csv_header(target, "target file not found (a CSV with time_s and <axis>_deg)")
    present = [d.get("axis") for _, d in docs if f"{d.get('axis')}_deg" in head]
    if not present:
        raise CalibError(
            f"{target}: no <axis>_deg column for the fit(s) given (axes "
            f"{', '.join(str(d.get('axis')) for _, d in docs)}); give the target's angle "
            "column(s) or --dataset"
        )
    frame = read_target(target, present, unit)
    names = []
    for axis in present:
        path, doc = next((p, d) for p, d in docs if d.get("axis") == axis)
        names.append(choose_dataset(doc, axis, frame[f"{axis}_deg"].to_numpy(), path))
    return names


def _start_counts(name: str, path, lo: float, hi: float, sign: float, start_counts):
    """(start input in the model's convention, where it comes from): ``--start-counts``
    (refused outside the fitted range ``lo..hi``), else rest at 0 or the range's end
    nearest 0."""
    if start_counts is None:
        v0 = float(np.clip(0.0, lo, hi))
        if v0 != 0.0:
            return v0, "default (the fitted range's end nearest 0)"
        return v0, "default (rest at 0)"
    v0 = sign * float(start_counts)
    if not lo <= v0 <= hi:
        rng = sorted((sign * lo + 0.0, sign * hi + 0.0))
        raise CalibError(
            f"--start-counts {start_counts:g} is outside the {name} fit's input range "
            f"{rng[0]:g}..{rng[1]:g} counts ({path}); give the encoder counts the "
            "motor rests at, inside that range"
        )
    return v0, "--start-counts"


def _axis_setup(name, axis, docs, frame, start_counts, max_counts_per_s, configured) -> dict:
    """One axis's inversion set-up: its fit.json and dataset record, sign (-1 for a
    ``-`` dataset), input range, rate limit, start counts and goal (the target in the
    model's convention)."""
    found = [(p, d) for p, d in docs if d.get("axis") == axis]
    if not found:
        raise CalibError(
            f"no fit.json for the {axis} axis among {', '.join(str(p) for p, _ in docs)}; "
            f"give the {axis} fit.json too"
        )
    path, doc = found[0]
    record = dataset_record(doc, name, path)
    sign = -1.0 if name.endswith("-") else 1.0
    lo, hi = (float(x) for x in record["input_range_counts"])
    if not name.endswith("±"):
        lo = min(lo, 0.0)
    rate, rate_source, rate_warn = rate_limit(record, max_counts_per_s, configured, hi - lo)
    v0, start_source = _start_counts(name, path, lo, hi, sign, start_counts)
    return {
        "name": name, "path": path, "doc": doc, "record": record, "sign": sign, "lo": lo,
        "hi": hi, "rate": rate, "rate_source": rate_source, "rate_warn": rate_warn,
        "v0": v0, "start_source": start_source,
        "goal": sign * frame[f"{axis}_deg"].to_numpy(), "t": frame["time_s"].to_numpy(),
    }  # fmt: skip


def _check_ramp_lengths(setup: dict, t: np.ndarray) -> None:
    """CalibError, before any ramp is built, when an axis's rate limit is so slow that
    a ramp across its fitted input range (the entry ramp or a leg of the conditioning
    sweep) would take more than :data:`MAX_RAMP_COMMANDS` commands at the target's
    sample interval (``--max-counts-per-s 1e-9`` asked for 610 TiB)."""
    dt0 = float(t[1] - t[0]) if t.size > 1 else 1.0
    for a in setup.values():
        span = a["hi"] - a["lo"]
        need = ramp_commands(span, a["rate"], dt0)
        if need > MAX_RAMP_COMMANDS:
            rng = sorted((a["sign"] * a["lo"] + 0.0, a["sign"] * a["hi"] + 0.0))
            raise CalibError(
                f"rate limit {a['rate']:g} counts/s ({a['rate_source']}) is too slow for the "
                f"{a['name']} fit's input range {rng[0]:g}..{rng[1]:g} counts: a ramp across "
                f"it at one command every {dt0:g} s (the target's interval) would take "
                f"{need:.3g} commands (at most {MAX_RAMP_COMMANDS:.0e}); give a rate limit of "
                f"at least {span / (MAX_RAMP_COMMANDS * dt0):.3g} counts/s"
            )


def _history_start(setup: dict, history, start_counts) -> dict:
    """The ``--history`` commands (axis -> model-convention inputs, oldest first); each
    axis starts at the history's last row (``--start-counts``, if given, must be it)."""
    past = read_history(history, setup)
    for axis, a in setup.items():
        last = float(past[axis][-1])
        if start_counts is not None and last != a["v0"]:
            raise CalibError(
                f"--start-counts {start_counts:g} is not the history's last {axis} counts "
                f"{a['sign'] * last:g} ({history}); give one of them"
            )
        a["v0"], a["start_source"] = last, f"--history (its last row, {history})"
    return past


def _prepend_start(setup: dict, start: dict, past: dict | None, t: np.ndarray) -> None:
    """Add to each axis the inputs before its entry ramp: ``hist`` (the history, then the
    conditioning sweep padded to the longest axis's; None when neither), ``n_pre`` (the
    history's length), ``v_entry`` (where the entry ramp starts), ``start`` and
    ``sweep_ends`` (the sweep's turning counts, robot's sign)."""
    dt0 = float(t[1] - t[0]) if t.size > 1 else 1.0
    sweeps = {
        axis: conditioning_sweep(
            a["v0"], a["lo"], a["hi"], a["rate"], dt0, 1.0, last=sweep_last(a["goal"])
        )
        if start["sweep"]
        else np.zeros(0)
        for axis, a in setup.items()
    }  # fmt: skip
    n_cond = max(x.size for x in sweeps.values())
    for axis, a in setup.items():
        cond = np.concatenate((np.full(n_cond - sweeps[axis].size, a["v0"]), sweeps[axis]))
        pre = past[axis] if past is not None else np.array([a["v0"]])
        a["hist"] = np.concatenate((pre, cond)) if (past is not None or n_cond) else None
        a["n_pre"] = pre.size
        a["v_entry"] = float(a["hist"][-1]) if a["hist"] is not None else a["v0"]
        a["start"] = start
        ends = (a["hi"], a["lo"]) if sweep_last(a["goal"]) == "lo" else (a["lo"], a["hi"])
        a["sweep_ends"] = [float(a["sign"] * x) + 0.0 for x in ends] if sweeps[axis].size else None


def _kinds_to_invert(a: dict, axis: str, axes: list, model: str | None, mf) -> list[str]:
    """The model kinds of ``a``'s dataset to invert: ``--model``'s (a coupled one needs
    the other axis), else every invertible fitted kind (coupled ones only with both
    axes; ``diagnosed`` with a model file)."""
    name, path, record = a["name"], a["path"], a["record"]
    other = next((x for x in axes if x != axis), None)
    if model is not None:
        if model in COUPLED_KINDS and other is None:
            o = "pitch" if axis == "yaw" else "yaw"
            raise CalibError(
                f"--model {model} for {name} needs the {o} motor's commands: give the {o} "
                f"fit.json and a {o}_deg target column too (or another --model)"
            )
        return [model]
    kinds = [k for k in record.get("models", {}) if k in INVERSE_KINDS]
    if other is None:  # no other motor's commands: coupled models left out
        kinds = [k for k in kinds if k not in COUPLED_KINDS]
    if DIAGNOSED in record.get("models", {}) and mf is not None:
        kinds.append(DIAGNOSED)
    if not kinds:
        raise CalibError(
            f"{path} [{name}]: none of its models ({', '.join(record.get('models', {}))}) "
            f"can be inverted; compensate inverts {', '.join(INVERSE_KINDS)} and "
            "diagnosed models (coupled ones with both axes)"
        )
    return kinds


def _add_candidates(a: dict, axis: str, axes: list, model: str | None, mf, target) -> None:
    """Load the axis's models to invert and invert the uncoupled ones: adds
    ``candidates`` (kind -> CompensationResult), ``models`` (kind -> model), ``coupled``
    and ``coupled_model`` (the coupled kind, solved jointly later, or None)."""
    candidates, models = {}, {}
    coupled_kind, coupled_model = None, None
    for kind in _kinds_to_invert(a, axis, axes, model, mf):
        fitted = load_model(a["doc"], a["record"], kind, a["path"], mf)
        models[kind] = fitted
        if kind in COUPLED_KINDS:  # solved jointly with the other axis
            coupled_kind, coupled_model = kind, fitted
            continue
        try:
            candidates[kind] = _invert_axis(
                fitted, a["goal"], a["t"], a["lo"], a["hi"], a["rate"], a["v0"], hist=a["hist"]
            )
        except CalibError as exc:
            raise CalibError(f"{target} [{a['name']}] {kind}: {exc}") from None
    a.update(candidates=candidates, models=models, coupled=coupled_kind,
             coupled_model=coupled_model)  # fmt: skip


def _add_joint_candidates(setup: dict, t: np.ndarray, target) -> None:
    """Add the coupled candidates, solved jointly (:func:`_solve_coupled`) from each
    axis's best uncoupled commands (or a hold at its entry counts)."""
    current = {}
    for axis, a in setup.items():
        best = (
            rank_models(a["candidates"], a["record"], a["models"], a["v0"])[0]["model"]
            if a["candidates"]
            else None
        )
        cmds = a["candidates"][best].commands if best else np.full(t.size, a["v_entry"])
        current[axis] = (a["sign"] * cmds, a["sign"] * a["v_entry"])
    try:
        joint = _solve_coupled(setup, current)
    except CalibError as exc:
        raise CalibError(f"{target} (coupled, both axes): {exc}") from None
    for axis, res in joint.items():
        setup[axis]["candidates"][setup[axis]["coupled"]] = res


def _choose_model(a: dict, model: str | None) -> None:
    """Rank the axis's candidates (:func:`rank_models`, information: the predicted
    tracking error on this target) and choose ``--model``, else the model fit.json
    recommends (its ``decision``, :func:`~i2ris_calib.io.fit_records.decided_kind`; when
    that one cannot be inverted here, the next of the decision's ranking that can, and
    ``substitute`` says which and why): adds ``kind``, ``ranking`` (each row marked
    ``chosen``), ``recommended`` and ``substitute``."""
    ranking = rank_models(a["candidates"], a["record"], a["models"], a["v0"])
    if model is not None and not ranking[0]["continuous"] and model not in COUPLED_KINDS:
        _rank_alternatives(a, model)  # the forced model steps: name the others
        ranking = rank_models(a["candidates"], a["record"], a["models"], a["v0"])
    decision = record_decision(a["record"])
    a["recommended"] = decision.model
    a["substitute"] = None
    if model is None:
        kind, note = decided_kind(a["record"], lambda k: _refusal(a, k),
                                  f"{a['path']} [{a['name']}]")  # fmt: skip
        a["substitute"] = note or None
    else:
        kind = model
    for r in ranking:
        r["chosen"] = r["model"] == kind
    a["kind"] = kind
    a["ranking"] = ranking


def _refusal(a: dict, kind: str) -> str | None:
    """Why compensate cannot invert ``kind`` for axis ``a`` (None: it can)."""
    if kind in a["candidates"] or (kind in COUPLED_KINDS and kind == a.get("coupled")):
        return None
    if kind == DIAGNOSED:
        return "the diagnosed model needs its final_model.json (--model-file)"
    if kind not in INVERSE_KINDS:
        return f"{kind} has no inverse (compensate inverts {', '.join(INVERSE_KINDS)})"
    if kind in COUPLED_KINDS:
        return f"{kind} reads the other motor: give both axes' fit.json and target columns"
    return f"{kind} could not be inverted"


def _reinvert_coupled_choice(setup: dict, t: np.ndarray) -> None:
    """Invert a chosen coupled model once more, given the other axis's final commands."""
    for axis, a in setup.items():
        if a["kind"] in COUPLED_KINDS:
            other = next(x for x in setup if x != axis)
            o = setup[other]
            vo = o["sign"] * o["candidates"][o["kind"]].commands
            a["candidates"][a["kind"]] = _invert_axis(
                a["models"][a["kind"]], a["goal"], t, a["lo"], a["hi"], a["rate"], a["v0"],
                vo, o["sign"] * o["v_entry"], a["hist"], _other_hist(setup, axis),
            )  # fmt: skip


def output_step_warning(a: dict, summ: dict, stepped: np.ndarray | None = None) -> str | None:
    """The line saying the chosen model's predicted output steps where the target passes
    (more than :data:`STEP_SHARE` of the samples flagged ``output_step`` or
    ``spike_removed``; ``stepped``: those samples, shape (n,), for the largest miss
    there), naming the continuous models of the ranking with their predicted tracking
    error (``score_deg``, the chosen model's too). When the ranking chose the stepping
    model, the smooth ones track more than :data:`STEP_PENALTY` x worse: they are named
    as the choice for when smoothness matters more, not as the better model. None when
    the model does not step."""
    n = summ["flags"]["output_step"] + summ["flags"]["spike_removed"]
    if n <= STEP_SHARE * summ["n_samples"]:
        return None
    kind = a["kind"]
    where = " at v_f" if kind in STEP_AT_VF_KINDS else ""
    res = a["res"]
    miss = ""
    if stepped is not None and stepped.any():
        err = np.abs(res.predicted_deg - res.target_deg)[stepped]
        miss = f", missing the target by up to {float(np.max(err)):.3g} deg there"
    smooth = [r for r in a["ranking"] if r["continuous"] and r["model"] != kind]
    mine = next((r["score_deg"] for r in a["ranking"] if r["model"] == kind), None)
    if smooth:
        names = " or ".join(f"{r['model']} ({r['score_deg']:.3g} deg)" for r in smooth)
        cost = "" if mine is None else f"; {kind} {mine:.3g} deg"
        if a.get("forced"):
            alt = (
                f"{names} track it without steps (predicted tracking error{cost}): "
                f"--model {smooth[0]['model']}"
            )
        else:
            alt = (
                f"{names} track it without steps (predicted tracking error{cost}); "
                f"--model {smooth[0]['model']} if smooth output matters more"
            )
    elif a.get("forced"):
        alt = "leave out --model to rank the other models on this target"
    else:
        alt = "no other model of the fit tracks it without steps"
    return (
        f"{kind} steps{where} where the target passes ({n} samples flagged output_step"
        f"{' or spike_removed' if summ['flags']['spike_removed'] else ''}{miss}); {alt}"
    )


def _outputs(results: dict, frame: pd.DataFrame, t: np.ndarray, target, unit: float):
    """(COMMANDS.csv table, compensate.json ``axes``): the conditioning sweep (common
    length, ``a["hist"]`` after the known history's ``a["n_pre"]`` inputs), then every
    axis's entry ramp padded to the longest (holding the sweep's end, or the start
    counts, before its own ramp), then the target's samples. The predicted angles are
    the model run over the whole sequence (history included) from rest."""
    n_entry = max(a["res"].entry_commands.size for a in results.values())
    first = next(iter(results.values()))
    n_pre = first["n_pre"] if first["hist"] is not None else 0
    n_cond = first["hist"].size - n_pre if first["hist"] is not None else 0
    dt0 = float(t[1] - t[0]) if t.size > 1 else 1.0
    t_full = np.concatenate((t[0] - dt0 * np.arange(n_pre + n_cond + n_entry, 0, -1), t))
    t_all = t_full[n_pre:]
    seqs = _command_sequences(results, n_entry)
    cols: dict[str, Any] = {"time_s": t_all}
    reach_all = np.ones(t_all.size, dtype=bool)
    flags_by_axis: dict[str, list[list[str]]] = {}
    axes_doc: dict[str, Any] = {}
    preds, reach_cols = {}, {}
    for axis, a in results.items():
        res, sign = a["res"], a["sign"]
        y = _predicted(results, axis, seqs, t_full, n_pre)
        seq = seqs[axis][n_pre:]
        cols[f"enc_{axis}"] = np.rint(sign * seq).astype(np.int64)
        preds[f"predicted_{axis}_deg"] = sign * y
        ok = np.concatenate((np.ones(n_cond + n_entry, dtype=bool), res.reachable))
        reach_all &= ok
        reach_cols[f"reachable_{axis}"] = ok.astype(int)
        fl = dict(res.flags)
        fl["output_step"] = fl["output_step"] | family_switch_steps(a["model"], res, a["v0"])
        flags_by_axis[axis] = (
            [["conditioning"] for _ in range(n_cond)]
            + [["entry"] for _ in range(n_entry)]
            + [[f for f in FLAG_NAMES if fl[f][i]] for i in range(t.size)]
        )
        sent = np.concatenate(([seqs[axis][n_pre - 1]] if n_pre else [], seq))
        t_sent = np.concatenate(([t_full[n_pre - 1]] if n_pre else [], t_all))
        axes_doc[axis] = _axis_doc(
            a, frame[f"{axis}_deg"].to_numpy(), t, fl, _max_rate(sent, t_sent), n_cond, n_pre,
            dt0, unit,
        )  # fmt: skip
    cols.update(preds)
    if len(results) > 1:
        cols.update(reach_cols)
    cols["reachable"] = reach_all.astype(int)
    cols["flags"] = _flag_column(flags_by_axis, prefix=len(results) > 1)
    return pd.DataFrame(cols), axes_doc


def _command_sequences(results: dict, n_entry: int) -> dict[str, np.ndarray]:
    """Axis -> every input the model sees (model convention): history and conditioning
    sweep, the entry ramp padded to ``n_entry`` by holding its start, the commands."""
    seqs = {}
    for axis, a in results.items():
        ramp = a["res"].entry_commands
        hist = a["hist"] if a["hist"] is not None else np.zeros(0)
        seqs[axis] = np.concatenate(
            (hist, np.full(n_entry - ramp.size, a["v_entry"]), ramp, a["res"].commands)
        )
    return seqs


def _predicted(results: dict, axis: str, seqs: dict, t_full: np.ndarray, n_pre: int):
    """The axis's model output (deg, model convention) over its sequence from the
    conditioning sweep on (shape ``(seqs[axis].size - n_pre,)``): run from rest at the
    history's first input, or from the start counts; a coupled model given the other
    axis's sequence."""
    a = results[axis]
    other = next((x for x in results if x != axis), None)
    vo = vo0 = None
    if other is not None and a["kind"] in COUPLED_KINDS:
        vo = results[other]["sign"] * seqs[other]
        vo0 = results[other]["sign"] * results[other]["v0"]
    with deferred():
        if a["hist"] is not None:  # from rest at the history's first input
            return forward(a["model"], seqs[axis], t_full, None, v_other=vo)[n_pre:]
        return forward(
            a["model"], seqs[axis], t_full[n_pre:], a["v0"], v_other=vo, v_other_initial=vo0
        )


def _max_rate(sent: np.ndarray, t_sent: np.ndarray) -> float:
    """The fastest command move (counts/s) over consecutive commands sent; 0 for one."""
    return float(np.max(np.abs(np.diff(sent)) / np.diff(t_sent))) if sent.size > 1 else 0.0


def _axis_doc(a, target_deg, t, fl, max_rate, n_cond, n_pre, dt0, unit) -> dict:
    """compensate.json's record of one axis (docs/compensate.md): dataset, model and its
    ranking, limits, start state, the result's summary with every flag counted
    (``fl``: flag -> bool per target sample), warnings."""
    res, sign, rec = a["res"], a["sign"], a["record"]
    ramp = res.entry_commands
    summ = res.summary()
    summ["flags"] = {name: int(f.sum()) for name, f in fl.items()}
    summ.pop("n_history", None)
    summ["max_command_rate_per_s"] = max_rate
    step_warn = output_step_warning(a, summ, fl["output_step"] | fl["spike_removed"])
    bad = np.flatnonzero(~res.reachable)
    reach = reachable_angles(a["model"], (a["lo"], a["hi"]), sign)
    warn = range_warning(
        a["name"], a["kind"], target_deg, reach, res.tol_deg, float(res.reachable.mean())
    )
    return {
        "dataset": a["name"],
        "fit_json": str(a["path"]),
        "model": a["kind"],
        "model_choice": "--model" if a.get("forced") else "fit decision",
        "recommended_model": a.get("recommended"),
        "substitute": a.get("substitute"),
        "ranking": a["ranking"],
        "params": rec["models"][a["kind"]]["params"],
        "input_range_counts": [a["lo"], a["hi"]],
        "max_counts_per_s": a["rate"] if np.isfinite(a["rate"]) else None,
        "max_counts_per_s_source": a["rate_source"],
        "recording_max_rate_counts_per_s": rec.get("max_input_rate_counts_per_s"),
        "start_counts": float(sign * a["v0"]) + 0.0,
        "start_counts_source": a["start_source"],
        "start_state": a["start"]["method"],
        "start_state_reason": a["start"]["reason"],
        "fit_initial_state": _initial_state_text(rec),
        "n_conditioning": int(n_cond),
        "conditioning_s": float(n_cond * dt0),
        "conditioning_counts": a["sweep_ends"],
        "history_file": a["history_file"],
        "n_history": int(n_pre) if a["history_file"] else 0,
        "entry_from_counts": float(sign * a["v_entry"]) + 0.0,
        "time_unit_s": unit,
        "delay_s": res.delay_s,
        "tol_deg": res.tol_deg,
        **summ,
        "n_entry": int(ramp.size),
        "entry_s": float(ramp.size * dt0),
        "unreachable_first_times_s": [float(t[i]) for i in bad[:20]],
        "status_codes": {str(k): v for k, v in STATUS_NAMES.items()},
        "reachable_deg": list(reach),
        "warnings": [w for w in (a["rate_warn"], warn, step_warn) if w is not None],
    }


def _initial_state_text(record: dict) -> str | None:
    """fit.json's sentence on how its recording started (the first model's
    ``initial_state.text``; "at rest" when none was estimated; None when not recorded)."""
    known = _virgin_identified(record)
    if known is None:
        return None
    if known:
        return "the recording started at rest"
    st = next(m["initial_state"] for m in record["models"].values() if m.get("initial_state"))
    return str(st.get("text", "initial state estimated"))


def _start_text(rec: dict) -> str:
    """The summary line's start-state clause (empty for a plain start from rest)."""
    method = rec.get("start_state", "rest")
    if method == "rest":
        return f"start: at rest ({rec.get('start_state_reason', '')}); "
    parts = []
    if rec.get("n_history"):
        parts.append(f"history of {rec['n_history']} commands")
    if rec.get("n_conditioning"):
        ends = rec.get("conditioning_counts") or []
        path = " -> ".join(f"{x:g}" for x in [rec["start_counts"], *ends])
        parts.append(
            f"conditioning sweep {rec['n_conditioning']} samples ({rec['conditioning_s']:.3g} s, "
            f"{path} counts; {rec['start_state_reason']})"
        )
    return "start: " + ", then ".join(parts) + "; " if parts else ""


def summary_lines(doc: dict) -> list[str]:
    """The terminal summary of a compensate.json document: per axis the model (and
    why), the predicted error, every flag counted, the rate limit and where it comes
    from."""
    lines = []
    for rec in doc["axes"].values():
        fl = ", ".join(f"{k} {v}" for k, v in rec["flags"].items() if v) or "none"
        rate = rec["max_counts_per_s"]
        rate_txt = "no rate limit" if rate is None else (
            f"rate limit {rate:g} counts/s ({rec['max_counts_per_s_source']}; commands "
            f"reach {rec['max_command_rate_per_s']:.4g})"
        )  # fmt: skip
        if rec["model_choice"] == "--model":
            why = "forced by --model"
        elif rec.get("substitute"):
            why = f"instead of the recommended {rec.get('recommended_model')}"
        else:
            why = "recommended by fit.json"
        start = _start_text(rec)
        lines.append(
            f"{rec['dataset']} ({rec['model']}, {why}): predicted RMSE {rec['rmse_deg']:.4f} "
            f"deg, max {rec['max_abs_err_deg']:.4f} deg, {rec['n_unreachable']} of "
            f"{rec['n_samples']} samples unreachable; flags: {fl}; {rate_txt}; {start}entry "
            f"{rec['n_entry']} samples from {rec.get('entry_from_counts', rec['start_counts']):g} "
            "counts"
            + "".join(f"; {w}" for w in rec.get("warnings", []) if "where the target passes (" in w)
        )
        if rec.get("substitute"):
            lines.append(f"note: {rec['substitute']}")
    return lines
