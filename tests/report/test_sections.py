"""The clock, tracking and overview sections: what a reader judges each stage by."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
from runfolder import write_fit

from i2ris_calib.report import tables
from i2ris_calib.report.build import build_document, sync_section, tracking_section
from i2ris_calib.report.clock import angle_rate_p95, clock_view, stated_clock
from i2ris_calib.report.config import ReportConfig
from i2ris_calib.report.document import Code, Figure, Table, Verdict
from i2ris_calib.report.recommend import recommend
from i2ris_calib.report.render import render_markdown
from i2ris_calib.report.verdicts import angle_noise_deg, longest_unmeasured, tracking_verdicts
from i2ris_calib.sync.clock import ClockModel

CFG = ReportConfig(figure_dpi=40)


def _sync_json(clock: ClockModel, t_ref: float, t_range=(0.0, 60.0), **extra) -> dict:
    """sync.json's clock fields exactly as commands/sync.py writes them."""
    return {
        "method": clock.method,
        "method_requested": "auto",
        "offset_s": clock.offset_at(0.0),
        "drift_ppm": clock.drift_ppm,
        "offset_stderr_s": clock.offset_stderr_at(0.0),
        "drift_stderr_ppm": clock.drift_stderr_ppm,
        "t_ref_cam_s": t_ref,
        "offset_at_t_ref_s": clock.offset_at(t_ref),
        "offset_at_t_ref_stderr_s": clock.offset_stderr_at(t_ref),
        "camera_time_range_s": list(t_range),
        "n_rows": 1800,
        "n_dropped_outside_log": 0,
        **extra,
    }


@pytest.mark.parametrize("rho", [-0.9, -0.3, 0.0, 0.6])
def test_stated_clock_sd_equals_the_sync_stage_covariance_at_every_time(rho):
    """Three stated standard errors fix the (offset, drift) covariance: the band the
    report draws is the one the sync stage's ClockModel states, at every camera time."""
    so, sd = 3e-4, 8.0
    cov = np.array([[so**2, rho * so * sd], [rho * so * sd, sd**2]])
    clock = ClockModel(12.5, 75.0, so, sd, cov, "event")
    line = stated_clock(_sync_json(clock, 31.2))
    t = np.linspace(-10.0, 80.0, 37)
    truth = np.array([clock.offset_stderr_at(x) for x in t])
    np.testing.assert_allclose(line.sd(t), truth, rtol=1e-6)
    np.testing.assert_allclose(line.offset(t), [clock.offset_at(x) for x in t], rtol=0, atol=1e-12)


def test_clock_view_worst_error_edges_and_method_reason():
    cov = np.diag([(2e-4) ** 2, 6.0**2])
    clock = ClockModel(12.5, 75.0, 2e-4, 6.0, cov, "event")
    edges = [
        {
            "camera": "top",
            "kind": "on",
            "t_cam_s": t,
            "t_cam_sd_s": 3e-4,
            "t_ctrl_sd_s": 2e-4,
            "t_ctrl_s": t + clock.offset_at(t) + r,
        }  # fmt: skip
        for t, r in ((0.5, 1e-4), (20.0, -2e-4), (59.0, 5e-3))  # the last one 14 sd off
    ]
    sync = _sync_json(clock, 30.0, evidence={"n_camera_edges": 3, "n_log_edges": 2, "edges": edges})
    view = clock_view(sync)
    worst, at = view.worst_sd()
    assert at == 60.0 and worst == pytest.approx(clock.offset_stderr_at(60.0), rel=1e-9)
    assert [e.residual_s for e in view.edges] == pytest.approx([1e-4, -2e-4, 5e-3], abs=1e-9)
    assert view.why.startswith("LED flash edges")  # auto, no evidence.auto: from the method
    assert tables.clock_table(view, sync).rows[0] == ("method used (asked)", "event (auto)")
    verdicts = [v for v in sync_section_blocks(sync) if isinstance(v, Verdict)]
    edge = next(v for v in verdicts if "flash edges matched" in v.text)
    assert edge.status == "warn" and "1 beyond 3 sd" in edge.text


def sync_section_blocks(sync: dict, synced: pd.DataFrame | None = None) -> list:
    from i2ris_calib.report.data import RunData

    return list(sync_section(RunData("r", sync=sync, synced=synced), CFG).blocks)


def test_sync_section_first_screen_and_size(run_data):
    """Verdicts first, then one clock figure and a table of at most 15 rows; no dump."""
    run, truth = run_data
    sec = sync_section(run, CFG)
    kinds = [type(b).__name__ for b in sec.blocks]
    assert kinds[: kinds.index("Figure")] == ["Verdict"] * kinds.index("Figure")
    assert kinds.index("Figure") >= 3
    table = next(b for b in sec.blocks if isinstance(b, Table))
    assert len(table.rows) <= 15
    rows = dict(table.rows)
    assert rows["drift"] == tables.fmt_pm(truth["sync"]["drift_ppm"], 2.5) + " ppm"
    assert [b.name for b in sec.blocks if isinstance(b, Figure)] == ["clock", "synced_loops"]
    # the stated error verdict turns it into an angle error with the recording's speed
    stated = next(b for b in sec.blocks if isinstance(b, Verdict) and "Stated clock" in b.text)
    rate = max(
        angle_rate_p95(run.synced["time_s"], run.synced[c]) for c in ("yaw_deg", "pitch_deg")
    )
    assert f"{tables.fmt_sig(rate, 2)} deg/s" in stated.text


def test_no_table_in_view_over_40_rows_and_raw_json_in_appendix(run_data):
    run, _ = run_data
    doc = build_document(run, CFG)

    def walk(secs):
        for s in secs:
            yield s
            yield from walk(s.subsections)

    for s in walk(doc.sections):
        for b in s.blocks:
            if isinstance(b, Table):
                assert len(b.rows) <= 40, (s.anchor, b.caption)
    appendix = doc.sections[-1]
    assert appendix.anchor == "appendix"
    codes = [b for b in appendix.blocks if isinstance(b, Code)]
    assert [c.summary.split(" ")[0] for c in codes] == ["track/track.json", "sync/sync.json"]
    md, _ = render_markdown(doc)
    assert '"offset_stderr_s"' not in md and "Raw sync/sync.json: see the file" in md


def test_tracking_verdicts_and_status_timeline(run_data):
    run, truth = run_data
    sec = tracking_section(run, CFG)
    verdict = next(b for b in sec.blocks if isinstance(b, Verdict))
    assert verdict.text.startswith(
        "92.5 % of 600 frames measured (30 not_found, 10 ambiguous, 5 rejected)"
    )
    assert verdict.status == "warn"  # below 95 %
    # the longest stretch: the 30 not_found frames (1.0 s)
    assert "1.0 s from t = 3.83 s" in verdict.text
    assert len(next(b for b in sec.blocks if isinstance(b, Table)).rows) <= 15
    track = {
        "reference": {"roll_correction_deg": 0.251429, "roll_sd_deg": 0.008831, "roll_method": "session", "fit_frames": 1873},
        "lagged_camera_refit_frames": [3, 4],
        "lagged_camera_flagged_frames": [9],
        "lagged_camera_spread_deg": {"median": 0.004, "p99": 0.25, "tolerance": 0.2},
        "view_check": {"rigid_rig_spread_mm": {"as_labelled": 0.0011, "swapped": 0.35}, "frames": 400, "verdict": "consistent"},
    }  # fmt: skip
    v = {x.text.split(" ")[0]: x for x in tracking_verdicts(None, track)}
    assert v["Reference"].status == "ok" and "0.2514 ± 0.0088 deg" in v["Reference"].text
    assert v["Lagged"].status == "warn" and "2 frames refitted" in v["Lagged"].text
    assert v["Camera"].status == "ok"
    track["view_check"]["verdict"] = "swapped"
    assert {x.text.split(" ")[0]: x for x in tracking_verdicts(None, track)}[
        "Camera"
    ].status == "warn"


def test_angle_noise_and_longest_gap_known_truth():
    rng = np.random.default_rng(0)
    t = np.arange(3000) / 30
    a = 10 * np.sin(2 * np.pi * t / 20) + rng.normal(0, 0.01, t.size)
    assert angle_noise_deg(t, a) == pytest.approx(0.01, rel=0.1)
    status = np.array(["measured"] * 100, dtype=object)
    status[10:13] = "not_found"
    status[50:60] = "rejected"
    dur, start = longest_unmeasured(
        pd.DataFrame({"time_s": np.arange(100) * 0.1, "status": status})
    )
    assert dur == pytest.approx(1.0) and start == pytest.approx(5.0)


def test_recommendation_rule(tmp_path):
    fit = write_fit(tmp_path, "yaw")
    d = tables.fit_datasets(fit)[0]
    pred = pd.read_csv(tmp_path / "fit" / "yaw" / "predictions.csv")
    pred = pred[pred["dataset"] == "yaw+"]
    r = recommend(d, pred)
    # fixture: held-out errors 0.2 sin (EGPI) < 0.4 sin (EGPI_C) < 1.2 sin (GPI)
    assert r.model == "egpi" and "lowest held-out RMSE" in r.why and "GPI is 6.0x worse" in r.why
    assert "steps at the flag point" in r.why
    own = pred[(pred["split"] != "other") & pred["theta_deg"].notna()]
    assert r.support.startswith(
        f"input {tables.fmt_sig(own['v'].min(), 4)}–{tables.fmt_sig(own['v'].max(), 4)} counts"
    )
    # EGPI_C within 10 % of EGPI: the continuous model is recommended
    e = d["models"]["egpi"]["holdout_metrics"]["rmse_deg"]
    d["models"]["egpi_c"]["holdout_metrics"]["rmse_deg"] = 1.05 * e
    assert recommend(d, pred).model == "egpi_c"
    # a model that did not converge is never recommended; unidentified parameters named
    d["models"]["egpi_c"]["converged"] = False
    d["models"]["egpi"]["stderr"]["a5"] = 10 * abs(d["models"]["egpi"]["params"]["a5"])
    r = recommend(d, pred)
    assert r.model == "egpi" and "not identified by these data (a5)" in r.why
    # no predictions: the range from fit.json
    assert recommend({**d, "input_range_counts": [0, 6000]}).support == "input 0–6000 counts"


def test_overview_leads_with_the_recommendation(run_data):
    run, _ = run_data
    doc = build_document(run, CFG)
    first = doc.sections[0].blocks[0]
    assert isinstance(first, Table) and first.header[:2] == ("dataset", "recommended model")
    assert [r[0] for r in first.rows] == ["yaw+", "yaw-", "pitch+", "pitch-"]


def test_fit_only_run_has_model_sections_alone(run_data):
    run, _ = run_data
    only = replace(run, angles=None, track=None, sync=None, synced=None, diagnoses=(), fit_only=True, fits=run.fits[:1])  # fmt: skip
    doc = build_document(only, CFG)
    assert [s.anchor for s in doc.sections] == [
        "overview",
        "accuracy",
        "fig6",
        "parameters",
        "provenance",
    ]
    stage_rows = doc.sections[0].blocks[2].rows
    assert stage_rows == (("fit", "fit.json", "found"), ("fit", "predictions.csv", "found"))
