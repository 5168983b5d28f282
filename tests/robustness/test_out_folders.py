"""``--out`` never takes a user's files for the tool's (issue 33, items 1, 3, 20, 21).

A folder without a marker is the tool's only when a file in it carries the tool's
mark (names alone are not enough); a link to nothing is refused before any work; a
second commands file does not take the first one's compensate.json; and one command
at a time writes an ``--out`` (a lock file made with exclusive creation).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from robust_cli import assert_one_line_error, run_cli, tree_digest

from i2ris_calib.commands import fit as fit_cmd
from i2ris_calib.commands import simulate as simulate_cmd
from i2ris_calib.errors import CalibError
from i2ris_calib.io.outputs import LOCK_SUFFIX, claim_output_dir, lock_path, output_lock

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "sample_data"


@pytest.fixture
def no_fit(monkeypatch):
    """Fitting fails the test: every refusal here comes before any work."""

    def fail(*a, **k):
        raise AssertionError("the fit ran before --out was checked")

    monkeypatch.setattr(fit_cmd, "fit_every_kind", fail)


@pytest.fixture
def synced(tmp_path) -> Path:
    p = tmp_path / "data" / "yaw_pos.csv"
    p.parent.mkdir()
    shutil.copy(SAMPLE / "datasets" / "yaw_pos.csv", p)
    return p


def _recording(folder: Path) -> Path:
    """A real recording: simulate's file names, the user's data (no marker, no truth/)."""
    folder.mkdir(parents=True)
    (folder / "session.toml").write_text('name = "take 3"\nnotes = "the good one"\n')
    (folder / "top.mp4").write_bytes(b"\x00\x00\x00\x18ftypmp42 my recording top")
    (folder / "side.mp4").write_bytes(b"\x00\x00\x00\x18ftypmp42 my recording side")
    for cam in ("top", "side"):
        (folder / f"{cam}_timestamps.csv").write_text("frame,time_s\n0,0.0\n1,0.033\n")
        (folder / f"{cam}.yaml").write_text("%YAML:1.0\ncamera_matrix: [1, 0, 0]\n")
    (folder / "encoders.csv").write_text("time_s,enc_yaw,enc_pitch\n0.0,0,0\n")
    return folder


def _fake_build(folder, cfg, name="session", progress=False):
    """A quick stand-in for the 80 s render: simulate's names, new contents."""
    (folder / "session.toml").write_text(f'name = "{name}"\n')
    (folder / "top.avi").write_bytes(b"synthetic")
    (folder / "encoders.csv").write_text("time_s,enc_yaw,enc_pitch\n0.0,1,1\n")
    (folder / "truth").mkdir()
    doc = {"schema": "i2ris-calib.truth/1", "provenance": {"package": "i2ris-calib"}}
    (folder / "truth" / "truth.json").write_text(json.dumps(doc))
    return {}


# --- 1: simulate --force on a recording ----------------------------------------------------


def test_simulate_force_refuses_a_recording_with_simulates_names(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(simulate_cmd, "build_session", _fake_build)
    rec = _recording(tmp_path / "take3")
    before = tree_digest(rec)
    rc, _, err = run_cli(capsys, ["simulate", "--out", rec, "--force"])
    assert_one_line_error(rc, err, str(rec), "no sign that i2ris-calib wrote them", "new or empty")
    assert tree_digest(rec) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["take3"]  # no temporary, no lock


def test_simulate_force_still_replaces_an_older_simulate_folder(tmp_path, capsys, monkeypatch):
    """An unmarked folder whose truth/truth.json carries the tool's provenance is an
    older simulate output: --force replaces it."""
    monkeypatch.setattr(simulate_cmd, "build_session", _fake_build)
    old = tmp_path / "sim"
    old.mkdir()
    _fake_build(old, None)
    (old / "top.avi").write_bytes(b"old render")
    rc, _, err = run_cli(capsys, ["simulate", "--out", old, "--force"])
    assert rc == 0, err
    assert (old / "top.avi").read_bytes() == b"synthetic"


# --- 3: the user's own fit.json or report.md -----------------------------------------------


def test_fit_refuses_a_folder_holding_the_users_own_fit_json(synced, tmp_path, capsys, no_fit):
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "fit.json").write_text(json.dumps({"axis": "yaw", "note": "fitted by hand"}))
    (mine / "predictions.csv").write_text("time_s,v\n0,0\n")
    before = tree_digest(mine)
    rc, _, err = run_cli(capsys, ["fit", synced, "--axis", "yaw", "--out", mine])
    assert_one_line_error(rc, err, str(mine), "fit.json", "no sign that i2ris-calib wrote them")
    assert tree_digest(mine) == before


def test_fit_json_of_another_tool_with_a_provenance_is_not_ours(tmp_path):
    mine = tmp_path / "mine"
    mine.mkdir()
    doc = {"schema": "other-tool.fit/2", "provenance": {"package": "i2ris-calib"}}
    (mine / "fit.json").write_text(json.dumps(doc))
    with pytest.raises(CalibError, match="no sign"):
        claim_output_dir(mine, "fit", outputs=fit_cmd.OUTPUTS)
    doc["schema"] = "i2ris-calib.fit/1"  # an older version's fit folder: ours
    (mine / "fit.json").write_text(json.dumps(doc))
    claim_output_dir(mine, "fit", outputs=fit_cmd.OUTPUTS)


def test_report_refuses_a_folder_holding_the_users_own_report_md(synced, tmp_path, capsys):
    run = tmp_path / "run"  # a run folder with one fit: the report says what is missing
    rc, _, err = run_cli(capsys, ["fit", synced, "--axis", "yaw", "--model", "gpi",
                                  "--out", run / "fit" / "yaw"])  # fmt: skip
    assert rc == 0, err
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "report.md").write_text("# My report\n\nWritten by hand.\n")
    rc, _, err = run_cli(capsys, ["report", run, "--out", mine])
    assert_one_line_error(rc, err, str(mine), "report.md", "no sign that i2ris-calib wrote them")
    assert tree_digest(mine) == {"report.md": tree_digest(mine)["report.md"]}
    assert (mine / "report.md").read_text().startswith("# My report")
    # a report written by the tool (generator tag in report.html) is replaced
    rc, _, err = run_cli(capsys, ["report", run, "--out", tmp_path / "ours"])
    assert rc == 0, err
    (tmp_path / "ours" / ".i2ris-calib.json").unlink()  # as an older version left it
    rc, _, err = run_cli(capsys, ["report", run, "--out", tmp_path / "ours"])
    assert rc == 0, err


# --- 20: --out at a link to nothing -----------------------------------------------------------


def test_fit_out_at_a_dangling_symlink_is_refused_before_the_fit(synced, tmp_path, capsys, no_fit):
    link = tmp_path / "out"
    link.symlink_to(tmp_path / "gone")
    rc, _, err = run_cli(capsys, ["fit", synced, "--axis", "yaw", "--out", link])
    assert_one_line_error(rc, err, str(link), "symbolic link", "does not exist")
    assert link.is_symlink() and not (tmp_path / "gone").exists()
    rc, _, err = run_cli(capsys, ["fit", synced, "--axis", "yaw", "--out", link / "yaw"])
    assert_one_line_error(rc, err, "symbolic link", "does not exist")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["data", "out"]


def test_compensate_and_run_out_at_a_dangling_symlink(tmp_path, capsys):
    fit_json, target = _fit_and_target(tmp_path)
    link = tmp_path / "c.csv"
    link.symlink_to(tmp_path / "gone.csv")
    rc, _, err = run_cli(capsys, ["compensate", fit_json, "--dataset", "yaw+", "--target",
                                  target, "--out", link])  # fmt: skip
    assert_one_line_error(rc, err, "symbolic link", "does not exist")
    assert link.is_symlink() and not (tmp_path / "gone.csv").exists()
    session = tmp_path / "session"
    shutil.copytree(SAMPLE / "session", session, ignore=shutil.ignore_patterns("truth"))
    runs = tmp_path / "runs"
    runs.symlink_to(tmp_path / "nowhere")
    rc, _, err = run_cli(capsys, ["run", session, "--out", runs, "--jobs", "1"])
    assert_one_line_error(rc, err, "symbolic link", "does not exist")
    assert not (tmp_path / "nowhere").exists()


# --- 21: a second commands file; two commands at once ------------------------------------


def _fit_and_target(tmp_path: Path) -> tuple[Path, Path]:
    sys.path.insert(0, str(ROOT / "tests" / "commands"))
    from test_compensate_command import _fit_json

    _fit_json(tmp_path / "fit.json")
    t = np.arange(0, 10, 0.02)
    pd.DataFrame({"time_s": t, "yaw_deg": -(14 + 8 * np.sin(t))}).to_csv(
        tmp_path / "target.csv", index=False
    )
    return tmp_path / "fit.json", tmp_path / "target.csv"


def test_second_commands_file_does_not_take_the_firsts_compensate_json(tmp_path, capsys):
    fit_json, target = _fit_and_target(tmp_path)
    out = tmp_path / "cmds"
    out.mkdir()

    def compensate(name):
        return run_cli(capsys, ["compensate", fit_json, "--dataset", "yaw-", "--target", target,
                                "--out", out / name, "--model", "gpi"])  # fmt: skip

    rc, _, err = compensate("a.csv")
    assert rc == 0, err
    before = tree_digest(out)
    rc, _, err = compensate("b.csv")
    assert_one_line_error(rc, err, "compensate.json belongs to", "a.csv", "its own folder")
    assert tree_digest(out) == before
    rc, _, err = compensate("a.csv")  # the same commands file again: replaced
    assert rc == 0, err
    (out / "a.csv").unlink()  # its commands file gone: compensate.json is free
    rc, _, err = compensate("b.csv")
    assert rc == 0, err
    assert json.loads((out / "compensate.json").read_text())["commands_csv"] == "b.csv"
    assert not list(out.glob(f"*{LOCK_SUFFIX}"))


HOLD = textwrap.dedent(
    """
    import sys
    from i2ris_calib.io.outputs import output_lock
    with output_lock(*sys.argv[2:], command=sys.argv[1]):
        print("held", flush=True)
        sys.stdin.read()
    """
)


@pytest.fixture
def holder():
    """Start a process holding the locks of some paths (another command at work)."""
    procs = []

    def start(command: str, *paths: Path) -> subprocess.Popen:
        env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
        p = subprocess.Popen([sys.executable, "-c", HOLD, command, *map(str, paths)],
                             stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)  # fmt: skip
        procs.append(p)
        assert p.stdout.readline().strip() == "held"
        return p

    yield start
    for p in procs:
        p.stdin.close()
        p.wait(timeout=30)


def test_fit_refused_while_another_fit_writes_the_same_out(synced, tmp_path, capsys, holder,
                                                          no_fit):  # fmt: skip
    out = tmp_path / "fitted"
    p = holder("fit", out)
    rc, _, err = run_cli(capsys, ["fit", synced, "--axis", "yaw", "--out", out])
    line = assert_one_line_error(rc, err, str(out), "'fit'", f"process {p.pid}", "is writing there")
    assert "remove" in line
    assert not out.exists()
    p.stdin.close()
    p.wait(timeout=30)
    assert not lock_path(out).exists()  # removed when the other command ended


def test_compensate_refused_while_another_compensate_writes_there(tmp_path, capsys, holder):
    fit_json, target = _fit_and_target(tmp_path)
    out = tmp_path / "cmds" / "c.csv"
    holder("compensate", out.with_name("compensate.json"))
    rc, _, err = run_cli(capsys, ["compensate", fit_json, "--dataset", "yaw-", "--target",
                                  target, "--out", out])  # fmt: skip
    assert_one_line_error(rc, err, "'compensate'", "is writing there")
    assert not out.exists() and not out.with_name("compensate.json").exists()


def test_lock_is_reentrant_removed_on_error_and_stale_one_taken_over(tmp_path):
    out = tmp_path / "a" / "b"
    with pytest.raises(KeyboardInterrupt):
        with output_lock(out, command="fit"):
            assert lock_path(out).is_file()
            with output_lock(out, command="fit"):  # the same process: re-entered
                pass
            assert lock_path(out).is_file()
            raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []  # lock and the parents made for it removed
    # a lock left by a process that has ended (killed): taken over
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)  # fmt: skip
    import socket

    lock = lock_path(tmp_path / "o")
    lock.write_text(json.dumps({"pid": int(dead.stdout), "host": socket.gethostname()}))
    with output_lock(tmp_path / "o"):
        assert json.loads(lock.read_text())["pid"] == os.getpid()
    assert not lock.exists()
