"""The diagnosis as a JSON-ready record and as a Markdown report section.

Both are pure functions of a :class:`~i2ris_calib.diagnosis.results.Diagnosis`;
the io layer writes them (``diagnosis.json``, ``diagnosis.md``).
"""

from __future__ import annotations

import numpy as np

from i2ris_calib.diagnosis.results import Diagnosis
from i2ris_calib.hysteresis.effects import CATALOGUE, effects_of


def diagnosis_record(diag: Diagnosis, figures: list[str], auto=None) -> dict:
    """``diagnosis.json`` content (without schema/source/provenance, added by io).

    Parameters
    ----------
    diag : Diagnosis
    figures : list of str
        Figure file names: ``figures[0]`` shows the starting model's residual,
        ``figures[i]`` the residual after step i.
    auto : AutoDiagnosis, optional
        With several paths (``--start auto``), ``summary`` is :func:`auto_summary`
        (every path's verdicts and what it leaves open) and ``not_excluded`` the
        union over the paths (:attr:`AutoDiagnosis.not_excluded`, each entry with
        its ``start``).
    """
    steps = []
    for i, s in enumerate(diag.steps):
        steps.append(
            {
                "effect": s.effect,
                "meaning": CATALOGUE[s.effect].meaning,
                "params": effects_of(s.model_after)[-1][2],
                "model_params": {p.name: float(p.value) for p in s.model_after.parameters},
                "fit_rmse_before_deg": s.before.fit_rmse_deg,
                "fit_rmse_after_deg": s.after.fit_rmse_deg,
                "holdout_rmse_before_deg": s.before.holdout_rmse_deg,
                "holdout_rmse_after_deg": s.after.holdout_rmse_deg,
                "delta_bic": s.comparison.delta_bic,
                "evidence": s.comparison.as_dict(),
                "location_before": list(s.sentences_before),
                "candidates": [c.as_dict() for c in s.candidates],
                "alternatives": [a.as_dict() for a in s.alternatives],
                "verdict": step_verdict(s.effect, s.alternatives),
                "figures": {"before": figures[i], "after": figures[i + 1]},
            }
        )
    return {
        "summary": diagnosis_summary(diag),
        "baseline": diag.baseline.as_dict(),
        "final": diag.final.as_dict(),
        "named_effects": diag.named_effects,
        "steps": steps,
        "stopped_because": _stop_reason(diag),
        "last_candidates": [c.as_dict() for c in diag.last_candidates],
        "location_final": list(diag.sentences_final),
        "residual_analysis_final": diag.analysis_final,
        "decimation": diag.decimation,
        "holdout_fraction": float(np.mean(diag.holdout)),
        "notes": list(diag.notes),
        "not_excluded": _open_records(diag, auto),
        "figures": figures,
    } | ({"summary": auto_summary(auto)} if auto is not None and len(auto.paths) > 1 else {})


def _open_records(diag: Diagnosis, auto) -> list[dict]:
    if auto is None or len(auto.paths) < 2:
        return [a.as_dict() for a in diag.not_excluded]
    return [a.as_dict() | {"start": kind} for kind, a in auto.not_excluded]


def auto_summary(auto) -> str:
    """``--start auto`` in one paragraph: the answer's summary (its verdicts, the
    alternatives its steps could not exclude, what it leaves open), then every other
    start's, so that both paths' alternatives are shown, e.g. ``"time_delay; ...
    The egpi start: time_delay; rate_dependent_thresholds not excluded, z = 1.9."``."""
    text = diagnosis_summary(auto.diagnosis).rstrip(".") + "."
    for kind, d in auto.paths.items():
        if kind == auto.start:
            continue
        other = diagnosis_summary(d).rstrip(".") + "."
        same = other == text
        text += f" The {kind} start: " + ("the same." if same else other)
    return text


def step_verdict(effect: str, alternatives) -> str:
    """One sentence: the named effect and the alternatives the held-out cycles could
    not exclude, e.g. ``"dead_zone; backlash not excluded, z = 0.8"``."""
    open_ = [a for a in alternatives if not a.excluded]
    if not open_:
        return f"{effect}; no other candidate is left open by the held-out cycles"
    parts = [f"{a.effect} not excluded, z = {a.z:.1f}" for a in open_]
    text = f"{effect}; " + "; ".join(parts)
    exps = [f"to separate {a.effect}: {a.experiment}" for a in open_ if a.experiment]
    return text + (" (" + "; ".join(exps) + ")" if exps else "")


#: |z| below this: the alternative "fits as well" as the named effect on the held-out
#: cycles; z at or below minus this: it "fits better" (the test could not exclude it)
AS_WELL_Z = 2.0


def not_excluded_sentence(alternatives) -> str:
    """One sentence on the effects the data cannot tell from the final model, e.g.
    ``"backlash not excluded (width_counts = 151 moves the angle by 0.37 deg RMS as
    well fitted, z = -1.2; to separate it: ...)"``; "" when there are none."""
    parts = []
    for a in alternatives:
        params = ", ".join(f"{k} = {v:.3g}" for k, v in a.params.items())
        moves = (
            f" moves the angle by {a.effect_rms_deg:.2g} deg RMS and"
            if np.isfinite(a.effect_rms_deg)
            else ""
        )
        # the words follow z (the named effect's held-out SSE reduction over it)
        how = (
            "fits better"
            if a.z <= -AS_WELL_Z
            else "fits as well"
            if a.z < AS_WELL_Z
            else "fits almost as well"
        )
        held = f", held-out {a.holdout_rmse_deg:.3g} deg" if np.isfinite(a.holdout_rmse_deg) else ""
        text = f"{a.effect} not excluded ({params}{moves} {how}{held}, z = {a.z:.1f}"
        parts.append(text + (f"; to separate it: {a.experiment})" if a.experiment else ")"))
    return "; ".join(parts)


def diagnosis_summary(diag: Diagnosis) -> str:
    """The diagnosis in one sentence (the steps' verdicts, or nothing missing), with
    the effects the data cannot tell from the final model."""
    if not diag.steps:
        text = (
            "nothing missing: no candidate improved the held-out error by more than noise explains"
        )
    else:
        text = " Then ".join(step_verdict(s.effect, s.alternatives) + "." for s in diag.steps)
    open_ = not_excluded_sentence(diag.not_excluded)
    if open_:
        text = text.rstrip(".") + ("; " if not diag.steps else ". Not told apart: ") + open_
    return text


def verdict_line(rec: dict) -> str:
    """The diagnosis.json record in one terminal line (diagnosis.md has the rest), e.g.
    ``"yaw+: named time_delay (held-out RMSE 0.42 -> 0.15 deg); not told apart:
    backlash; gpi and egpi starts agree"``."""
    named = rec.get("named_effects") or []
    b, f = rec["baseline"]["holdout_rmse_deg"], rec["final"]["holdout_rmse_deg"]
    if named:
        parts = [f"named {', then '.join(named)} (held-out RMSE {_fmt(b)} -> {_fmt(f)} deg)"]
    else:
        parts = [f"nothing missing (held-out RMSE {_fmt(f)} deg)"]
    open_ = list(dict.fromkeys(a["effect"] for a in rec.get("not_excluded", [])))
    if open_:
        parts.append(f"not told apart: {', '.join(open_)}")
    paths = rec.get("paths") or {}
    if len(paths) > 1:
        answers = {tuple(p.get("named_effects", [])) for p in paths.values()}
        starts = " and ".join(paths)
        parts.append(
            f"{starts} starts agree"
            if len(answers) == 1
            else f"{starts} starts disagree (answer from {rec.get('start_model', '?')})"
        )
    return f"{rec.get('dataset', '?')}: " + "; ".join(parts)


def paths_record(auto) -> dict:
    """``paths`` entry of diagnosis.json for ``--start auto``: each start's answer."""
    return {
        kind: {
            "named_effects": d.named_effects,
            "summary": diagnosis_summary(d),
            "baseline": d.baseline.as_dict(),
            "final": d.final.as_dict(),
            "steps": [
                {
                    "effect": s.effect,
                    "params": effects_of(s.model_after)[-1][2],
                    "evidence": s.comparison.as_dict(),
                    "alternatives": [a.as_dict() for a in s.alternatives],
                }
                for s in d.steps
            ],
            "not_excluded": [a.as_dict() for a in d.not_excluded],
            "notes": list(d.notes),
        }
        for kind, d in auto.paths.items()
    }


def _stop_reason(diag: Diagnosis) -> str:
    if not diag.last_candidates:
        return "max_steps reached" if diag.steps else "no candidate fitted"
    return "no candidate effect improved the held-out error significantly"


def _fmt(x) -> str:
    if x is None:
        return "-"
    if isinstance(x, float):
        return f"{x:.3g}"
    return str(x)


def diagnosis_markdown(rec: dict) -> str:
    """Markdown section (``## Model diagnosis``) for the report, from the record."""
    b, f = rec["baseline"], rec["final"]
    named = rec["named_effects"]
    axis = rec.get("axis", "")
    lines = [
        f"## Model diagnosis{f' ({axis})' if axis else ''}",
        "",
        f"Starting model: **{rec.get('start_model', rec.get('start', '?'))}**"
        + (" (--start auto)" if rec.get("start") == "auto" else "")
        + ". "
        + (
            f"Effects named, in order: **{', '.join(named)}**."
            if named
            else "No missing effect was found: no candidate improved the held-out error "
            "by more than noise explains."
        ),
        "",
        f"**Verdict:** {rec['summary']}" if rec.get("summary") else "",
        "",
        *([f"Starting models: {rec['reconciliation']}.", ""] if rec.get("reconciliation") else []),
        *_paths_table(rec),
        "| model | fitted RMSE (deg) | held-out RMSE (deg) | BIC |",
        "|---|---|---|---|",
        f"| start | {_fmt(b['fit_rmse_deg'])} | {_fmt(b['holdout_rmse_deg'])} | {b['bic']:.1f} |",
        f"| final | {_fmt(f['fit_rmse_deg'])} | {_fmt(f['holdout_rmse_deg'])} | {f['bic']:.1f} |",
        "",
        f"![residual of the starting model]({rec['figures'][0]})",
        "",
    ]
    for i, step in enumerate(rec["steps"], start=1):
        lines += _step_lines(i, step)
    lines += ["### Remaining residual", "", *[f"- {x}" for x in rec["location_final"]], ""]
    if rec["last_candidates"]:
        lines += [
            "Last round (nothing named):",
            "",
            "| candidate | fit | held-out RMSE (deg) | rel. improvement | z | BIC change | named |",
            "|---|---|---|---|---|---|---|",
            *_candidate_rows(rec["last_candidates"], None),
            "",
        ]
    for n in rec.get("notes", []):
        lines.append(f"Note: {n}")
    return "\n".join(lines).rstrip() + "\n"


def _step_lines(i: int, s: dict) -> list[str]:
    """Markdown of one named step ``s`` (a diagnosis.json ``steps`` record): where the
    disagreement was, the fitted effect, the held-out evidence, the candidates."""
    ev = s["evidence"]
    lines = [
        f"### Step {i}: {s['effect']}",
        "",
        f"*{s['meaning']}.* Where the disagreement was:",
        "",
        *[f"- {x}" for x in s["location_before"]],
        "",
        "Fitted effect parameters: "
        + ", ".join(f"`{k}` = {_fmt(v)}" for k, v in s["params"].items())
        + ".",
        "",
        f"Held-out RMSE {_fmt(s['holdout_rmse_before_deg'])} -> "
        f"{_fmt(s['holdout_rmse_after_deg'])} deg ({100 * ev['rel_improvement']:.0f}% lower), "
        f"held-out SSE reduction z = {ev['z']:.1f} (p = {ev['p_value']:.2g}), "
        f"{ev['units_improved']}/{ev['n_units']} held-out strokes improved, "
        f"BIC change {s['delta_bic']:.1f}.",
        "",
        *([f"{s['verdict']}.", ""] if s.get("verdict") else []),
        "| candidate | fit | held-out RMSE (deg) | rel. improvement | z | BIC change | named |",
        "|---|---|---|---|---|---|---|",
    ]
    lines += _candidate_rows(s["candidates"], s["effect"])
    return lines + ["", f"![residual after {s['effect']}]({s['figures']['after']})", ""]


def _paths_table(rec: dict) -> list[str]:
    """Markdown table of every starting model's path (``--start auto``), [] for one."""
    paths = rec.get("paths") or {}
    if len(paths) < 2:
        return []
    lines = [
        "| start | named | held-out RMSE start -> final (deg) | verdict and what is left open |",
        "|---|---|---|---|",
    ]
    for kind, p in paths.items():
        mark = " (answer)" if kind == rec.get("start_model") else ""
        lines.append(
            f"| {kind}{mark} | {', '.join(p['named_effects']) or 'nothing'} | "
            f"{_fmt(p['baseline']['holdout_rmse_deg'])} -> {_fmt(p['final']['holdout_rmse_deg'])} | "
            f"{p['summary'].replace('|', '/')} |"
        )
    return [*lines, ""]


def _candidate_rows(cands: list[dict], chosen: str | None) -> list[str]:
    rows = []
    for c in cands:
        if "skipped" in c:
            rows.append(f"| {c['effect']} | skipped: {c['skipped']} | | | | | |")
            continue
        e = c["evidence"]
        rows.append(
            f"| {c['effect']} | {c.get('fit', 'warm')} | {_fmt(c['metrics']['holdout_rmse_deg'])} | "
            f"{100 * e['rel_improvement']:.1f}% | {e['z']:.1f} | {e['delta_bic']:.1f} | "
            f"{'yes' if c['effect'] == chosen else 'no'} |"
        )
    return rows
