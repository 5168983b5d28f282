"""Output folders and files (io/outputs.py, issue 19): a command writes only into a folder
that is new, empty or its own, never destroys a file it did not write, and refuses an
``--out`` that is, contains or lies inside an input, before doing any work."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from i2ris_calib.cli import main
from i2ris_calib.errors import CalibError
from i2ris_calib.io.outputs import MARKER, claim_output_dir, claim_output_file, output_dir

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "sample_data"


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file below ``folder`` with its bytes (hidden files included)."""
    return {
        p.relative_to(folder).as_posix(): p.read_bytes() for p in folder.rglob("*") if p.is_file()
    }


@pytest.fixture
def session(tmp_path):
    dst = tmp_path / "session"
    shutil.copytree(SAMPLE / "session", dst, ignore=shutil.ignore_patterns("truth"))
    return dst


@pytest.fixture
def synced(tmp_path):
    folder = tmp_path / "mine"
    folder.mkdir()
    shutil.copy(SAMPLE / "datasets" / "yaw_pos.csv", folder / "synced.csv")
    (folder / "notes.txt").write_text("my notes")
    return folder / "synced.csv"


def refused(capsys, argv: list[str], *words: str) -> str:
    """Run the CLI, assert exit 2 with a one-line error containing ``words`` (``run``
    prints the session it starts on a line before)."""
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err, err
    err = err.splitlines()[-1]
    assert err.startswith("error: "), err
    for w in words:
        assert w in err, err
    return err


# --- the module ---------------------------------------------------------------------------


def test_new_folder_gets_files_and_marker(tmp_path):
    out = tmp_path / "a" / "b"
    with output_dir(out, "fit") as tmp:
        (tmp / "fit.json").write_text("{}")
    assert sorted(p.name for p in out.iterdir()) == [MARKER, "fit.json"]
    rec = json.loads((out / MARKER).read_text())
    assert rec["command"] == "fit" and rec["files"] == ["fit.json"]


def test_rewrite_keeps_user_files_and_drops_own_stale_ones(tmp_path):
    out = tmp_path / "o"
    with output_dir(out, "diagnose") as tmp:
        (tmp / "residual_00_start.png").write_bytes(b"a")
        (tmp / "residual_01_time_delay.png").write_bytes(b"b")
    (out / "notes.txt").write_text("mine")
    with output_dir(out, "diagnose") as tmp:
        (tmp / "residual_00_start.png").write_bytes(b"c")
    assert (out / "notes.txt").read_text() == "mine"
    assert (out / "residual_00_start.png").read_bytes() == b"c"
    assert not (out / "residual_01_time_delay.png").exists()  # ours, not written this time


def test_failure_or_interrupt_leaves_folder_untouched(tmp_path):
    out = tmp_path / "o"
    with output_dir(out, "fit") as tmp:
        (tmp / "fit.json").write_text("old")
    before = snapshot(out)
    for exc in (RuntimeError("boom"), KeyboardInterrupt()):
        with pytest.raises(type(exc)):
            with output_dir(out, "fit") as tmp:
                (tmp / "fit.json").write_text("half")
                raise exc
        assert snapshot(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o"]  # no temporary left


def test_failure_removes_parents_it_made(tmp_path):
    with pytest.raises(RuntimeError):
        with output_dir(tmp_path / "x" / "y" / "z", "fit"):
            raise RuntimeError
    assert list(tmp_path.iterdir()) == []


def test_folder_of_another_command_or_of_the_user_is_refused(tmp_path):
    out = tmp_path / "o"
    with output_dir(out, "track") as tmp:
        (tmp / "angles.csv").write_text("x")
    with pytest.raises(CalibError, match="output of 'track', not of 'diagnose'"):
        claim_output_dir(out, "diagnose")
    user = tmp_path / "u"
    user.mkdir()
    (user / "notes.txt").write_text("mine")
    with pytest.raises(CalibError, match=r"did not write \(notes.txt\)"):
        claim_output_dir(user, "fit", outputs=("fit.json",))


def test_unmarked_folder_of_own_names_is_accepted(tmp_path):
    """A folder written by an older version (no marker) holds only the command's names,
    and one of its JSON files carries the tool's provenance (issue 33 item 3)."""
    out = tmp_path / "track"
    out.mkdir()
    (out / "angles.csv").write_text("old")
    (out / ".stamp.json").write_text("{}")
    with pytest.raises(CalibError, match="no sign that i2ris-calib wrote them"):
        claim_output_dir(out, "track", outputs=("angles.csv", "track.json"))
    prov = {"schema": "i2ris-calib.track/1", "provenance": {"package": "i2ris-calib"}}
    (out / "track.json").write_text(json.dumps(prov))
    claim_output_dir(out, "track", outputs=("angles.csv", "track.json"))
    with output_dir(out, "track", outputs=("angles.csv", "track.json")) as tmp:
        (tmp / "angles.csv").write_text("new")
    assert (out / "angles.csv").read_text() == "new"


@pytest.mark.parametrize("where", ["is", "contains"])
def test_out_that_is_or_contains_an_input_is_refused(tmp_path, where):
    data = tmp_path / "d" / "in.csv"
    data.parent.mkdir()
    data.write_text("x")
    out = data if where == "is" else tmp_path
    with pytest.raises(CalibError, match="input|is a file"):
        claim_output_dir(out, "fit", [data])


def test_out_inside_an_input_folder_is_allowed(tmp_path):
    claim_output_dir(tmp_path / "track", "track", [tmp_path])


def test_file_is_replaced_only_when_the_tool_wrote_it(tmp_path):
    user = tmp_path / "cmd.csv"
    user.write_text("mine")
    with pytest.raises(CalibError, match="not written by i2ris-calib"):
        claim_output_file(user)
    ours = tmp_path / "c.csv"
    ours.write_text("x")
    (tmp_path / "compensate.json").write_text(
        json.dumps({"commands_csv": "c.csv", "provenance": {"package": "i2ris-calib"}})
    )
    claim_output_file(ours, companions=[tmp_path / "compensate.json"])


# --- every command that takes --out -------------------------------------------------------


def test_track_out_is_the_session(session, capsys):
    before = snapshot(session)
    refused(capsys, ["track", str(session), "--out", str(session)], "is the input")
    assert snapshot(session) == before


def test_track_out_is_a_user_file(session, tmp_path, capsys):
    notes = tmp_path / "notes.txt"
    notes.write_text("mine")
    refused(capsys, ["track", str(session), "--out", str(notes)], "is a file")
    assert notes.read_text() == "mine"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt", "session"]


def test_track_out_contains_the_session(session, capsys):
    refused(capsys, ["track", str(session), "--out", str(session.parent)], "contains the input")


def test_sync_out_under_a_file_fails_before_any_work(session, tmp_path, capsys, monkeypatch):
    import i2ris_calib.commands.sync as sync_io

    def no_work(*a, **k):  # pragma: no cover - must not be reached
        raise AssertionError("sync did work before checking --out")

    monkeypatch.setattr(sync_io, "estimate_clock", no_work)
    monkeypatch.setattr(sync_io, "read_encoder_log", no_work)
    (session / "track").mkdir()
    (session / "track" / "angles.csv").write_text("time_s,yaw_deg,pitch_deg\n")
    blocker = tmp_path / "file"
    blocker.write_text("mine")
    refused(capsys, ["sync", str(session), "--out", str(blocker / "sync")], "is a file")
    refused(capsys, ["sync", str(session), "--out", str(session)], "is the input")


def test_diagnose_out_is_the_folder_of_its_input(synced, capsys):
    folder = synced.parent
    before = snapshot(folder)
    refused(capsys, ["diagnose", str(synced), "--axis", "yaw", "--out", str(folder)], "contains")
    assert snapshot(folder) == before


def test_diagnose_out_is_a_run_folder(tmp_path, capsys):
    run = tmp_path / "run"
    for part in ("track", "sync", "fit/yaw", "report"):
        (run / part).mkdir(parents=True)
        (run / part / "x.json").write_text("{}")
    shutil.copy(SAMPLE / "datasets" / "yaw_pos.csv", run / "sync" / "synced.csv")
    before = snapshot(run)
    refused(capsys, ["diagnose", str(run / "sync" / "synced.csv"), "--axis", "yaw",
                     "--out", str(run)], "contains the input")  # fmt: skip
    assert snapshot(run) == before


def test_diagnose_out_is_an_existing_file(synced, tmp_path, capsys):
    notes = synced.parent / "notes.txt"
    refused(capsys, ["diagnose", str(synced), "--axis", "yaw", "--out", str(notes)], "is a file")
    assert notes.read_text() == "my notes"
    assert not any(p.name.startswith(".notes") for p in synced.parent.iterdir())


def test_fit_out_is_a_user_folder(synced, tmp_path, capsys):
    user = tmp_path / "results"
    user.mkdir()
    (user / "thesis.tex").write_text("mine")
    refused(capsys, ["fit", str(synced), "--axis", "yaw", "--out", str(user)], "did not write")
    assert sorted(p.name for p in user.iterdir()) == ["thesis.tex"]
    refused(capsys, ["fit", str(synced), "--axis", "yaw", "--out", str(synced)], "is a file")


def test_compensate_out_is_a_user_file(tmp_path, capsys):
    fit_json = tmp_path / "fit.json"
    fit_json.write_text("{}")
    target = tmp_path / "t.csv"
    target.write_text("time_s,yaw_deg\n0,1\n")
    mine = tmp_path / "cmds.csv"
    mine.write_text("mine")
    base = ["compensate", str(fit_json), "--dataset", "yaw+", "--target", str(target), "--out"]
    refused(capsys, [*base, str(mine)], "not written by i2ris-calib")
    refused(capsys, [*base, str(target)], "is the input")
    assert mine.read_text() == "mine" and target.read_text().startswith("time_s")


def test_calibrate_out_is_a_user_file(tmp_path, capsys):
    mine = tmp_path / "cam.yaml"
    mine.write_text("mine: 1\n")
    src = SAMPLE / "session" / "top.yaml"
    refused(capsys, ["calibrate", str(src), "--out", str(mine)], "not written by i2ris-calib")
    assert mine.read_text() == "mine: 1\n"
    assert main(["calibrate", str(src), "--out", str(tmp_path / "ok.yaml")]) == 0
    assert main(["calibrate", str(src), "--out", str(tmp_path / "ok.yaml")]) == 0  # ours


def test_report_out_is_a_user_folder(tmp_path, capsys):
    user = tmp_path / "u"
    user.mkdir()
    (user / "notes.txt").write_text("mine")
    refused(capsys, ["report", str(tmp_path), "--out", str(user)], "did not write")
    assert snapshot(user) == {"notes.txt": b"mine"}


def test_paper_sim_and_simulate_refuse_a_user_folder(tmp_path, capsys):
    user = tmp_path / "u"
    user.mkdir()
    (user / "notes.txt").write_text("mine")
    refused(capsys, ["paper-sim", "--out", str(user)], "did not write")
    refused(capsys, ["simulate", "--out", str(user), "--force"], "did not write")
    assert snapshot(user) == {"notes.txt": b"mine"}


def test_run_out_is_a_file(session, tmp_path, capsys):
    f = tmp_path / "f"
    f.write_text("mine")
    refused(capsys, ["run", str(session), "--out", str(f)], "is a file")
    assert f.read_text() == "mine"


def test_run_refuses_a_user_folder_under_the_session_name(session, tmp_path, capsys):
    from i2ris_calib.io.session import load_session

    runs = tmp_path / "runs"

    name = load_session(session).name or session.name
    (runs / name).mkdir(parents=True)
    (runs / name / "notes.txt").write_text("mine")
    refused(capsys, ["run", str(session), "--out", str(runs)], "not a run folder")
    assert snapshot(runs) == {f"{name}/notes.txt": b"mine"}


def test_batch_run_leaves_no_folder_for_a_failed_session(session, tmp_path, capsys):
    from i2ris_calib.commands import run as run_io

    def fail(*a, **k):
        raise CalibError("boom")

    runs = tmp_path / "runs"
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(run_io, "track_session", fail)
        refused(capsys, ["run", str(session), "--out", str(runs), "--jobs", "1"], "boom")
    assert not runs.exists() or not any(runs.rglob("*"))
