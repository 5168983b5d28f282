"""`i2ris-calib report RUN_DIR`: reading run folders, writing the report, bad input."""

from __future__ import annotations

import base64
import hashlib
import importlib.util
import json
import re
from pathlib import Path

import pytest

from i2ris_calib.cli import main
from i2ris_calib.commands.report import write_report
from i2ris_calib.config import PipelineConfig
from i2ris_calib.errors import CalibError
from i2ris_calib.io.outputs import MARKER
from i2ris_calib.io.run_folder import load_run, png_paths
from i2ris_calib.report.config import ReportConfig

_spec = importlib.util.spec_from_file_location(
    "report_runfolder", Path(__file__).parents[1] / "report" / "runfolder.py"
)
runfolder = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(runfolder)

CFG = PipelineConfig(report=ReportConfig(figure_dpi=40))


@pytest.fixture
def run_dir(tmp_path):
    root = tmp_path / "session_a"
    runfolder.make_run_folder(root, diagnosis=True)
    return root


def test_write_report_outputs_and_markdown_links(run_dir):
    page = write_report(run_dir, None, CFG)
    out = run_dir / "report"
    assert page == out / "report.html"
    assert sorted(p.name for p in out.iterdir() if p.name != MARKER) == [
        "figures",
        "report.html",
        "report.md",
    ]
    assert json.loads((out / MARKER).read_text())["command"] == "report"
    md = (out / "report.md").read_text()
    links = re.findall(r"\]\((figures/[^)]+\.png)\)", md)
    files = sorted(p.relative_to(out).as_posix() for p in (out / "figures").iterdir())
    assert sorted(set(links)) == files and len(files) == 9
    html = page.read_text()
    # Every PNG beside the Markdown is also inlined in the HTML, byte for byte.
    inlined = {base64.b64decode(s) for s in re.findall(r"data:image/png;base64,([^\"]+)", html)}
    assert {(out / f).read_bytes() for f in files} == inlined
    # sync offset (s) with its stderr, shown in both twins; the raw sync.json only in the HTML
    assert "0.25000 ± 0.00040 s" in html and "0.25000 ± 0.00040 s" in md
    assert "<details><summary>sync/sync.json (raw" in html and '"offset_s": 0.25' not in md
    assert not list(run_dir.glob(".report.tmp-*"))


@pytest.fixture
def stub_figures(monkeypatch):
    """Replace the matplotlib figures by a tiny PNG (figures are tested in tests/report)."""
    from i2ris_calib.report import figures

    for name in ("fit_figure_png", "tracking_figure_png", "synced_figure_png", "clock_figure_png"):
        monkeypatch.setattr(figures, name, lambda *a, **k: runfolder.tiny_png())


def test_report_provenance_hashes_inputs_relative_to_run(run_dir, stub_figures):
    run, inputs = load_run(run_dir)
    write_report(run_dir, None, CFG)
    md = (run_dir / "report" / "report.md").read_text()
    for rel in (
        "track/angles.csv",
        "sync/sync.json",
        "fit/yaw/predictions.csv",
        "diagnose/yaw/plots/step1_after.png",
    ):
        digest = hashlib.sha256((run_dir / rel).read_bytes()).hexdigest()
        assert f"| input {rel} | sha256 {digest} |" in md


def test_report_is_deterministic(tmp_path):
    run_dir = tmp_path / "s"
    runfolder.make_run_folder(run_dir, fit_axes=("yaw",), diagnosis=True)
    write_report(run_dir, tmp_path / "r1", CFG)
    write_report(run_dir, tmp_path / "r2", CFG)
    for name in ("report.html", "report.md", "figures/fig6_yaw_yaw_pos.png"):
        assert (tmp_path / "r1" / name).read_bytes() == (tmp_path / "r2" / name).read_bytes()


def test_empty_run_folder_is_refused_every_time(tmp_path, capsys):
    """Was: exit 0 with every stage "not found", then exit 2 on the second call (the
    report/ folder it had written was "an unrelated folder")."""
    root = tmp_path / "empty"
    root.mkdir()
    for _ in range(2):
        assert main(["report", str(root)]) == 2
        err = capsys.readouterr().err
        assert "nothing to report" in err and err.count("\n") == 1
        assert list(root.iterdir()) == []


def test_a_stage_folder_alone_gives_a_report_that_says_what_is_missing(tmp_path, capsys):
    root = tmp_path / "only_track"
    (root / "track").mkdir(parents=True)
    assert main(["report", str(root)]) == 0
    out, err = capsys.readouterr()
    assert out.startswith("wrote ") and "report.html" in out and err == ""  # no blank line
    md = (root / "report" / "report.md").read_text()
    for label in runfolder.STAGE_FILES:
        assert f"{label}: not found" in md


def test_partial_run_and_header_only_csv(tmp_path):
    root = tmp_path / "partial"
    runfolder.make_run_folder(root, sync=False, fit_axes=("yaw",), predictions=False)
    (root / "track" / "angles.csv").write_text(
        "frame,time_s,yaw_deg,pitch_deg,status,reproj_err_px\n"
    )
    run, _ = load_run(root)
    assert run.angles is None and run.absent["track/angles.csv"] == "present but has no data rows"
    assert [f.axis for f in run.fits] == ["yaw"] and run.fits[0].predictions is None
    write_report(root, None, CFG)
    md = (root / "report" / "report.md").read_text()
    assert "fit/yaw/predictions.csv: not found" in md and "sync/sync.json: not found" in md


def _one_line_error(args, capsys) -> str:
    rc = main(args)
    err = capsys.readouterr().err
    assert rc == 2, err
    assert err.startswith("error: ") and len(err.strip().splitlines()) == 1
    assert "Traceback" not in err
    return err


@pytest.mark.parametrize(
    ("rel", "content", "expect"),
    [
        ("sync/sync.json", '{"offset_s": 0.1,', "malformed JSON"),
        ("track/track.json", "[1, 2]", "expected a JSON object"),
        ("fit/yaw/fit.json", '{"schema": "i2ris-calib.fit/1", "axis": "yaw"}', "no 'datasets'"),
        (
            "fit/yaw/fit.json",
            '{"datasets": [{"name": "yaw+", "models": {"gpi": {"metrics": {"rmse_deg": "big"}}}}]}',
            "rmse_deg = 'big' is not a number",
        ),
        ("sync/synced.csv", "time_s,enc_yaw\n0,1\n", "missing column(s) enc_pitch"),
        (
            "track/angles.csv",
            "time_s,yaw_deg,pitch_deg,status\n0,1,x1,measured\n",
            "column 'pitch_deg' has non-numeric value 'x1' (row 2)",
        ),
        ("fit/pitch/predictions.csv", 'dataset,time_s,v,theta_deg,split\n"a,1\n', "malformed CSV"),
        (
            "fit/pitch/predictions.csv",
            "dataset,time_s,v,theta_deg,split\na,1,2,3,fit\n",
            "no model column (none of gpi_deg, egpi_deg",
        ),
        (
            "fit/pitch/predictions.csv",
            "dataset,time_s,v,theta_deg,egpi_c_deg,split\na,1,2,3,4,fit\na,2,2,3,4,train\n",
            "column 'split' has value 'train' (row 3); expected one of fit, holdout, other",
        ),
        (
            "fit/yaw/fit.json",
            '{"datasets": [{"name": "yaw+", "rows": {"fitted": "many"}, "models": {}}]}',
            "datasets[0].rows.fitted = 'many' is not a number",
        ),
        (
            "fit/yaw/fit.json",
            '{"datasets": [{"name": "yaw+", "models": {"gpi": {"converged": "no"}}}]}',
            "datasets[0].models.gpi.converged = 'no' is not true/false",
        ),
        ("diagnose/yaw/diagnosis.json", "{nope}", "malformed JSON"),
    ],
)
def test_malformed_input_is_one_line_error_naming_the_file(run_dir, capsys, rel, content, expect):
    (run_dir / rel).write_text(content)
    with pytest.raises(CalibError, match=re.escape(expect)):
        load_run(run_dir)
    err = _one_line_error(["report", str(run_dir)], capsys)
    assert str(run_dir / rel) in err and expect in err
    assert not (run_dir / "report").exists()  # nothing half-written


def test_missing_run_dir_and_unsafe_out(tmp_path, run_dir, capsys):
    assert "run folder not found" in _one_line_error(["report", str(tmp_path / "nope")], capsys)
    assert "contains the run folder" in _one_line_error(
        ["report", str(run_dir), "--out", str(run_dir)], capsys
    )
    other = tmp_path / "precious"
    other.mkdir()
    (other / "notes.txt").write_text("keep me")
    assert "did not write" in _one_line_error(["report", str(run_dir), "--out", str(other)], capsys)
    assert (other / "notes.txt").read_text() == "keep me"


def test_rerun_replaces_the_previous_report(tmp_path, stub_figures):
    run_dir = tmp_path / "s"
    runfolder.make_run_folder(run_dir, fit_axes=())
    write_report(run_dir, None, CFG)
    assert (run_dir / "report" / "figures" / "synced_loops.png").exists()
    mine = run_dir / "report" / "figures" / "my_sketch.png"  # a user's file: never removed
    mine.write_bytes(b"mine")
    (run_dir / "report" / ".stamp.json").write_text("{}")  # as left by 'run'
    (run_dir / "sync" / "synced.csv").unlink()
    write_report(run_dir, None, CFG)
    assert mine.read_bytes() == b"mine"
    assert not (run_dir / "report" / "figures" / "synced_loops.png").exists()  # ours, stale
    assert "sync/synced.csv: not found" in (run_dir / "report" / "report.md").read_text()


def test_diagnosis_missing_image_is_a_warning(tmp_path):
    root = tmp_path / "s"
    runfolder.make_run_folder(root, fit_axes=(), track=False, sync=False)
    runfolder.write_diagnosis(root, "pitch", with_missing_image=True)
    run, _ = load_run(root)
    assert run.diagnoses[0].missing_images == ("plots/gone.png",)
    assert set(run.diagnoses[0].images) == {"plots/step1_before.png", "plots/step1_after.png"}
    write_report(root, None, CFG)
    md = (root / "report" / "report.md").read_text()
    assert "diagnose/pitch/plots/gone.png is listed in diagnosis.json but not found" in md
    assert "![residual before step 1](figures/diagnose_pitch_plots_step1_before.png)" in md


def test_png_paths_walks_nested_json():
    obj = {"a": "x.png", "steps": [{"plots": ["y.PNG", "x.png"]}, {"n": 1}], "b": "z.csv"}
    assert png_paths(obj) == ["x.png", "y.PNG"]


def test_config_section_is_validated(tmp_path, run_dir, capsys):
    cfg = tmp_path / "c.toml"
    cfg.write_text("[report]\nfigure_dpi = 5\n")
    err = _one_line_error(["report", str(run_dir), "--config", str(cfg)], capsys)
    assert "figure_dpi" in err
    cfg.write_text("[report]\nfigure_dpl = 80\n")
    assert "did you mean 'figure_dpi'" in _one_line_error(
        ["report", str(run_dir), "--config", str(cfg)], capsys
    )


def test_fit_json_with_no_datasets_is_a_note_not_an_error(tmp_path):
    root = tmp_path / "s"
    (root / "fit" / "yaw").mkdir(parents=True)
    (root / "fit" / "yaw" / "fit.json").write_text(
        '{"schema": "i2ris-calib.fit/1", "datasets": []}'
    )
    write_report(root, None, CFG)
    assert "fit/yaw/fit.json has no datasets." in (root / "report" / "report.md").read_text()


def test_folder_in_place_of_a_file_counts_as_missing(run_dir):
    (run_dir / "sync" / "sync.json").unlink()
    (run_dir / "sync" / "sync.json").mkdir()  # a folder where a file is expected
    run, _ = load_run(run_dir)
    assert run.sync is None and run.absent["sync/sync.json"] == "not found"


def test_predictions_with_only_egpi_c_and_other_rows_are_read(run_dir):
    """The fit stage's current predictions.csv (every sample, split other) loads as is."""
    pred_path = run_dir / "fit" / "yaw" / "predictions.csv"
    text = pred_path.read_text()
    assert ",other\n" in text and "egpi_c_deg" in text.splitlines()[0]
    run, _ = load_run(run_dir)
    pred = run.fits[0].predictions
    assert set(pred["split"]) == {"fit", "holdout", "other"}
    assert pred["egpi_c_deg"].dtype.kind == "f"


def test_parent_of_run_folders_is_refused(tmp_path, capsys):
    """`report runs/` (the folder holding runs) says which folder to give."""
    (tmp_path / "runs" / "s1" / "fit").mkdir(parents=True)
    (tmp_path / "runs" / "s2" / "sync").mkdir(parents=True)
    assert main(["report", str(tmp_path / "runs")]) == 2
    err = capsys.readouterr().err
    assert "holds runs" in err and "s1" in err and err.count("\n") == 1
    assert not (tmp_path / "runs" / "report").exists()


def test_fit_output_folder_gives_the_model_sections_alone(tmp_path):
    """`report FIT_DIR`: a fit output folder (fit.json + predictions.csv) without a run."""
    runfolder.make_run_folder(tmp_path / "r", track=False, sync=False, fit_axes=("yaw",))
    fit_dir = tmp_path / "fit_out"
    (tmp_path / "r" / "fit" / "yaw").rename(fit_dir)
    run, inputs = load_run(fit_dir)
    assert run.fit_only and [fd.axis for fd in run.fits] == ["yaw"]
    assert sorted(p.name for p in inputs) == ["fit.json", "predictions.csv"]
    page = write_report(fit_dir, None, CFG)
    assert page == fit_dir / "report" / "report.html"
    html = page.read_text()
    anchors = re.findall(r'<section id="([a-z0-9]+)">', html)
    assert anchors == ["overview", "accuracy", "fig6", "parameters", "provenance"]
    assert "recommended model" in html and "Clock synchronisation" not in html
    figs = sorted(p.name for p in (fit_dir / "report" / "figures").iterdir())
    assert figs == ["fig6_yaw_yaw_neg.png", "fig6_yaw_yaw_pos.png"]
    # --out may not be the fit folder itself (the input), nor contain it
    for bad in (fit_dir, tmp_path):
        with pytest.raises(CalibError, match="fit folder|input"):
            write_report(fit_dir, bad, CFG)
    # without predictions.csv the report says so instead of drawing
    (fit_dir / "predictions.csv").unlink()
    write_report(fit_dir, tmp_path / "rep2", CFG)
    text = (tmp_path / "rep2" / "report.md").read_text()
    assert "predictions.csv: not found" in text


@pytest.mark.slow  # ~20 s: a coupled two-motor fit; signed fits in the report on the default run: tests/report/ (test_model_choice_line_per_axis_and_signed_curves_drawn)
def test_fit_folder_report_of_a_signed_two_motor_fit(tmp_path):
    """`fit` on a two-motor recording through zero chooses the signed two-tendon models
    (agpi, agpi_coupled); `report FIT_DIR` shows them in every part."""
    import pandas as pd

    from i2ris_calib.simulation.two_motor import simulate_two_motor

    rec = simulate_two_motor(3, n_samples=900)
    synced = tmp_path / "synced.csv"
    pd.DataFrame(rec.columns()).to_csv(synced, index=False)
    fit_dir = tmp_path / "f_pitch"
    assert main(["fit", str(synced), "--axis", "pitch", "--out", str(fit_dir)]) == 0
    fit = json.loads((fit_dir / "fit.json").read_text())
    choice = fit["model_choice"]
    assert choice["input"] == "signed" and "agpi" in choice["kinds"]
    page = write_report(fit_dir, None, CFG)
    html, md = page.read_text(), (fit_dir / "report" / "report.md").read_text()
    # the overview: fit's model choice per axis, the recommendation among the signed models
    assert f"pitch: {choice['line']}" in md
    (rec_row,) = [ln for ln in md.splitlines() if ln.startswith("| pitch± | two-tendon GPI")]
    assert fit["decision"]["model"] == choice["main"]  # one decision (issue 32)
    assert f"{choice['main']}: held-out" in rec_row  # fit's decision, its figures
    # one Fig-6 figure of the signed dataset, drawing the two-tendon models
    figs = sorted(p.name for p in (fit_dir / "report" / "figures").iterdir())
    assert figs == ["fig6_pitch_pitch_signed.png"]
    assert (
        "GPI, two-tendon GPI" in md
        and "EGPI_C" not in md.split("## Fitted parameters")[0].split("## Model vs")[1]
    )
    # parameters grouped per tendon (and per side of the other motor when coupled)
    assert "tendon + (positive input)" in html and "tendon − (|negative input|)" in html
    if "agpi_coupled" in choice["kinds"]:
        assert "coupling: other motor +" in html
    tables = re.findall(r"<tbody>(.*?)</tbody>", html, flags=re.S)
    assert tables and max(t.count("<tr>") for t in tables) <= 40
    # accuracy rows for each fitted model, no EGPI invented
    for kind in choice["kinds"]:
        label = {"gpi": "GPI", "agpi": "two-tendon GPI"}.get(kind)
        if label:
            assert f"| {label} | held-out |" in md


@pytest.mark.parametrize(
    ("value", "problem"),
    [
        (None, "is null, not a finite number"),
        (float("nan"), "= NaN is not a finite number"),
        ("abc", "= 'abc' is not a number"),
    ],
)
def test_fit_json_parameter_must_be_a_finite_number(run_dir, capsys, value, problem):
    # the one fit.json check (io/fit_schema.py) that compensate uses too: a null or NaN
    # parameter was shown as "-" before
    path = run_dir / "fit" / "yaw" / "fit.json"
    doc = json.loads(path.read_text())
    doc["datasets"][1]["models"]["egpi"]["params"]["a3"] = value
    path.write_text(json.dumps(doc))
    name = doc["datasets"][1]["name"]
    expect = f"{path} [{name}]: datasets[1].models.egpi.params.a3 {problem}; re-run 'fit'"
    with pytest.raises(CalibError, match=re.escape(expect)):
        load_run(run_dir)
    assert _one_line_error(["report", str(run_dir)], capsys).startswith(f"error: {expect}")
    assert not (run_dir / "report").exists()
