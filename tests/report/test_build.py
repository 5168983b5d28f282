"""Document assembly: every section present with data, and each degrades alone."""

from __future__ import annotations

from dataclasses import replace

import pytest
from runfolder import STAGE_FILES

from i2ris_calib.report.build import build_document, section_count
from i2ris_calib.report.config import ReportConfig
from i2ris_calib.report.data import RunData
from i2ris_calib.report.document import (
    Figure,
    MarkdownFragment,
    Note,
    Paragraph,
    Table,
    Verdict,
)

CFG = ReportConfig(figure_dpi=40)
REAL_FIGURE_TESTS = {"test_complete_run_has_every_section_and_figure"}


@pytest.fixture(autouse=True)
def fast_figures(request, monkeypatch):
    """Stub the matplotlib figures (tested in test_figures.py) unless a test asks for real ones.

    The stub still records which data each figure was given, one tiny PNG per call.
    """
    if request.node.name in REAL_FIGURE_TESTS:
        return
    from runfolder import tiny_png

    from i2ris_calib.report import figures

    for name in ("fit_figure_png", "tracking_figure_png", "synced_figure_png", "clock_figure_png"):
        monkeypatch.setattr(figures, name, lambda *a, **k: tiny_png())


def _walk(sections):
    for s in sections:
        yield s
        yield from _walk(s.subsections)


def _blocks(doc, anchor: str, kind=object):
    sec = next(s for s in _walk(doc.sections) if s.anchor == anchor)
    return [b for s in _walk((sec,)) for b in s.blocks if isinstance(b, kind)]


def test_complete_run_has_every_section_and_figure(run_data):
    run, truth = run_data
    doc = build_document(run, CFG, {"version": "0.1.0", "inputs": {"a": "b"}, "config": {"x": 1}})
    anchors = [s.anchor for s in doc.sections]
    assert anchors == [
        "overview",
        "accuracy",
        "fig6",
        "parameters",
        "diagnosis",
        "tracking",
        "sync",
        "provenance",
        "appendix",
    ]
    names = [f.name for f in doc.figures()]
    # 4 Fig-6 figures (2 axes x 2 directions), tracking, clock, synced loops, 2 diagnosis PNGs.
    assert sorted(n for n in names if n.startswith("fig6_")) == [
        "fig6_pitch_pitch_neg",
        "fig6_pitch_pitch_pos",
        "fig6_yaw_yaw_neg",
        "fig6_yaw_yaw_pos",
    ]
    assert {"tracking_quality", "clock", "synced_loops"} <= set(names) and len(names) == 9
    assert not _blocks(doc, "overview", Note)
    params = next(s for s in doc.sections if s.anchor == "parameters")
    assert [s.title for s in params.subsections] == ["yaw+", "yaw-", "pitch+", "pitch-"]
    units = {r[0]: r[1] for r in params.subsections[0].blocks[0].rows}
    assert units["a1"] == "deg/count" and units["kappa"] == "1"  # from the model declarations
    acc = _blocks(doc, "accuracy", Table)
    assert [t.caption.split(":")[0] for t in acc] == ["yaw"] * 3 + ["pitch"] * 3
    # per axis: our metrics, the samples accounting, the paper's values
    assert [t.rows[0][1] for t in acc[:3]] == [
        "fitted",
        str(truth["fit"]["yaw"]["datasets"][0]["rows"]["total"]),
        "paper",
    ]
    assert [r[0] for r in acc[0].rows] == ["EGPI_C"] * 2 + ["EGPI"] * 2 + ["GPI"] * 2
    fig6 = [f for f in doc.figures() if f.name == "fig6_yaw_yaw_pos"][0]
    rows = truth["fit"]["yaw"]["datasets"][0]["rows"]
    assert (
        f"Own samples: {rows['fitted']} fitted, {rows['holdout']} held out (yellow: held-out "
        f"cycles), {rows['angle_missing']} not measured. The "
        f"{rows['total'] - rows['in_direction']} samples of the other direction" in fig6.caption
    )


def test_progress_is_called_once_per_section(run_data):
    run, _ = run_data
    calls: list[str] = []
    doc = build_document(run, CFG, progress=calls.append)
    assert len(calls) == len(doc.sections) == section_count(run) == 9
    empty = RunData("e")
    calls.clear()
    assert len(build_document(empty, CFG, progress=calls.append).sections) == len(calls)
    assert len(calls) == section_count(empty)


def test_headline_ratio_from_fit_json(run_data):
    run, truth = run_data
    doc = build_document(run, CFG)
    headline = _blocks(doc, "overview", Table)[1]
    assert headline.header == (
        "dataset",
        "EGPI_C held-out RMSE (deg)",
        "EGPI held-out RMSE (deg)",
        "GPI held-out RMSE (deg)",
        "GPI / EGPI",
    )
    d = truth["fit"]["yaw"]["datasets"][0]
    c, e, g = (d["models"][k]["holdout_metrics"]["rmse_deg"] for k in ("egpi_c", "egpi", "gpi"))
    assert headline.rows[0] == ("yaw+", f"{c:.3f}", f"{e:.3f}", f"{g:.3f}", f"{g / e:.2f}")
    assert "not converged" not in headline.caption
    # a failed fit is starred in its own cell only (model x dataset)
    run.fits[0].fit["datasets"][1]["models"]["gpi"]["converged"] = False
    headline = _blocks(build_document(run, CFG), "overview", Table)[1]
    assert [r[3].endswith("*") for r in headline.rows] == [False, True, False, False]
    assert not any(c.endswith("*") for r in headline.rows for c in (*r[1:3], r[4]))
    assert "* = not converged" in headline.caption


def test_signed_dataset_gets_its_own_figure_name(run_data):
    run, _ = run_data
    fit = run.fits[0].fit
    d = {**fit["datasets"][0], "name": "yaw±", "direction": "±", "abs_fitted": False}
    pred = run.fits[0].predictions.assign(dataset="yaw±", split="fit")
    fd = replace(run.fits[0], fit={**fit, "datasets": [d]}, predictions=pred)
    doc = build_document(replace(run, fits=(fd,)), CFG)
    assert [f.name for f in doc.figures() if f.name.startswith("fig6_")] == ["fig6_yaw_yaw_signed"]


def test_empty_run_states_every_missing_output():
    absent = dict.fromkeys(STAGE_FILES, "not found")
    doc = build_document(RunData("empty", absent=absent), CFG)
    assert doc.figures() == []
    notes = " ".join(b.text for s in _walk(doc.sections) for b in s.blocks if isinstance(b, Note))
    for label in absent:
        assert label in notes
    assert "diagnosis" not in [s.anchor for s in doc.sections]


@pytest.mark.parametrize("missing", ["angles", "track", "sync", "synced", "predictions"])
def test_each_missing_part_degrades_alone(run_data, missing):
    run, _ = run_data
    label = {
        "angles": "track/angles.csv",
        "track": "track/track.json",
        "sync": "sync/sync.json",
        "synced": "sync/synced.csv",
        "predictions": "fit/yaw/predictions.csv",
    }[missing]
    if missing == "predictions":
        run = replace(
            run,
            fits=(replace(run.fits[0], predictions=None), run.fits[1]),
            absent={label: "not found"},
        )
    else:
        run = replace(run, **{missing: None}, absent={label: "not found"})
    doc = build_document(run, CFG)
    notes = [b.text for s in _walk(doc.sections) for b in s.blocks if isinstance(b, Note)]
    assert any(label in n for n in notes)
    full = len(build_document(run_data[0], CFG).figures())
    lost = {"angles": 1, "track": 0, "sync": 1, "synced": 1, "predictions": 2}[missing]
    assert len(doc.figures()) == full - lost


def test_predictions_without_a_dataset_row_is_a_warning(run_data):
    run, _ = run_data
    pred = run.fits[0].predictions
    run = replace(run, fits=(replace(run.fits[0], predictions=pred[pred["dataset"] == "yaw+"]),))
    doc = build_document(run, CFG)
    warns = [b.text for b in _blocks(doc, "fig6", Note)]
    assert warns == ["predictions.csv has no rows for dataset 'yaw-'."]


def test_diagnosis_fragment_is_embedded_with_unreferenced_plots_after_it(run_data):
    run, _ = run_data
    doc = build_document(run, CFG)
    sec = next(s for s in _walk(doc.sections) if s.anchor == "diagnosis-yaw")
    assert isinstance(sec.blocks[0], Verdict)  # the section opens with its verdict
    frag, fig = sec.blocks[-2:]
    assert isinstance(frag, MarkdownFragment) and frag.text == run.diagnoses[0].markdown
    assert list(frag.images) == ["plots/step1_before.png"]  # the one the fragment references
    assert isinstance(fig, Figure) and fig.name == "diagnose_yaw_plots_step1_after"


def test_diagnosis_summary_without_fragment(run_data):
    run, _ = run_data
    dd = replace(run.diagnoses[0], markdown=None)
    doc = build_document(replace(run, diagnoses=(dd,)), CFG)
    sec = next(s for s in _walk(doc.sections) if s.anchor == "diagnosis-yaw")
    paras = [b.text for b in sec.blocks if isinstance(b, Paragraph)]
    assert paras == ["Named effects, in the order added: axis_coupling."]
    base_final, steps = [b for b in sec.blocks if isinstance(b, Table)]
    rows = dict((r[0], r[1:]) for r in base_final.rows)
    assert rows["held-out RMSE (deg)"] == ("0.91", "0.31")
    assert steps.header[:4] == ("step", "named effect", "meaning", "fitted values")
    assert steps.rows[0][:2] == ("1", "axis_coupling")
    assert steps.rows[0][3:5] == ("c_deg_per_count = 0.001", "0.91 → 0.31")
    assert [f.name for f in sec.blocks if isinstance(f, Figure)] == [
        "diagnose_yaw_plots_step1_before",
        "diagnose_yaw_plots_step1_after",
    ]


def test_no_named_effect_is_said(run_data):
    run, _ = run_data
    dd = replace(
        run.diagnoses[0],
        diagnosis={**run.diagnoses[0].diagnosis, "named_effects": []},
        markdown=None,
        missing_images=("plots/gone.png",),
    )
    doc = build_document(replace(run, diagnoses=(dd,)), CFG)
    sec = next(s for s in _walk(doc.sections) if s.anchor == "diagnosis-yaw")
    assert sec.blocks[0].text.startswith("nothing missing (held-out RMSE 0.31 deg)")
    paras = [b.text for b in sec.blocks if isinstance(b, Paragraph)]
    assert paras[0].startswith("Named effects, in the order added: none")
    assert any(isinstance(b, Note) and "plots/gone.png" in b.text for b in sec.blocks)


def test_provenance_lists_every_stage_json(run_data):
    run, _ = run_data
    doc = build_document(run, CFG, {"version": "0.1.0", "inputs": {}, "config": {}})
    labels = [
        s.title for s in next(s for s in doc.sections if s.anchor == "provenance").subsections
    ]
    assert labels == [
        "this report",
        "track/track.json",
        "sync/sync.json",
        "fit/yaw/fit.json",
        "fit/pitch/fit.json",
        "diagnose/yaw/diagnosis.json",
    ]


def test_missing_axis_that_does_not_move_is_explained(run_data):
    run, _ = run_data
    still = run.synced.assign(enc_pitch=7)
    run = replace(run, fits=run.fits[:1], synced=still, absent={"fit/pitch/fit.json": "not found"})
    notes = [b.text for b in _blocks(build_document(run, CFG), "accuracy", Note)]
    assert notes == [
        "fit/pitch/fit.json: not found (its encoder does not move in sync/synced.csv); "
        "this axis is not shown."
    ]


def test_stage_warnings_are_listed_in_the_overview():
    """Warnings recorded by track, sync and fit reach the report's overview."""
    from i2ris_calib.report.build import overview_section, run_warnings
    from i2ris_calib.report.data import FitData, RunData

    fit = {
        "schema": "i2ris-calib.fit/1",
        "axis": "yaw",
        "datasets": [
            {
                "name": "yaw+",
                "models": {
                    "gpi": {"warnings": ["the model explains only 3 % of the angle's variance"]}
                },
            }
        ],
    }
    run = RunData(
        name="r",
        track={"warnings": ["top: 12 dropped frames"]},
        sync={"warnings": ["yaw_deg follows enc_pitch"]},
        fits=(FitData(axis="yaw", fit=fit),),
    )
    w = run_warnings(run)
    assert [x[0] for x in w] == ["track", "sync", "fit"]
    texts = " ".join(str(b) for b in overview_section(run).blocks)
    assert "3 warning(s)" in texts and "explains only 3 %" in texts
