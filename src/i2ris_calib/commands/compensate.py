"""``i2ris-calib compensate``: fit.json + target CSV -> COMMANDS.csv + compensate.json.

Reads the files, plans each axis and chooses its model with the compensation stage
(:mod:`i2ris_calib.compensation.plan`, :mod:`~i2ris_calib.compensation.choice`,
:mod:`~i2ris_calib.compensation.outcome`), writes what it sends and predicts. Formats
are documented in docs/compensate.md (schema ``i2ris-calib.compensate/1``).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from i2ris_calib.compensation import STATUS_NAMES
from i2ris_calib.compensation.choice import AxisChoice, choose_models
from i2ris_calib.compensation.config import CONDITIONING
from i2ris_calib.compensation.outcome import AxisOutcome, Outcome, outcome
from i2ris_calib.compensation.plan import (
    AxisPlan,
    after_history,
    alternative_kinds,
    axis_plan,
    check_ramp_lengths,
    choose_dataset,
    kinds_to_invert,
    start_state,
    with_start,
    with_target,
)
from i2ris_calib.errors import CalibError
from i2ris_calib.hysteresis.kinds import DIAGNOSED
from i2ris_calib.hysteresis.registry import INVERSE_KINDS
from i2ris_calib.io.atomic import atomic_path, write_json
from i2ris_calib.io.csv_file import read_csv_header
from i2ris_calib.io.fit import read_fit_json
from i2ris_calib.io.fit_records import (
    dataset_names,
    dataset_record,
    fitted_dataset,
    load_model,
    virgin_identified,
)
from i2ris_calib.io.outputs import claim_output_file, output_lock
from i2ris_calib.io.provenance import provenance
from i2ris_calib.io.target_csv import read_history, read_target

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
        axis of the target with a fit.json,
        :func:`~i2ris_calib.compensation.plan.choose_dataset`.
    target : path
        Target CSV (``time_s``, ``<axis>_deg`` per axis).
    out : path
        COMMANDS.csv to write; compensate.json is written beside it.
    model : str, optional
        Force a model kind; default: the model fit.json recommends
        (:func:`~i2ris_calib.compensation.choice.choose_models`).
    max_counts_per_s : float, optional
        Motor rate limit (counts/s; ``inf``: none); default ``[compensate]
        max_counts_per_s``, else the fit's fastest input move
        (:func:`~i2ris_calib.compensation.rate.rate_limit`).
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
        The start state (:func:`~i2ris_calib.compensation.plan.start_state`): ``sweep`` prepends a conditioning sweep
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
    records, plans = {}, {}
    for name, axis in zip(datasets, axes, strict=True):
        path, doc = _fit_of_axis(docs, axis)
        records[axis] = (path, doc, dataset_record(doc, name, path))
        plan = axis_plan(fitted_dataset(records[axis][2], path), max_counts_per_s, configured)
        plans[axis] = with_target(plan, frame[f"{axis}_deg"].to_numpy(), t, start_counts)
    check_ramp_lengths(plans, t)
    past = None
    if history is not None:
        past = read_history(history, plans)  # in each plan's convention and range
        plans = after_history(plans, past, start_counts, str(history))
    plans = with_start(plans, start_state(plans, conditioning, history is not None), past, t)
    mf = None if model_file is None else Path(model_file)
    models = {axis: _models(records[axis], kinds_to_invert(p, len(plans) > 1, model, mf is not None), mf)
              for axis, p in plans.items()}  # fmt: skip
    alternatives = None
    if model is not None:
        alternatives = {axis: _loadable(records[axis], alternative_kinds(p.fit, model))
                        for axis, p in plans.items()}  # fmt: skip
    choices = choose_models(plans, models, model, str(target), alternatives)
    result = outcome(plans, choices, t)
    axes_doc = {
        axis: _axis_doc(a, choices[axis], result.axes[axis], result, records[axis][2], history, t, unit)
        for axis, a in plans.items()
    }  # fmt: skip
    inputs = [*(p for p, _ in docs), Path(target), *(Path(x) for x in extra)]
    doc_out = {
        "schema": SCHEMA,
        "commands_csv": out.name,
        "method": METHOD_NOTE,
        "axes": axes_doc,
        "provenance": provenance(inputs, config),
    }
    _write_outputs(out, _table(result), doc_out)
    return doc_out


def _fit_of_axis(docs: list, axis: str) -> tuple[Path, dict]:
    """(path, document) of the fit.json of ``axis``; a one-line CalibError without one."""
    found = [(p, d) for p, d in docs if d.get("axis") == axis]
    if not found:
        raise CalibError(
            f"no fit.json for the {axis} axis among {', '.join(str(p) for p, _ in docs)}; "
            f"give the {axis} fit.json too"
        )
    return found[0]


def _models(source: tuple, kinds: list[str], mf: Path | None) -> dict:
    """Kind -> the fitted model of ``source`` (path, fit.json document, dataset record)."""
    path, doc, record = source
    return {kind: load_model(doc, record, kind, path, mf) for kind in kinds}


def _loadable(source: tuple, kinds: list[str]) -> dict:
    """Kind -> the fitted model of ``source`` for those of ``kinds`` that load (the
    others left out)."""
    path, doc, record = source
    out = {}
    for kind in kinds:
        try:
            out[kind] = load_model(doc, record, kind, path, None)
        except CalibError:
            continue
    return out


def _table(result: Outcome) -> pd.DataFrame:
    """COMMANDS.csv's table: time, per axis the signed counts and predicted angle (and
    whether reachable, with two axes), whether every axis is reachable, the flags."""
    cols: dict[str, Any] = {"time_s": result.t}
    reach_all = np.ones(result.t.size, dtype=bool)
    for axis, o in result.axes.items():
        cols[f"enc_{axis}"] = o.counts
        reach_all &= o.reachable
    two = len(result.axes) > 1
    cols.update({f"predicted_{axis}_deg": o.predicted_deg for axis, o in result.axes.items()})
    if two:
        cols.update(
            {f"reachable_{axis}": o.reachable.astype(int) for axis, o in result.axes.items()}
        )
    cols["reachable"] = reach_all.astype(int)
    cols["flags"] = _flag_column({axis: o.row_flags for axis, o in result.axes.items()}, prefix=two)
    return pd.DataFrame(cols)


def _claimed_output(out, inputs: list) -> Path:
    """``out`` as a Path after checking it is a .csv the tool may write (not one of the
    ``inputs``; compensate.json beside it likewise)."""
    out = Path(out)
    if out.suffix.lower() != ".csv":
        raise CalibError(f"--out {out}: give the COMMANDS.csv file to write (ending in .csv)")
    claim_output_file(out, inputs, companions=[out.with_name("compensate.json")])
    return out


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
    ``<axis>_deg`` column in the target
    (:func:`~i2ris_calib.compensation.plan.choose_dataset`)."""
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
        names.append(
            choose_dataset(dataset_names(doc), axis, frame[f"{axis}_deg"].to_numpy(), str(path))
        )
    return names


def _axis_doc(
    a: AxisPlan, c: AxisChoice, o: AxisOutcome, result: Outcome, rec: dict, history, t, unit
) -> dict:
    """compensate.json's record of one axis (docs/compensate.md): dataset, model and its
    ranking, limits, start state, the result's summary with every flag counted,
    warnings."""
    res, sign = c.result, a.sign
    ramp = res.entry_commands
    bad = np.flatnonzero(~res.reachable)
    n_cond, n_pre, dt0 = result.n_cond, result.n_pre, result.dt0
    replaced = rec["models"][c.kind].get("replaced")  # a later stage's lower cost (issue 31)
    said = {"fit_replaced": replaced["text"]} if isinstance(replaced, dict) else {}
    return {
        "dataset": a.name,
        "fit_json": a.fit.where,
        "model": c.kind,
        "model_choice": "--model" if c.forced else "fit decision",
        "recommended_model": c.recommended,
        "substitute": c.substitute,
        "ranking": c.ranking,
        "params": rec["models"][c.kind]["params"],
        "input_range_counts": [a.lo, a.hi],
        "max_counts_per_s": a.max_rate,
        "max_counts_per_s_source": a.rate.source,
        "recording_max_rate_counts_per_s": rec.get("max_input_rate_counts_per_s"),
        "start_counts": float(sign * a.v0) + 0.0,
        "start_counts_source": a.start_source,
        "start_state": a.start.method,
        "start_state_reason": a.start.reason,
        "fit_initial_state": _initial_state_text(rec),
        "n_conditioning": int(n_cond),
        "conditioning_s": float(n_cond * dt0),
        "conditioning_counts": None if a.sweep_ends is None else list(a.sweep_ends),
        "history_file": None if history is None else str(history),
        "n_history": int(n_pre) if history is not None else 0,
        "entry_from_counts": float(sign * a.v_entry) + 0.0,
        "time_unit_s": unit,
        "delay_s": res.delay_s,
        "tol_deg": res.tol_deg,
        **o.summary,
        "n_entry": int(ramp.size),
        "entry_s": float(ramp.size * dt0),
        "unreachable_first_times_s": [float(t[i]) for i in bad[:20]],
        "status_codes": {str(k): v for k, v in STATUS_NAMES.items()},
        "reachable_deg": list(o.reach),
        "warnings": o.warnings,
        **said,
    }


def _initial_state_text(record: dict) -> str | None:
    """fit.json's sentence on how its recording started (the first model's
    ``initial_state.text``; "at rest" when none was estimated; None when not recorded)."""
    known = virgin_identified(record)
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
        if rec.get("fit_replaced"):  # the model inverted is the rerun's (docs/diagnosis.md)
            lines.append(f"note: {rec['fit_replaced']}")
    return lines
