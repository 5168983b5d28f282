"""Assemble the report :class:`~i2ris_calib.report.document.Document` from a RunData.

Every section degrades on its own: a stage output that is absent becomes a
:class:`~i2ris_calib.report.document.Note` saying so, never an exception.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
import pandas as pd

from i2ris_calib.hysteresis.models import gpi_model, i2ris_egpi_model
from i2ris_calib.report import figures, tables, verdicts
from i2ris_calib.report.clock import angle_rate_p95, clock_view
from i2ris_calib.report.config import ReportConfig
from i2ris_calib.report.data import CompensationData, DiagnosisData, FitData, RunData
from i2ris_calib.report.document import (
    Code,
    Document,
    Figure,
    MarkdownFragment,
    Note,
    Paragraph,
    Section,
    Table,
)
from i2ris_calib.report.recommend import CONTINUOUS_MARGIN, recommend

STAGE_INPUTS = (
    ("track", "track/angles.csv"),
    ("track", "track/track.json"),
    ("sync", "sync/sync.json"),
    ("sync", "sync/synced.csv"),
)


def build_document(
    run: RunData,
    config: ReportConfig | None = None,
    provenance: Mapping[str, Any] | None = None,
    progress: Callable[[str], None] | None = None,
) -> Document:
    """The whole report for one run.

    Parameters
    ----------
    run : RunData
        Parsed run folder (any part may be missing).
    config : ReportConfig, optional
        Figure settings; defaults when omitted.
    provenance : mapping, optional
        The report's own provenance block (version, config, input hashes).
    progress : callable, optional
        Called with a section title before each section is built (for a progress bar);
        see :func:`section_count` for the number of calls.
    """
    cfg = config or ReportConfig()
    builders: list[tuple[str, Callable[[], Section]]] = [
        ("overview", lambda: overview_section(run)),
        ("accuracy tables", lambda: accuracy_section(run)),
        ("Fig 6 figures", lambda: fit_figures_section(run, cfg)),
        ("parameters", lambda: parameters_section(run)),
    ]
    if run.fit_only:
        builders.append(("provenance", lambda: provenance_section(run, provenance)))
        return _assemble(run, builders, progress, "GPI / EGPI hysteresis models (Yue et al.)")
    if run.diagnoses:
        builders.append(("diagnosis", lambda: diagnosis_section(run.diagnoses)))
    if run.compensation is not None:
        builders.append(("compensation", lambda: compensation_section(run.compensation, cfg)))
    builders += [
        ("tracking quality", lambda: tracking_section(run, cfg)),
        ("clock sync", lambda: sync_section(run, cfg)),
        ("provenance", lambda: provenance_section(run, provenance)),
        ("appendix", lambda: appendix_section(run)),
    ]
    return _assemble(
        run,
        builders,
        progress,
        "GPI / EGPI hysteresis models (Yue et al.), tracking, clock sync and provenance",
    )


def _assemble(run: RunData, builders, progress, subtitle: str) -> Document:
    sections = []
    for label, build in builders:
        if progress is not None:
            progress(label)
        sections.append(build())
    return Document(
        title=f"I2RIS calibration report: {run.name}", subtitle=subtitle, sections=tuple(sections)
    )


def section_count(run: RunData) -> int:
    """Number of top-level sections (= progress calls) :func:`build_document` makes."""
    if run.fit_only:
        return 5
    return 8 + bool(run.diagnoses) + (run.compensation is not None)


def _pred_label(run: RunData, fd: FitData) -> str:
    """How predictions.csv of ``fd`` is named in ``run.absent`` and in the report."""
    return "predictions.csv" if run.fit_only else f"fit/{fd.axis}/predictions.csv"


def _missing(run: RunData, label: str) -> Note:
    return Note(
        f"{label}: {run.absent.get(label, 'not found')}. This part of the report is omitted."
    )


def overview_section(run: RunData) -> Section:
    """Which stage outputs were found, and the headline result per dataset."""
    rows = []
    for stage, label in () if run.fit_only else STAGE_INPUTS:
        rows.append(
            (stage, label, "missing: " + run.absent[label] if label in run.absent else "found")
        )
    for fd in run.fits:
        pred = (
            "found"
            if fd.predictions is not None
            else "missing: " + run.absent.get(_pred_label(run, fd), "not found")
        )
        rows.append(("fit", f"fit/{fd.axis}/fit.json", "found"))
        rows.append(("fit", _pred_label(run, fd), pred))
    for label, why in sorted(run.absent.items()):
        if label.startswith("fit/") and not any(
            label == f"fit/{fd.axis}/predictions.csv" for fd in run.fits
        ):
            rows.append(("fit", label, "missing: " + why))
    for dd in run.diagnoses:
        rows.append(("diagnose", f"diagnose/{dd.axis}/diagnosis.json", "found"))
    if not run.diagnoses and not run.fit_only:
        rows.append(("diagnose", "diagnose/AXIS/diagnosis.json", "not run (optional)"))
    if run.fit_only:  # a fit output folder: its two files, no run layout
        rows = [
            (stage, label.split("/")[-1], status) for stage, label, status in rows if stage == "fit"
        ]
    blocks: list = []
    recs = recommendation_table(run.fits)
    if recs is not None:
        blocks.append(recs)
    headline = _headline(run.fits)
    if headline is not None:
        blocks.append(headline)
    blocks.append(
        Table(
            ("stage", "output", "status"),
            tuple(rows),
            "Files read from the fit output folder (no run folder: tracking, clock and "
            "diagnosis are not part of this report)."
            if run.fit_only
            else "Stage outputs read from the run folder.",
        )
    )
    warned = run_warnings(run)
    if warned:
        blocks.append(
            Note(
                f"{len(warned)} warning(s): results that may be wrong although every stage "
                "finished. Read them before using the numbers below.",
                "warn",
            )
        )
        blocks.append(
            Table(("stage", "where", "warning"), tuple(warned), "Warnings of every stage.")
        )
    return Section("overview", "Overview", tuple(blocks))


def recommendation_table(fits: tuple[FitData, ...]) -> Table | None:
    """The model recommended per dataset, why, and the range its data cover."""
    rows = []
    for fd in fits:
        preds = _predictions_by_dataset(fd)
        for d in tables.fit_datasets(fd.fit):
            name = str(d.get("name", fd.axis))
            r = recommend(d, preds.get(name))
            rows.append((name, r.label, tables.fmt(r.rmse_deg, 3), r.why, r.support))
    if not rows:
        return None
    return Table(
        (
            "dataset",
            "recommended model",
            "held-out RMSE (deg)",
            "why",
            "data cover (outside: extrapolation)",
        ),
        tuple(rows),
        "Recommended model per dataset: among converged models the lowest held-out RMSE; "
        "EGPI_C (continuous) over EGPI when within "
        f"{100 * CONTINUOUS_MARGIN:.0f} % of it. The last column is the range of the "
        "dataset's own measured samples: no data were seen outside it, so the model is "
        "not supported there.",
        align=("l", "l", "r", "l", "l"),
    )


def run_warnings(run: RunData) -> list[tuple[str, str, str]]:
    """(stage, where, text) of every warning the stages recorded: ``warnings`` in
    track.json and sync.json, each fitted model's ``warnings`` in fit.json."""
    out: list[tuple[str, str, str]] = []
    for stage, doc, where in (("track", run.track, "track.json"), ("sync", run.sync, "sync.json")):
        for w in (doc or {}).get("warnings", []) or []:
            out.append((stage, where, w if isinstance(w, str) else json.dumps(w)))
    for fd in run.fits:
        for d in tables.fit_datasets(fd.fit):
            for kind, rec in d.get("models", {}).items():
                for w in rec.get("warnings", []) or []:
                    out.append(("fit", f"{d.get('name', fd.axis)} {kind}", str(w)))
    return out


def _headline(fits: tuple[FitData, ...]) -> Table | None:
    """Held-out RMSE per dataset and model (``*`` = not converged), and GPI / EGPI."""
    records = [(fd.axis, d) for fd in fits for d in tables.fit_datasets(fd.fit)]
    if not records:
        return None
    models = [
        (k, lab)
        for k, lab in tables.FIT_MODELS
        if any(k in d.get("models", {}) for _, d in records)
    ]
    rows = []
    starred = False
    for axis, d in records:
        cells = []
        for key, _ in models:
            rec = d.get("models", {}).get(key) or {}
            value = (rec.get("holdout_metrics") or {}).get("rmse_deg")
            star = tables.not_converged(d, key)
            starred |= star
            cells.append(tables.metric_cell(value, 3, star))
        ratio = tables.gpi_egpi_ratio(d)
        rows.append(
            (
                str(d.get("name", axis)),
                *cells,
                tables.fmt(ratio, 2) if ratio is not None else tables.DASH,
            )
        )
    return Table(
        ("dataset", *(f"{lab} held-out RMSE (deg)" for _, lab in models), "GPI / EGPI"),
        tuple(rows),
        "Headline: held-out RMSE per dataset (the paper reports GPI 4-7x worse than EGPI)."
        + (f" {tables.NOT_CONVERGED} = not converged." if starred else ""),
    )


def _no_fit_note(run: RunData) -> Note:
    absent = [f"{k}: {v}" for k, v in run.absent.items() if k.endswith("/fit.json")]
    why = "; ".join(absent) if absent else "no fit/AXIS/fit.json in the run folder"
    return Note(f"No fit results ({why}). Run 'i2ris-calib fit ... --out RUN_DIR/fit/AXIS'.")


def _missing_fit_notes(run: RunData) -> list[Note]:
    """Notes for expected axes without fit.json when other axes were fitted."""
    notes = []
    for k, v in run.absent.items():
        if k.startswith("fit/") and k.endswith("/fit.json"):
            axis = k.split("/")[1]
            why = (
                " (its encoder does not move in sync/synced.csv)" if _axis_still(run, axis) else ""
            )
            notes.append(Note(f"{k}: {v}{why}; this axis is not shown."))
    return notes


def _axis_still(run: RunData, axis: str) -> bool:
    """True when synced.csv is there and ``enc_<axis>`` spans less than one count."""
    col = f"enc_{axis}"
    if run.synced is None or col not in run.synced:
        return False
    enc = run.synced[col].to_numpy(dtype=float)
    return bool(enc.size) and float(np.nanmax(enc) - np.nanmin(enc)) < 1.0


def accuracy_section(run: RunData) -> Section:
    """Tables shaped like the paper's Tables 1-2, one per axis, each followed by the paper's."""
    if not run.fits:
        return Section("accuracy", "Model accuracy (paper Tables 1-2)", (_no_fit_note(run),))
    blocks: list = _missing_fit_notes(run)
    for fd in run.fits:
        ds = tables.fit_datasets(fd.fit)
        blocks.append(
            tables.metrics_table(fd.axis, ds)
            if ds
            else Note(f"fit/{fd.axis}/fit.json has no datasets.")
        )
        samples = tables.samples_table(fd.axis, ds, _predictions_by_dataset(fd)) if ds else None
        if samples is not None:
            blocks.append(samples)
        if fd.axis in tables.PAPER_RESULTS:
            blocks.append(tables.paper_table(fd.axis))
    return Section("accuracy", "Model accuracy (paper Tables 1-2)", tuple(blocks))


def _dataset_rows(pred: pd.DataFrame, name: str) -> pd.DataFrame:
    return pred[pred["dataset"].astype(str) == name]


def _predictions_by_dataset(fd: FitData) -> dict[str, pd.DataFrame]:
    if fd.predictions is None:
        return {}
    return {str(k): g for k, g in fd.predictions.groupby("dataset", sort=False)}


def _direction(d: Mapping[str, Any]) -> str:
    """``"+"``, ``"-"`` or ``"±"`` of a fit.json dataset (older files: from abs_fitted)."""
    direction = str(d.get("direction", ""))
    if direction in ("+", "-", "±"):
        return direction
    return "-" if d.get("abs_fitted") else "+"


def fit_figures_section(run: RunData, cfg: ReportConfig) -> Section:
    """Fig-6-like figures per dataset from predictions.csv."""
    title = "Model vs measurement (paper Fig 6)"
    if not run.fits:
        return Section("fig6", title, (_no_fit_note(run),))
    subs = []
    for fd in run.fits:
        blocks: list = []
        if fd.predictions is None:
            blocks.append(_missing(run, _pred_label(run, fd)))
        else:
            for d in tables.fit_datasets(fd.fit):
                name = str(d.get("name", fd.axis))
                rows = _dataset_rows(fd.predictions, name)
                if rows.empty:
                    blocks.append(
                        Note(f"predictions.csv has no rows for dataset '{name}'.", "warn")
                    )
                    continue
                png = figures.fit_figure_png(
                    rows,
                    name,
                    fd.axis,
                    _direction(d),
                    dpi=cfg.figure_dpi,
                    max_points=cfg.max_plot_points,
                )
                caption = _fig6_caption(name, _direction(d), rows)
                blocks.append(Figure(f"fig6_{_slug(fd.axis)}_{_slug(name)}", png, caption))
        subs.append(Section(f"fig6-{_slug(fd.axis)}", fd.axis, tuple(blocks)))
    return Section("fig6", title, (), tuple(subs))


def _fig6_caption(name: str, direction: str, rows: pd.DataFrame) -> str:
    c = tables.rows_from_predictions(rows)
    models = [lab for col, lab, _ in figures.MODEL_CURVES if col in rows]
    banded = [lab for col, lab, _ in figures.MODEL_CURVES if figures.band_column(col) in rows]
    band = (
        f" Shaded about {', '.join(banded)} (middle): the ±{figures.BAND_SIGMA:g} sd prediction "
        "band from the parameter covariance (FitResult.eval_uncertainty)."
        if banded
        else " No prediction band: predictions.csv has no <model>_sd_deg column (the band "
        "needs the parameter covariance, which fit.json does not store; "
        "FitResult.eval_uncertainty gives it in Python)."
    )
    sign = (
        " Sign convention of a '-' dataset: input max(-enc, 0), angle -theta (= |angle| on "
        "its own samples)."
        if direction == "-"
        else ""
    )
    other = (
        f" The {c['other']} samples of the other direction (grey bands) drive the models "
        "but are not part of this dataset and are not drawn."
        if c["other"]
        else ""
    )
    return (
        f"{name}: measured angle (grey dots) and {', '.join(models) or 'no model'} "
        "predictions on the dataset's own samples; left: angle vs input, middle: angle vs "
        "time, right: model minus measured vs time. Own samples: "
        f"{c['fitted']} fitted, {c['holdout']} held out (yellow: held-out cycles), "
        f"{c['angle_missing']} not measured.{other} Lines are broken wherever samples are missing "
        "(other direction, unmeasured frames, time gaps): no line bridges a gap." + sign + band
    )


def parameter_info() -> dict[str, tuple[str, str]]:
    """Parameter name -> (unit, meaning) from the GPI and I2RIS-EGPI model declarations."""
    info: dict[str, tuple[str, str]] = {}
    for model in (i2ris_egpi_model(), gpi_model()):
        for p in model.parameters:
            info.setdefault(p.name, (p.unit, p.doc))
    return info


def parameters_section(run: RunData, info: Mapping[str, tuple[str, str]] | None = None) -> Section:
    """Fitted parameters with standard errors and fit diagnostics, one subsection per dataset."""
    title = "Fitted parameters"
    if not run.fits:
        return Section("parameters", title, (_no_fit_note(run),))
    info = parameter_info() if info is None else info
    subs = []
    for fd in run.fits:
        for d in tables.fit_datasets(fd.fit):
            name = str(d.get("name", fd.axis))
            blocks = (tables.params_table(d, info), tables.fit_info_table(d))
            subs.append(Section(f"parameters-{_slug(fd.axis)}-{_slug(name)}", name, blocks))
    return Section("parameters", title, (), tuple(subs))


def tracking_section(run: RunData, cfg: ReportConfig) -> Section:
    """Verdicts first, then the per-frame status timeline and a short quality table."""
    blocks: list = []
    if run.angles is None:
        blocks.append(_missing(run, "track/angles.csv"))
    if run.track is None:
        blocks.append(_missing(run, "track/track.json"))
    blocks += verdicts.tracking_verdicts(run.angles, run.track)
    if run.angles is not None:
        png = figures.tracking_figure_png(
            run.angles, cfg.detection_window_s, dpi=cfg.figure_dpi, max_points=cfg.max_plot_points
        )
        blocks.append(
            Figure(
                "tracking_quality",
                png,
                "Tracking over camera time: the status of every frame (measured, or why "
                "not), the fused yaw and pitch, the reprojection error of measured frames "
                "and the roll (twist) they imply.",
            )
        )
        summary = tables.tracking_summary(run.angles)
        noise = {
            axis: verdicts.angle_noise_deg(
                run.angles["time_s"].to_numpy(dtype=float),
                run.angles[f"{axis}_deg"].to_numpy(dtype=float),
            )
            for axis in ("yaw", "pitch")
            if f"{axis}_deg" in run.angles
        }
        blocks.append(tables.tracking_table(summary, run.track, noise))
    return Section("tracking", "Tracking quality", tuple(blocks))


def sync_section(run: RunData, cfg: ReportConfig) -> Section:
    """Verdicts first (method and why, stated error, edges, axes, coverage), the clock
    figure, a short table, then the synced loops."""
    blocks: list = []
    view = clock_view(run.sync) if run.sync is not None else None
    if run.sync is None:
        blocks.append(_missing(run, "sync/sync.json"))
    elif view is None:
        blocks.append(Note("sync/sync.json states no clock offset (offset_s).", "warn"))
    else:
        blocks += verdicts.clock_verdicts(view, run.sync, _angle_rate(run))
        blocks.append(
            Figure(
                "clock",
                figures.clock_figure_png(view, dpi=cfg.figure_dpi),
                "Clock line: the offset t_ctrl − t_cam over camera time with its stated ±1 and "
                "±2 sd band (top), and every piece of evidence relative to it (bottom): the "
                "matched flash edges with ±1 sd, and the clocks the event and the "
                "hysteresis model gave alone when auto combined them"
                + (
                    "; right: the model method's residual sum of squares over the offset "
                    "(its minimum is the model's offset)."
                    if view.profile is not None
                    else "."
                ),
            )
        )
        blocks.append(tables.clock_table(view, run.sync))
    if run.synced is None:
        blocks.append(_missing(run, "sync/synced.csv"))
    else:
        png = figures.synced_figure_png(
            run.synced, dpi=cfg.figure_dpi, max_points=cfg.max_plot_points
        )
        blocks.append(
            Figure(
                "synced_loops",
                png,
                "Synced samples: tracked angle vs interpolated encoder per axis (raw hysteresis "
                "loops; a wrong clock offset widens them).",
            )
        )
    return Section("sync", "Clock synchronisation", tuple(blocks))


def _angle_rate(run: RunData) -> float:
    """Largest (over yaw and pitch) 95th-percentile angular speed (deg/s) of synced.csv,
    else of angles.csv; NaN without either."""
    frame = run.synced if run.synced is not None else run.angles
    if frame is None:
        return float("nan")
    rates = [
        angle_rate_p95(frame["time_s"].to_numpy(dtype=float), frame[c].to_numpy(dtype=float))
        for c in ("yaw_deg", "pitch_deg")
        if c in frame
    ]
    rates = [r for r in rates if np.isfinite(r)]
    return max(rates) if rates else float("nan")


def appendix_section(run: RunData) -> Section:
    """The raw stage records (track.json, sync.json) collapsed, for a reader who wants
    every number; the Markdown twin points to the files instead."""
    blocks: list = []
    for label, doc in (("track/track.json", run.track), ("sync/sync.json", run.sync)):
        if doc is None:
            continue
        blocks.append(
            Code(
                json.dumps(doc, indent=2, default=str),
                f"{label} (raw, {len(json.dumps(doc))} characters)",
                md_note=f"Raw {label}: see the file in the run folder (shown in report.html).",
            )
        )
    if not blocks:
        blocks.append(Paragraph("No track.json or sync.json in the run folder."))
    return Section("appendix", "Appendix: raw stage records", tuple(blocks))


def diagnosis_section(diagnoses: tuple[DiagnosisData, ...]) -> Section:
    """One subsection per diagnosed axis: named effects, metrics, steps, the stage's own fragment."""
    return Section(
        "diagnosis",
        "Diagnosis (model discrepancy)",
        (),
        tuple(_diagnosis_subsection(d) for d in diagnoses),
    )


def _diagnosis_subsection(dd: DiagnosisData) -> Section:
    """The stage's own diagnosis.md when present (it is the complete account), else a summary."""
    fig_names = {
        rel: f"diagnose_{_slug(dd.axis)}_{_slug(rel.removesuffix('.png'))}" for rel in dd.images
    }
    referenced: set[str] = set()
    if dd.markdown:
        referenced = {rel for rel in dd.images if f"]({rel})" in dd.markdown}
        frag_images = {rel: (fig_names[rel], dd.images[rel]) for rel in referenced}
        blocks: list = [MarkdownFragment(dd.markdown, frag_images)]
    else:
        blocks = _diagnosis_summary(dd.diagnosis)
    for rel, png in dd.images.items():
        if rel not in referenced:
            blocks.append(Figure(fig_names[rel], png, f"{dd.axis}: {rel}"))
    for rel in dd.missing_images:
        blocks.append(
            Note(f"diagnose/{dd.axis}/{rel} is listed in diagnosis.json but not found.", "warn")
        )
    return Section(f"diagnosis-{_slug(dd.axis)}", dd.axis, tuple(blocks))


def _diagnosis_summary(diag: Mapping[str, Any]) -> list:
    """Named effects, baseline vs final metrics and a compact steps table from diagnosis.json."""
    blocks: list = []
    named = diag.get("named_effects")
    if isinstance(named, list):
        text = (
            ", ".join(map(str, named))
            if named
            else "none (no candidate effect improved the held-out error)"
        )
        blocks.append(Paragraph(f"Named effects, in the order added: {text}."))
    metric_rows = _baseline_final_rows(diag)
    if metric_rows:
        blocks.append(
            Table(("metric", "baseline", "final"), tuple(metric_rows), "Baseline vs final model.")
        )
    steps = diag.get("steps")
    if isinstance(steps, list) and steps:
        blocks.append(_steps_table(steps))
    return blocks


def _baseline_final_rows(diag: Mapping[str, Any]) -> list[tuple[str, str, str]]:
    base, final = diag.get("baseline"), diag.get("final")
    if not isinstance(base, Mapping) and not isinstance(final, Mapping):
        return []
    b = dict(tables.flatten(base)) if isinstance(base, Mapping) else {}
    f = dict(tables.flatten(final)) if isinstance(final, Mapping) else {}
    keys = list(b) + [k for k in f if k not in b]
    return [(k, tables.fmt(b.get(k)), tables.fmt(f.get(k))) for k in keys]


def _step_row(step: Any) -> dict[str, str]:
    """A step's scalar fields and its ``params`` as ``name=value``; nested detail left out."""
    if not isinstance(step, Mapping):
        return {"effect": str(step)}
    row = {
        k: tables.fmt(v)
        for k, v in step.items()
        if not isinstance(v, (Mapping, list)) and not _is_png_list(v)
    }
    if isinstance(step.get("params"), Mapping):
        row["params"] = tables.fmt(step["params"])
    return row


def _steps_table(steps: list) -> Table:
    rows = [_step_row(s) for s in steps]
    keys: list[str] = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    keys.sort(key=lambda k: (k != "effect", k != "params", k))
    body = tuple((str(i + 1), *(_clip(r.get(k, "")) for k in keys)) for i, r in enumerate(rows))
    return Table(("step", *keys), body, "Diagnosis steps (details in diagnosis.json).")


def _is_png_list(value: Any) -> bool:
    items = value if isinstance(value, list) else [value]
    return bool(items) and all(isinstance(x, str) and x.lower().endswith(".png") for x in items)


def _clip(text: str, n: int = 160) -> str:
    return text if len(text) <= n else text[: n - 1] + "…"


def provenance_section(run: RunData, report_prov: Mapping[str, Any] | None) -> Section:
    """Package version, configuration and input hashes of the report and of every stage."""
    subs = []
    if report_prov:
        subs.append(_provenance_subsection("report", "this report", report_prov))
    sources: list[tuple[str, Any]] = [("track/track.json", run.track), ("sync/sync.json", run.sync)]
    sources += [(f"fit/{fd.axis}/fit.json", fd.fit) for fd in run.fits]
    sources += [(f"diagnose/{dd.axis}/diagnosis.json", dd.diagnosis) for dd in run.diagnoses]
    blocks: list = []
    for label, obj in sources:
        if obj is None:
            continue
        prov = obj.get("provenance")
        if isinstance(prov, Mapping):
            subs.append(_provenance_subsection(_slug(label), label, prov))
        else:
            blocks.append(Note(f"{label} has no provenance block.", "warn"))
    return Section("provenance", "Provenance", tuple(blocks), tuple(subs))


def _provenance_subsection(anchor: str, label: str, prov: Mapping[str, Any]) -> Section:
    blocks: list = [tables.provenance_table(label, prov)]
    if prov.get("config") is not None:
        blocks.append(
            Code(json.dumps(prov["config"], indent=2, sort_keys=True), f"configuration of {label}")
        )
    return Section(f"provenance-{anchor}", label, tuple(blocks))


def _slug(text: str) -> str:
    """Lower-case ASCII identifier for anchors and file names (``yaw+`` -> ``yaw_pos``,
    ``yaw-`` -> ``yaw_neg``, ``yaw±`` -> ``yaw_signed``)."""
    text = str(text)
    suffix = {"+": "_pos", "-": "_neg", "±": "_signed"}
    if text[-1:] in suffix:
        text = text[:-1] + suffix[text[-1]]
    return re.sub(r"[^a-z0-9_]+", "_", text.lower()).strip("_") or "x"


def compensation_section(comp: CompensationData, cfg: ReportConfig) -> Section:
    """Feedforward compensation (``[compensate] target``): commands from the inverse of
    the fitted model, the angle the model predicts for them, unreachable samples."""
    axes_doc = comp.doc.get("axes", {})
    rows = []
    for axis, a in axes_doc.items():
        un = a.get("unreachable", {})
        why = ", ".join(f"{k} {v}" for k, v in un.items() if v) or "-"
        rows.append(
            (
                axis,
                str(a.get("dataset", "?")),
                str(a.get("model", "?")),
                tables.fmt(a.get("rmse_deg"), 3),
                tables.fmt(a.get("max_abs_err_deg"), 3),
                f"{a.get('n_unreachable', 0)} of {a.get('n_samples', 0)} ({why})",
            )
        )
    blocks: list = [
        Paragraph(
            "Motor commands that make the fitted model follow the target angle (exact "
            "inversion of the stateful model, sample by sample; docs/compensate.md). The "
            "error is the model's, not a measurement: run the commands on the robot and "
            "track the result to measure the achieved angle."
        ),
        Table(
            ("axis", "dataset", "model", "RMSE (deg)", "max |error| (deg)", "unreachable"),
            tuple(rows),
            "Predicted angle vs target for the commands in compensate/commands.csv.",
        ),
    ]
    axes = [a for a in axes_doc if f"enc_{a}" in comp.commands]
    if axes:
        png = figures.compensation_figure_png(
            comp.commands, comp.target, axes, dpi=cfg.figure_dpi, max_points=cfg.max_plot_points
        )
        blocks.append(
            Figure(
                "compensation",
                png,
                "Target and predicted angle, their difference with unreachable samples "
                "marked x, and the motor command over time.",
            )
        )
    return Section("compensation", "Feedforward compensation", tuple(blocks))
