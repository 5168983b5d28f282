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

from i2ris_calib.hysteresis.kinds import PAPER_MODEL
from i2ris_calib.hysteresis.registry import BUILT_KINDS, model_for_kind
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
    Verdict,
)
from i2ris_calib.report.recommend import CONTINUOUS_MARGIN, recommend
from i2ris_calib.report.tables import fmt_sig

MODELS_SUBTITLE = "Hysteresis models (GPI / EGPI of Yue et al., two-tendon GPI)"

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
        return _assemble(run, builders, progress, MODELS_SUBTITLE)
    if run.diagnoses:
        builders.append(("diagnosis", lambda: diagnosis_section(run.diagnoses, cfg)))
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
        MODELS_SUBTITLE + ", tracking, clock sync and provenance",
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
    blocks: list = model_choice_verdicts(run.fits) + replaced_fit_verdicts(run.fits)
    recs = recommendation_table(run.fits)
    if recs is not None:
        blocks.append(recs)
    limits = limits_table(run.fits)
    if limits is not None:
        blocks.append(limits)
    headline = _headline(run.fits)
    if headline is not None:
        blocks.append(headline)
    blocks.append(
        Table(
            ("stage", "output", "status"),
            tuple(_stage_output_rows(run)),
            "Files read from the fit output folder (no run folder: tracking, clock and "
            "diagnosis are not part of this report)."
            if run.fit_only
            else "Stage outputs read from the run folder.",
        )
    )
    blocks.extend(_warning_blocks(run))
    return Section("overview", "Overview", tuple(blocks))


def _stage_output_rows(run: RunData) -> list[tuple[str, str, str]]:
    """(stage, output file, found / missing: why / not run) for every stage output the
    report reads; only the fit files, by file name, for a fit output folder."""
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
    return rows


def _warning_blocks(run: RunData) -> list:
    """A note with the number of warnings and the table of every stage's warnings;
    empty when there are none."""
    warned = run_warnings(run)
    if not warned:
        return []
    return [
        Note(
            f"{len(warned)} warning(s): results that may be wrong although every stage "
            "finished. Read them before using the numbers below.",
            "warn",
        ),
        Table(("stage", "where", "warning"), tuple(warned), "Warnings of every stage."),
    ]


def recommendation_table(fits: tuple[FitData, ...]) -> Table | None:
    """The model recommended per dataset, why, and the range its data cover."""
    rows = []
    for fd in fits:
        preds = _predictions_by_dataset(fd)
        for d in tables.fit_datasets(fd.fit):
            name = str(d.get("name", fd.axis))
            r = recommend(d, preds.get(name), fd.fit.get("model_choice"))
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
        "Recommended model per dataset, decided once by fit (fit.json decision; compensate "
        "and the Python API use the same): among the usable models (converged, some "
        "parameter identified, no search-box bound that moves the output, held-out error "
        "from rest within 2x that from the fitted start, no output jumps) the lowest "
        "held-out RMSE, fewer parameters within 5 %, EGPI_C (continuous) over EGPI within "
        f"{100 * CONTINUOUS_MARGIN:.0f} %. The last column is the range of the "
        "dataset's own measured samples: no data were seen outside it, so the model is "
        "not supported there.",
        align=("l", "l", "r", "l", "l"),
    )


def limits_table(fits: tuple[FitData, ...]) -> Table | None:
    """The recommended model's held-out error against the recording's own limits
    (fit.json ``limits``: noise, repeatability, model-free baselines, the worst sample,
    cross-validation); None when no fit.json has them (older files)."""
    rows = []
    for fd in fits:
        for d in tables.fit_datasets(fd.fit):
            lim = d.get("limits")
            if not isinstance(lim, dict):
                continue
            cv = lim.get("crossval") or {}
            cv_cell = (
                f"{tables.fmt_sig(cv['mean_deg'], 2)} ± {tables.fmt_sig(cv['sd_deg'], 2)} "
                f"({len(cv.get('folds_rmse_deg', []))} folds)"
                if cv.get("mean_deg") is not None
                else tables.DASH
            )
            rec = (d.get("models", {}).get(lim.get("model")) or {}).get("holdout_metrics") or {}
            worst = lim.get("worst_sample") or {}
            worst_cell = (
                f"{tables.fmt_sig(worst['error_deg'], 2)} at {tables.fmt_sig(worst['time_s'], 4)} s"
                if worst.get("error_deg") is not None
                else tables.DASH
            )
            rows.append((
                str(d.get("name", fd.axis)),
                str(lim.get("model") or tables.DASH),
                tables.fmt(lim.get("model_rmse_deg"), 3),
                cv_cell,
                tables.fmt(rec.get("p99_abs_err_deg"), 3),
                worst_cell,
                tables.fmt(lim.get("noise_sd_deg"), 3),
                tables.fmt(lim.get("repeatability_deg"), 3),
                tables.fmt(lim.get("line_rmse_deg"), 3),
                tables.fmt(lim.get("phase_rmse_deg"), 3),
                str(lim.get("verdict", "")),
            ))  # fmt: skip
    if not rows:
        return None
    return Table(
        (
            "dataset",
            "model",
            "held-out RMSE (deg)",
            "cross-validated (deg)",
            "99th pct |error| (deg)",
            "worst sample (deg)",
            "noise sd (deg)",
            "repeatability (deg)",
            "straight line (deg)",
            "function of phase (deg)",
            "verdict",
        ),  # fmt: skip
        tuple(rows),
        "The recording's own limits: the angle noise (from the model residual's "
        "sample-to-sample changes), the cycle-to-cycle repeatability at the same input "
        "(cycles of the same range), and two model-free baselines on the held-out "
        "samples: a straight line on the inputs, and for a periodic input the best "
        "function of the loop's phase. Cross-validated: each cycle held out once (short "
        "recordings), mean ± sd. The worst held-out sample and the 99th percentile of "
        "|error| sit beside the RMSE so one glitch cannot hide in it.",
        align=("l", "l", "r", "r", "r", "r", "r", "r", "r", "r", "l"),
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
    with_ratio = any(PAPER_MODEL in d.get("models", {}) for _, d in records)
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
        ratio_cell = tables.fmt(ratio, 2) if ratio is not None else tables.DASH
        rows.append((str(d.get("name", axis)), *cells, *((ratio_cell,) if with_ratio else ())))
    return Table(
        (
            "dataset",
            *(f"{lab} held-out RMSE (deg)" for _, lab in models),
            *(("GPI / EGPI",) if with_ratio else ()),
        ),
        tuple(rows),
        "Headline: held-out RMSE per dataset"
        + (" (the paper reports GPI 4-7x worse than EGPI)." if with_ratio else ".")
        + (f" {tables.NOT_CONVERGED} = not converged." if starred else ""),
    )


def model_choice_verdicts(fits: tuple[FitData, ...]) -> list[Verdict]:
    """One line per fitted axis: the model ``fit`` chose for its input and why
    (fit.json ``model_choice.line``; nothing for an older fit.json without it)."""
    out = []
    for fd in fits:
        choice = fd.fit.get("model_choice")
        if not isinstance(choice, Mapping):
            continue
        line = choice.get("line")
        if not line:
            kinds = ", ".join(map(str, choice.get("kinds") or ())) or "?"
            line = f"models {kinds} over the {choice.get('input', '?')} input" + (
                f" ({choice['why']})" if choice.get("why") else ""
            )
        out.append(Verdict(f"{fd.axis}: {line}", "info"))
    return out


def replaced_fit_verdicts(fits: tuple[FitData, ...]) -> list[Verdict]:
    """One line per model of a fit.json that a later stage replaced (its ``replaced``
    record: a lower cost of the same model on the same data, the fit rerun from it),
    e.g. ``pitch: fit.json's pitch+ egpi replaced: cost 6.43 -> 0.545 (found by
    diagnose's refit from creep_log's values)``; nothing for a fit as ``fit`` wrote it."""
    out = []
    for fd in fits:
        for d in tables.fit_datasets(fd.fit):
            for rec in (d.get("models") or {}).values():
                r = rec.get("replaced") if isinstance(rec, Mapping) else None
                if isinstance(r, Mapping) and isinstance(r.get("text"), str):
                    out.append(Verdict(f"{fd.axis}: {r['text']}", "info"))
    return out


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
        blocks += replaced_fit_verdicts((fd,))
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
    drawn = figures.drawn_models(rows[rows["split"].astype(str) != "other"])
    models = [lab for _, lab, _ in drawn]
    banded = [lab for col, lab, _ in drawn if figures.band_column(col) in rows]
    band = (
        f" Shaded about {', '.join(banded)} (middle): dark, the ±{figures.BAND_SIGMA:g} sd "
        "confidence band of the model curve from the parameter covariance "
        "(FitResult.eval_uncertainty); light, the ±"
        f"{figures.BAND_SIGMA:g} sd prediction band of a new measurement (that and the "
        "model's residual sd together, FitResult.eval_prediction_band)."
        if banded
        else " No confidence band: predictions.csv has no <model>_sd_deg column (the band "
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
    coupled = (
        " The coupled model's angle also follows the other motor, so against this "
        "motor's input alone it is not a single loop."
        if any(col == "agpi_coupled_deg" for col, _, _ in drawn)
        else ""
    )
    return (
        f"{name}: measured angle (grey dots) and {', '.join(models) or 'no model'} "
        "predictions on the dataset's own samples; left: angle vs input, middle: angle vs "
        "time, right: model minus measured vs time. Own samples: "
        f"{c['fitted']} fitted, {c['holdout']} held out (yellow: held-out cycles), "
        f"{c['angle_missing']} not measured.{other} Lines are broken wherever samples are missing "
        "(other direction, unmeasured frames, time gaps): no line bridges a gap."
        + sign
        + coupled
        + band
    )


def parameter_info() -> dict[str, tuple[str, str]]:
    """Parameter name -> (unit, meaning) from the model declarations of every built
    kind (the registry: GPI, EGPI, EGPI_C, two-tendon GPI, with coupling); the
    I2RIS-EGPI's meaning first where kinds share a name."""
    info: dict[str, tuple[str, str]] = {}
    kinds = (PAPER_MODEL, *(k for k in BUILT_KINDS if k != PAPER_MODEL))
    for kind in kinds:
        for p in model_for_kind(kind).parameters:
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
            subs.append(
                Section(f"parameters-{_slug(fd.axis)}-{_slug(name)}", name, dataset_params(d, info))
            )
    return Section("parameters", title, (), tuple(subs))


def dataset_params(d: Mapping[str, Any], info: Mapping[str, tuple[str, str]]) -> tuple:
    """The parameter tables of one dataset: one compact table per many-parameter model
    (per tendon / coupling side, :func:`~i2ris_calib.report.tables.grouped_params_table`),
    one table of the others side by side, then the fit diagnostics."""
    recs = {k: r for k, r in d.get("models", {}).items() if isinstance(r, Mapping)}
    grouped = [k for k, _ in tables.FIT_MODELS if k in recs and tables.is_grouped(recs[k])]
    flat = [k for k, _ in tables.FIT_MODELS if k in recs and k not in grouped]
    blocks: list = [tables.grouped_params_table(d, k, info) for k in grouped]
    if flat or not grouped:
        blocks.append(tables.params_table(d, info, models=flat))
    blocks.append(tables.fit_info_table(d))
    return tuple(blocks)


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


def diagnosis_section(
    diagnoses: tuple[DiagnosisData, ...], cfg: ReportConfig | None = None
) -> Section:
    """One subsection per diagnosed axis and direction: verdicts, the before/after
    residual figure, the named effects with their fitted values, the ties, then the
    stage's own diagnosis.md."""
    return Section(
        "diagnosis",
        "Diagnosis (model discrepancy)",
        (),
        tuple(_diagnosis_subsection(d, cfg) for d in diagnoses),
    )


def _diagnosis_subsection(dd: DiagnosisData, cfg: ReportConfig | None = None) -> Section:
    """Verdict, before/after residual figure, named effects with their fitted values,
    the alternatives left open (with the experiment that would separate them), then
    the stage's own diagnosis.md (the complete account) and any plot it does not show."""
    cfg = cfg or ReportConfig()
    diag = dd.diagnosis
    blocks: list = diagnosis_verdicts(diag)
    before_after = _before_after(dd, cfg)
    if before_after is not None:
        blocks.append(before_after)
    blocks += _diagnosis_summary(diag)
    fig_names = {
        rel: f"diagnose_{_slug(dd.axis)}_{_slug(rel.removesuffix('.png'))}" for rel in dd.images
    }
    referenced: set[str] = set()
    if dd.markdown:
        referenced = {rel for rel in dd.images if f"]({rel})" in dd.markdown}
        frag_images = {rel: (fig_names[rel], dd.images[rel]) for rel in referenced}
        blocks.append(
            MarkdownFragment(
                dd.markdown,
                frag_images,
                summary="The evidence: the diagnosis stage's full account (diagnosis.md: "
                "steps, candidates, paths)",
            )
        )
    for rel, png in dd.images.items():
        if rel not in referenced:
            blocks.append(Figure(fig_names[rel], png, f"{dd.axis}: {rel}"))
    for rel in dd.missing_images:
        blocks.append(
            Note(f"diagnose/{dd.axis}/{rel} is listed in diagnosis.json but not found.", "warn")
        )
    return Section(f"diagnosis-{_slug(dd.axis)}", dd.axis, tuple(blocks))


def _rmse(block: Any) -> float | None:
    """Held-out RMSE (deg) of a diagnosis.json ``baseline`` / ``final`` object."""
    if not isinstance(block, Mapping):
        return None
    return tables._finite(block.get("holdout_rmse_deg"))


def _open_alternatives(diag: Mapping[str, Any]) -> list[Mapping[str, Any]]:
    """The final ``not_excluded`` alternatives (diagnosis.json), as mappings."""
    alts = diag.get("not_excluded")
    return [a for a in alts if isinstance(a, Mapping)] if isinstance(alts, list) else []


def diagnosis_verdicts(diag: Mapping[str, Any]) -> list[Verdict]:
    """One-line judgements of a diagnosis.json: what was named (held-out RMSE start ->
    final), what the data cannot tell apart, whether the starting models agree."""
    named = [str(x) for x in diag.get("named_effects") or []]
    b, f = _rmse(diag.get("baseline")), _rmse(diag.get("final"))
    start = diag.get("start_model") or diag.get("start")
    who = f"{diag.get('dataset')}: " if diag.get("dataset") else ""
    rmse = (
        f" (held-out RMSE {fmt_sig(b, 3)} → {fmt_sig(f, 3)} deg)"
        if b is not None and f is not None
        else ""
    )
    if named:
        text = f"{who}named {', then '.join(named)}{rmse}" + (
            f", starting from {start}" if start else ""
        )
        out = [Verdict(text + ".", "ok")]
    else:
        held = f" (held-out RMSE {fmt_sig(f, 3)} deg)" if f is not None else ""
        text = (
            f"{who}nothing missing{held}: no candidate effect improved the held-out error "
            "by more than noise explains" + (f" (start: {start})" if start else "")
        )
        out = [Verdict(text + ".", "ok")]
    open_ = list(dict.fromkeys(str(a.get("effect")) for a in _open_alternatives(diag)))
    if open_:
        out.append(
            Verdict(
                f"Not told apart from the final model: {', '.join(open_)} (the held-out "
                "cycles cannot exclude it; see the experiment that would separate it below).",
                "warn",
            )
        )
    paths = diag.get("paths")
    if isinstance(paths, Mapping) and len(paths) > 1:
        answers = {
            tuple(p.get("named_effects") or ()) for p in paths.values() if isinstance(p, Mapping)
        }
        starts = " and ".join(map(str, paths))
        agree = len(answers) == 1
        out.append(
            Verdict(
                f"The {starts} starts "
                + ("agree." if agree else f"disagree (answer from {start})."),
                "ok" if agree else "warn",
            )
        )
    if diag.get("reconciliation"):
        out.append(Verdict(f"Starting models: {diag['reconciliation']}.", "info"))
    return out


def _before_after(dd: DiagnosisData, cfg: ReportConfig) -> Figure | None:
    """The starting model's residual figure beside the final model's (diagnosis.json
    ``figures``: the first and the last), from the stage's own PNGs."""
    figs = dd.diagnosis.get("figures")
    figs = [x for x in figs if isinstance(x, str)] if isinstance(figs, list) else []
    if not figs or figs[0] not in dd.images:
        return None
    diag = dd.diagnosis
    b, f = _rmse(diag.get("baseline")), _rmse(diag.get("final"))
    named = [str(x) for x in diag.get("named_effects") or []]
    start = str(diag.get("start_model") or "starting model")
    b_txt = f", held-out RMSE {fmt_sig(b, 3)} deg" if b is not None else ""
    f_txt = f", held-out RMSE {fmt_sig(f, 3)} deg" if f is not None else ""
    after = figs[-1] if len(figs) > 1 and figs[-1] in dd.images else None
    if after is None and dd.markdown and f"]({figs[0]})" in dd.markdown:
        return None  # nothing added: diagnosis.md below shows the one residual figure
    if after is None:
        png = figures.before_after_png(
            dd.images[figs[0]], None, (f"{start} (nothing added){b_txt}", ""), cfg.figure_dpi
        )
        caption = (
            f"{dd.axis}: residual of the starting model {start}, which is also the final "
            "model (nothing was added): residual vs time (held-out cycles shaded), vs "
            "input per branch, vs input rate, and the angle vs input."
        )
    else:
        png = figures.before_after_png(
            dd.images[figs[0]],
            dd.images[after],
            (f"before: {start}{b_txt}", f"after: {' + '.join([start, *named])}{f_txt}"),
            cfg.figure_dpi,
        )
        caption = (
            f"{dd.axis}: residual before (left, the starting model {start}) and after "
            f"(right, with {', '.join(named) or 'the effects'} added), each: residual vs time "
            "(held-out cycles shaded), vs input per branch, vs input rate, and the angle vs "
            f"input ({figs[0]}, {after})."
        )
    return Figure(f"diagnose_{_slug(dd.axis)}_before_after", png, caption)


def _values(params: Any) -> str:
    """``name = value`` pairs of fitted effect parameters (3 significant digits)."""
    if not isinstance(params, Mapping) or not params:
        return tables.DASH
    return ", ".join(f"{k} = {fmt_sig(v, 3)}" for k, v in params.items())


def named_effects_table(steps: list) -> Table | None:
    """One row per named effect (diagnosis.json ``steps``): its meaning, fitted values,
    held-out RMSE before -> after, the evidence (z, BIC change) and the step's verdict."""
    rows = []
    for i, st in enumerate(steps):
        if not isinstance(st, Mapping) or "effect" not in st:
            continue
        ev = st.get("evidence") if isinstance(st.get("evidence"), Mapping) else {}
        before = fmt_sig(st.get("holdout_rmse_before_deg"), 3)
        after = fmt_sig(st.get("holdout_rmse_after_deg"), 3)
        rows.append(
            (
                str(i + 1),
                str(st["effect"]),
                _clip(str(st.get("meaning") or tables.DASH), 120),
                _values(st.get("params")),
                f"{before} → {after}",
                fmt_sig(ev.get("z"), 2),
                fmt_sig(st.get("delta_bic"), 3),
            )
        )
    if not rows:
        return None
    return Table(
        (
            "step",
            "named effect",
            "meaning",
            "fitted values",
            "held-out RMSE (deg)",
            "z",
            "BIC change",
        ),
        tuple(rows),
        "Named effects in the order added, with their fitted values. z = held-out "
        "sum-of-squares reduction over its standard deviation (large = the effect is "
        "real); BIC change < 0 favours the effect.",
        align=("r", "l", "l", "l", "r", "r", "r"),
    )


def ties_table(diag: Mapping[str, Any]) -> Table | None:
    """The alternatives the held-out cycles could not exclude: at each step (against
    the effect named there) and against the final model (``not_excluded``), with their
    fitted values, how much they move the angle, z and the separating experiment."""
    rows: list[tuple[str, ...]] = []
    seen: set[tuple[str, str]] = set()

    def add(where: str, a: Mapping[str, Any]) -> None:
        key = (where, str(a.get("effect")))
        if key in seen or a.get("excluded"):
            return
        seen.add(key)
        rows.append(
            (
                where,
                str(a.get("effect", "?")),
                _values(a.get("params")),
                fmt_sig(a.get("effect_rms_deg"), 2),
                fmt_sig(a.get("z"), 2),
                _clip(str(a.get("experiment") or "none known"), 240),
            )
        )

    steps = diag.get("steps") if isinstance(diag.get("steps"), list) else []
    for i, st in enumerate(steps):
        if isinstance(st, Mapping):
            for a in st.get("alternatives") or []:
                if isinstance(a, Mapping):
                    add(f"step {i + 1} (vs {st.get('effect', '?')})", a)
    for a in _open_alternatives(diag):
        where = "final model" + (f" ({a['start']} start)" if a.get("start") else "")
        add(where, a)
    if not rows:
        return None
    return Table(
        (
            "against",
            "not excluded",
            "its fitted values",
            "moves the angle (deg RMS)",
            "z",
            "experiment that would separate them",
        ),
        tuple(rows[:40]),
        "Ties: effects the held-out cycles could not tell from the named one (or from the "
        "final model): z below the significance level. Their fitted values fit as well; "
        "the last column is a recording that would separate them.",
        align=("l", "l", "l", "r", "r", "l"),
    )


def paths_table(diag: Mapping[str, Any]) -> Table | None:
    """Each starting model's answer (``diagnose --start auto`` with several starts)."""
    paths = diag.get("paths")
    if not isinstance(paths, Mapping) or len(paths) < 2:
        return None
    rows = []
    for kind, p in paths.items():
        if not isinstance(p, Mapping):
            continue
        mark = " (answer)" if kind == diag.get("start_model") else ""
        rows.append(
            (
                f"{kind}{mark}",
                ", ".join(map(str, p.get("named_effects") or [])) or "nothing",
                f"{fmt_sig(_rmse(p.get('baseline')), 3)} → {fmt_sig(_rmse(p.get('final')), 3)}",
                _clip(str(p.get("summary") or ""), 240),
            )
        )
    return Table(
        ("start", "named", "held-out RMSE (deg)", "verdict"),
        tuple(rows),
        "Every starting model's path (diagnose --start auto).",
        align=("l", "l", "r", "l"),
    )


def _diagnosis_summary(diag: Mapping[str, Any]) -> list:
    """Named effects, start vs final metrics, the named effects' table (else the raw
    steps), the ties and the starting models' paths, from diagnosis.json."""
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
            Table(
                ("metric", "start", "final"),
                tuple(metric_rows),
                "Starting vs final model (RMSE in deg; BIC: lower is better; free parameters).",
            )
        )
    steps = diag.get("steps")
    if isinstance(steps, list) and steps:
        named_table = named_effects_table(steps)
        blocks.append(named_table if named_table is not None else _steps_table(steps))
    for table in (ties_table(diag), paths_table(diag)):
        if table is not None:
            blocks.append(table)
    return blocks


def _baseline_final_rows(diag: Mapping[str, Any]) -> list[tuple[str, str, str]]:
    base, final = diag.get("baseline"), diag.get("final")
    if not isinstance(base, Mapping) and not isinstance(final, Mapping):
        return []
    b = dict(tables.flatten(base)) if isinstance(base, Mapping) else {}
    f = dict(tables.flatten(final)) if isinstance(final, Mapping) else {}
    keys = list(b) + [k for k in f if k not in b]
    return [(METRIC_LABELS.get(k, k), _metric(b.get(k)), _metric(f.get(k))) for k in keys]


METRIC_LABELS = {
    "fit_rmse_deg": "fitted RMSE (deg)",
    "holdout_rmse_deg": "held-out RMSE (deg)",
    "bic": "BIC",
    "n_free": "free parameters",
}


def _metric(value: Any) -> str:
    """A diagnosis metric: whole numbers as they are, others to 4 significant digits."""
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return fmt_sig(value, 4)
    return tables.fmt(value)


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


COMPENSATION_FLAGS = (
    ("above_range", "target above the model's reach: clipped"),
    ("below_range", "target below the model's reach: clipped"),
    ("rate_limited", "command held back by the rate limit"),
    ("output_step", "the model's output steps here (nearest side taken)"),
    ("spike_removed", "an up-and-back spike removed"),
    ("within_delay", "within the model's delay (cannot be reached yet)"),
)
"""compensate.json ``flags`` in table order, with what each means (docs/compensate.md)."""


def _axes_doc(comp: CompensationData) -> dict[str, Mapping[str, Any]]:
    axes = comp.doc.get("axes")
    if not isinstance(axes, Mapping):
        return {}
    return {str(k): v for k, v in axes.items() if isinstance(v, Mapping)}


def _model_name(kind: Any) -> str:
    return dict(tables.FIT_MODELS).get(str(kind), str(kind))


def compensation_verdicts(axes: Mapping[str, Mapping[str, Any]]) -> list[Verdict]:
    """Per axis: the model and why, the predicted error, unreachable samples; the rate
    limit and the fastest command; the entry ramp; spikes left; the stage's warnings."""
    out = []
    for axis, a in axes.items():
        name = a.get("dataset", axis)
        out += [_model_verdict(name, a), _rate_verdict(name, a), *_start_verdicts(name, a)]
        if a.get("spikes_left"):
            out.append(
                Verdict(f"{name}: {a['spikes_left']} output spike(s) left in the commands.", "warn")
            )
        out += [Verdict(str(w), "warn") for w in a.get("warnings") or []]
    return out


def _model_verdict(name: str, a: Mapping[str, Any]) -> Verdict:
    """The model inverted for axis record ``a`` (compensate.json) and why, its predicted
    error and the target samples it cannot reach."""
    if a.get("model_choice") == "--model":
        why = "forced by --model"
    elif a.get("model_choice") == "ranking":  # an older compensate.json
        why = "best of the ranking"
    elif a.get("substitute"):
        why = f"instead of the recommended {a.get('recommended_model')}: {a['substitute']}"
    else:
        why = "the model fit.json recommends"
    n_bad, n = a.get("n_unreachable"), a.get("n_samples")
    main = (
        f"{name}: {_model_name(a.get('model', '?'))} ({why}): predicted RMSE "
        f"{fmt_sig(a.get('rmse_deg'), 2, pad=True)} deg, max "
        f"{fmt_sig(a.get('max_abs_err_deg'), 2, pad=True)} deg"
    )
    if n is not None:
        main += f"; {n_bad or 0} of {n} target samples unreachable"
    return Verdict(main + ".", "warn" if n_bad else "ok")


def _rate_verdict(name: str, a: Mapping[str, Any]) -> Verdict:
    """The rate limit of axis record ``a`` and where it came from, against the fastest
    command sent (a warning without a limit or above it)."""
    rate, seen = tables._finite(a.get("max_counts_per_s")), a.get("max_command_rate_per_s")
    if rate is None:
        return Verdict(
            f"{name}: no rate limit; the commands reach {fmt_sig(seen, 3)} counts/s.", "warn"
        )
    over = tables._finite(seen) is not None and float(seen) > rate * (1 + 1e-6)
    return Verdict(
        f"{name}: rate limit {fmt_sig(rate, 4)} counts/s "
        f"({a.get('max_counts_per_s_source', '?')}); the commands reach "
        f"{fmt_sig(seen, 4)} counts/s" + (" (above it)." if over else "."),
        "warn" if over else "ok",
    )


def _start_verdicts(name: str, a: Mapping[str, Any]) -> list[Verdict]:
    """How axis record ``a`` reaches the target: the conditioning sweep (or the start
    state's reason) and the entry ramp from the start counts."""
    out = []
    if a.get("n_conditioning"):
        reason = a.get("start_state_reason") or "the start state set to one the model knows"
        out.append(
            Verdict(
                f"{name}: conditioning sweep of {a['n_conditioning']} samples "
                f"({fmt_sig(a.get('conditioning_s'), 3)} s) over the fitted range first: "
                f"{reason}.",
                "info",
            )
        )
    elif a.get("start_state_reason"):
        out.append(Verdict(f"{name}: start state: {a['start_state_reason']}.", "info"))
    if a.get("n_entry"):
        out.append(
            Verdict(
                f"{name}: entry ramp of {a['n_entry']} samples "
                f"({fmt_sig(a.get('entry_s'), 3)} s) from {fmt_sig(a.get('start_counts'), 6)} "
                f"counts ({a.get('start_counts_source', '?')}) before the target's first "
                "sample.",
                "info",
            )
        )
    return out


def _flag_counts(comp: CompensationData, axis: str, two: bool) -> dict[str, int]:
    """Flag counts of ``axis``: compensate.json ``flags``, else counted in COMMANDS.csv."""
    a = _axes_doc(comp).get(axis, {})
    if isinstance(a.get("flags"), Mapping):
        counts = {str(k): int(v) for k, v in a["flags"].items() if tables._finite(v) is not None}
    elif "flags" in comp.commands:
        per = figures.axis_flags(comp.commands["flags"], axis, two)
        counts = {f: sum(f in x for x in per) for f, _ in COMPENSATION_FLAGS}
    else:
        counts = {}
    if a.get("n_entry") is not None:
        counts["entry"] = int(a["n_entry"])
    if a.get("n_conditioning"):
        counts["conditioning"] = int(a["n_conditioning"])
    return counts


def flag_table(comp: CompensationData, axes: list[str]) -> Table:
    """Flag counts per axis (rows: every flag; ``entry`` = the ramp's rows)."""
    counts = {a: _flag_counts(comp, a, len(axes) > 1) for a in axes}
    known = [f for f, _ in COMPENSATION_FLAGS]
    lead = ("conditioning", "entry")
    extra = sorted({f for c in counts.values() for f in c} - set(known) - set(lead))
    meaning = dict(COMPENSATION_FLAGS) | {
        "conditioning": "conditioning sweep: sets the hysteresis state, not tracking",
        "entry": "entry ramp before the target's first sample",
    }
    rows = [
        (f, meaning.get(f, ""), *(tables.fmt(counts[a].get(f)) for a in axes))
        for f in (*known, *extra, *lead)
        if any(f in counts[a] for a in axes)
    ]
    return Table(
        ("flag", "meaning", *(str(_axes_doc(comp).get(a, {}).get("dataset", a)) for a in axes)),
        tuple(rows),
        "Samples per flag (COMMANDS.csv flags column, compensate.json flags); a sample may "
        "carry several flags.",
        align=("l", "l", *("r" * len(axes))),
    )


def ranking_table(axes: Mapping[str, Mapping[str, Any]]) -> Table | None:
    """The models that could serve the target, best first (compensate.json ``ranking``)."""
    rows = []
    for axis, a in axes.items():
        for r in (a.get("ranking") or [])[:10]:
            if not isinstance(r, Mapping):
                continue
            rows.append(
                (
                    str(a.get("dataset", axis)),
                    tables.fmt(r.get("rank")),
                    _model_name(r.get("model")) + (" (chosen)" if r.get("chosen") else ""),
                    fmt_sig(r.get("predicted_rmse_deg"), 2, pad=True),
                    fmt_sig(r.get("holdout_rmse_deg"), 2, pad=True),
                    fmt_sig(r.get("score_deg"), 2, pad=True),
                    tables.fmt(r.get("output_steps")),
                    tables.fmt(r.get("continuous")),
                )
            )
    if not rows:
        return None
    return Table(
        (
            "dataset",
            "rank",
            "model",
            "predicted RMSE on the target (deg)",
            "held-out RMSE of the fit (deg)",
            "score (deg)",
            "output steps",
            "continuous",
        ),
        tuple(rows[:10]),
        "Models that could serve this target, for information (the model inverted is "
        "fit.json's decision unless --model forces one): models whose output steps where "
        "the target passes (more than 0.5 % of the samples) after the continuous ones, "
        "then by the score (the model's own error on this target and its held-out fit "
        "error in quadrature).",
        align=("l", "r", "l", "r", "r", "r", "r", "l"),
    )


def compensation_section(comp: CompensationData, cfg: ReportConfig) -> Section:
    """Feedforward compensation (``[compensate] target``): verdicts, target vs predicted
    and the commands with the rate limit and every flag, flag counts, the ranking."""
    axes_doc = _axes_doc(comp)
    blocks: list = compensation_verdicts(axes_doc)
    axes = [a for a in axes_doc if f"enc_{a}" in comp.commands]
    if axes:
        blocks.append(_compensation_figure(comp, axes, axes_doc, cfg))
    blocks.append(_compensation_error_table(axes_doc))
    if axes:
        blocks.append(flag_table(comp, axes))
    ranking = ranking_table(axes_doc)
    if ranking is not None:
        blocks.append(ranking)
    blocks.append(
        Paragraph(
            "Motor commands that make the fitted model follow the target angle (exact "
            "inversion of the stateful model, sample by sample; docs/compensate.md). The "
            "error is the model's, not a measurement: run the commands on the robot and "
            "track the result to measure the achieved angle."
        )
    )
    return Section("compensation", "Feedforward compensation", tuple(blocks))


def _compensation_figure(
    comp: CompensationData, axes: list[str], axes_doc: dict, cfg: ReportConfig
) -> Figure:
    """The compensation figure of ``axes`` (:func:`figures.compensation_figure_png`)
    with its caption."""
    png = figures.compensation_figure_png(
        comp.commands,
        comp.target,
        axes,
        axes_doc,
        dpi=cfg.figure_dpi,
        max_points=cfg.max_plot_points,
    )
    return Figure(
        "compensation",
        png,
        "Per axis, top to bottom: the target (grey) and the angle the model predicts "
        "for the commands; their difference with every flagged sample marked (count "
        "in the legend); the motor command within the fitted input range (dotted); "
        "the command's rate (counts/s, step to step) with the rate limit (dashed). "
        "Grey band: the entry ramp before the target's first sample; hatched band: the "
        "conditioning sweep that sets the hysteresis state (docs/compensate.md).",
    )


def _compensation_error_table(axes_doc: Mapping[str, Mapping]) -> Table:
    """Per axis of compensate.json: dataset, model, RMSE and max error of the predicted
    angle vs the target (deg), and the unreachable samples with why."""
    rows = []
    for axis, a in axes_doc.items():
        un = a.get("unreachable", {}) if isinstance(a.get("unreachable"), Mapping) else {}
        why = ", ".join(f"{k} {v}" for k, v in un.items() if v) or "-"
        rows.append(
            (
                axis,
                str(a.get("dataset", "?")),
                _model_name(a.get("model", "?")),
                fmt_sig(a.get("rmse_deg"), 3),
                fmt_sig(a.get("max_abs_err_deg"), 3),
                f"{a.get('n_unreachable', 0)} of {a.get('n_samples', 0)} ({why})",
            )
        )
    return Table(
        ("axis", "dataset", "model", "RMSE (deg)", "max |error| (deg)", "unreachable"),
        tuple(rows),
        "Predicted angle vs target for the commands in compensate/commands.csv.",
    )
