"""Stage stamping of `run`: skip when up to date, redo after changes or interruption."""

from dataclasses import dataclass

import pytest

from i2ris_calib.commands.run import STAMP, Stage, is_up_to_date, run_stage


@dataclass(frozen=True)
class Cfg:
    gain: float = 1.0


def make_stage(tmp_path, calls, cfg=Cfg(), fail=False):
    src = tmp_path / "in.txt"
    out = tmp_path / "stage"

    def action():
        calls.append(1)
        out.mkdir(exist_ok=True)
        if fail:
            raise KeyboardInterrupt
        (out / "result.txt").write_text(src.read_text().upper())

    return Stage("demo", out, (src,), cfg, action)


def test_skips_when_up_to_date_and_reruns_on_input_change(tmp_path):
    calls = []
    (tmp_path / "in.txt").write_text("a")
    st = make_stage(tmp_path, calls)
    assert run_stage(st, force=False) == "ran"
    assert run_stage(st, force=False) == "up to date"
    assert len(calls) == 1
    (tmp_path / "in.txt").write_text("b")
    assert not is_up_to_date(st)
    assert run_stage(st, force=False) == "ran"
    assert (tmp_path / "stage" / "result.txt").read_text() == "B"


def test_config_change_and_force_rerun(tmp_path):
    calls = []
    (tmp_path / "in.txt").write_text("a")
    run_stage(make_stage(tmp_path, calls), force=False)
    assert run_stage(make_stage(tmp_path, calls, cfg=Cfg(gain=2.0)), force=False) == "ran"
    assert run_stage(make_stage(tmp_path, calls, cfg=Cfg(gain=2.0)), force=True) == "ran"
    assert len(calls) == 3


def test_interrupted_stage_is_redone(tmp_path):
    calls = []
    (tmp_path / "in.txt").write_text("a")
    run_stage(make_stage(tmp_path, calls), force=False)
    (tmp_path / "in.txt").write_text("c")
    with pytest.raises(KeyboardInterrupt):
        run_stage(make_stage(tmp_path, calls, fail=True), force=False)
    assert not (tmp_path / "stage" / STAMP).exists()
    assert run_stage(make_stage(tmp_path, calls), force=False) == "ran"
    assert (tmp_path / "stage" / "result.txt").read_text() == "C"


def test_folder_inputs_cover_every_file_below(tmp_path):
    calls = []
    d = tmp_path / "fit"
    (d / "yaw").mkdir(parents=True)
    (d / "yaw" / "fit.json").write_text("{}")
    (d / "yaw" / ".stamp.json").write_text("ignored")
    out = tmp_path / "report"
    st = Stage("report", out, (d,), Cfg(), lambda: (calls.append(1), out.mkdir(exist_ok=True)))
    run_stage(st, force=False)
    assert is_up_to_date(st)
    (d / "yaw" / ".stamp.json").write_text("changed")  # dotfiles do not count
    assert is_up_to_date(st)
    (d / "yaw" / "predictions.csv").write_text("new file")
    assert not is_up_to_date(st)


SESSION_TOML = """# a comment
name = "{name}"
notes = "first take"

[encoder]
file = "encoders.csv"

[cameras.top]
video = "top.mp4"
timestamps = "top_timestamps.csv"
view = "top"
marker_id = 0

[cameras.side]
video = "side.mp4"
timestamps = "side_timestamps.csv"
view = "side"
marker_id = 1
"""


def _fake_session(folder, name, payload):
    """A session folder whose named files hold arbitrary bytes (nothing is decoded)."""
    folder.mkdir(parents=True)
    (folder / "session.toml").write_text(SESSION_TOML.format(name=name))
    (folder / "top.mp4").write_bytes(payload)
    (folder / "side.mp4").write_bytes(b"side video")
    for cam in ("top", "side"):
        (folder / f"{cam}_timestamps.csv").write_text("frame,time_s\n0,0.0\n1,0.033\n")
    (folder / "encoders.csv").write_text("time_s,enc_yaw,enc_pitch\n0.0,0,0\n")
    return folder


def test_run_dir_refuses_another_session_with_the_same_name(tmp_path):
    """Two sessions named alike, one --out: the second is refused, the first's outputs
    stay; the same session moved to another folder keeps its run folder."""
    from i2ris_calib.commands.run import claim_run_dir
    from i2ris_calib.errors import CalibError

    a = _fake_session(tmp_path / "a", "s", b"one recording")
    b = _fake_session(tmp_path / "b", "s", b"another recording!")
    run_dir = tmp_path / "runs" / "s"
    claim_run_dir(a, run_dir)
    (run_dir / "result.txt").write_text("a's results")
    with pytest.raises(CalibError, match="another session") as exc:
        claim_run_dir(b, run_dir)
    assert "\n" not in str(exc.value) and str(a.resolve()) in str(exc.value)
    assert (run_dir / "result.txt").read_text() == "a's results"
    moved = tmp_path / "moved"
    a.rename(moved)
    claim_run_dir(moved, run_dir)  # same recording, new folder: accepted


# --- session identity: what the pipeline reads, not what lies in the folder (issue 19) ----
def _stub_run(monkeypatch, calls):
    """``run_one_session`` with the real track and sync stages (inputs, config, stamps)
    but stand-in actions, so nothing is decoded."""
    import dataclasses

    from i2ris_calib.commands import run as run_io

    real = run_io.session_stages

    def stages(session, run_dir, config):
        out = []
        for st in real(session, run_dir, config)[:2]:  # track, sync

            def action(st=st):
                calls.append(st.name)
                st.out_dir.mkdir(parents=True, exist_ok=True)
                name = "angles.csv" if st.name == "track" else "synced.csv"
                (st.out_dir / name).write_text(f"{st.name} output {len(calls)}")

            out.append(dataclasses.replace(st, action=action))
        return out

    monkeypatch.setattr(run_io, "session_stages", stages)

    def run(session, run_dir):
        from i2ris_calib.config import PipelineConfig

        return dict(run_io.run_one_session(session, run_dir, PipelineConfig(), force=False))

    return run


def test_notes_comments_and_unread_files_do_not_change_the_session(tmp_path, monkeypatch, capsys):
    """Editing notes or comments of session.toml, or adding a target CSV (docs/compensate.md)
    or any other file the pipeline does not read: same session, nothing re-runs."""
    calls = []
    run = _stub_run(monkeypatch, calls)
    s = _fake_session(tmp_path / "s", "s", b"one recording")
    run_dir = tmp_path / "runs" / "s"
    assert run(s, run_dir) == {"track": "ran", "sync": "ran"}
    toml = s / "session.toml"
    toml.write_text(toml.read_text().replace("first take", "second thoughts").replace(
        "# a comment", "# another comment\n# and one more"))  # fmt: skip
    (s / "target.csv").write_text("time_s,yaw_deg\n0,0\n1,10\n")
    (s / "notes.txt").write_text("microscope refocused")
    (s / "truth").mkdir()
    (s / "truth" / "truth_frames.csv").write_text("frame\n0\n")
    capsys.readouterr()
    assert run(s, run_dir) == {"track": "up to date", "sync": "up to date"}
    assert calls == ["track", "sync"] and "note" not in capsys.readouterr().err


def test_changed_input_is_named_and_its_stages_rerun(tmp_path, monkeypatch, capsys):
    """The same session folder with an edited encoder log (same size) or video: not
    refused; the note names the input and the stages that re-run, and they do."""
    calls = []
    run = _stub_run(monkeypatch, calls)
    s = _fake_session(tmp_path / "s", "s", b"one recording")
    run_dir = tmp_path / "runs" / "s"
    run(s, run_dir)
    capsys.readouterr()
    log = s / "encoders.csv"
    log.write_text(log.read_text().replace("0.0,0,0", "0.0,0,5"))  # same size, new content
    assert run(s, run_dir) == {"track": "up to date", "sync": "ran"}
    (err,) = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("note: ")]
    assert "encoders.csv changed since its last run" in err, err
    assert "sync and the stages after it re-run (track is up to date)" in err, err
    assert "top.mp4" not in err and "session.toml" not in err, err
    # the note is given once: the record now holds the new inputs
    assert run(s, run_dir) == {"track": "up to date", "sync": "up to date"}
    assert "note" not in capsys.readouterr().err
    (s / "top.mp4").write_bytes(b"one recording, re-encoded")
    toml = s / "session.toml"
    toml.write_text(toml.read_text().replace("marker_id = 1", "marker_id = 2"))
    assert run(s, run_dir)["track"] == "ran"
    (err,) = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("note: ")]
    assert "top.mp4, session.toml [cameras.side] changed" in err, err
    assert "track, sync and the stages after them re-run" in err, err
    assert calls == ["track", "sync", "sync", "track", "sync"]


def test_moved_session_with_changed_inputs_is_another_session(tmp_path):
    """Only a different folder with different named inputs is refused; a moved session
    whose named files kept their names and sizes is the same one."""
    from i2ris_calib.commands.run import claim_run_dir
    from i2ris_calib.errors import CalibError

    a = _fake_session(tmp_path / "a", "s", b"one recording")
    run_dir = tmp_path / "runs" / "s"
    assert claim_run_dir(a, run_dir) is None
    assert claim_run_dir(a, run_dir) is None
    moved = tmp_path / "moved"
    a.rename(moved)
    (moved / "target.csv").write_text("time_s,yaw_deg\n0,0\n")  # not an input
    note = claim_run_dir(moved, run_dir)
    assert note == f"{run_dir}: session moved from {a.resolve()}"
    other = _fake_session(tmp_path / "other", "s", b"one recording")
    (other / "encoders.csv").write_text("time_s,enc_yaw,enc_pitch\n0.0,0,0\n0.1,1,1\n")
    with pytest.raises(CalibError, match="another session") as exc:
        claim_run_dir(other, run_dir)
    assert "\n" not in str(exc.value) and str(moved.resolve()) in str(exc.value)


def test_another_recording_with_the_same_names_and_sizes_is_refused(tmp_path, monkeypatch, capsys):
    """Issue 33 item 2: B has A's folder name, file names and sizes but other contents;
    ``run B`` into A's run folder is refused and A's outputs stay. A itself moved to
    another folder (same contents) still keeps its run folder."""
    from i2ris_calib.commands.run import claim_run_dir
    from i2ris_calib.errors import CalibError

    calls = []
    run = _stub_run(monkeypatch, calls)
    a = _fake_session(tmp_path / "x" / "take", "take", b"recording A")
    run_dir = tmp_path / "runs" / "take"
    run(a, run_dir)
    before = {p: p.read_bytes() for p in run_dir.rglob("*") if p.is_file()}
    b = _fake_session(tmp_path / "y" / "take", "take", b"recording B")  # same size
    (b / "encoders.csv").write_text("time_s,enc_yaw,enc_pitch\n0.0,9,9\n")  # same size
    with pytest.raises(CalibError, match="another session") as exc:
        claim_run_dir(b, run_dir)
    assert "\n" not in str(exc.value) and str(a.resolve()) in str(exc.value)
    assert {p: p.read_bytes() for p in run_dir.rglob("*") if p.is_file()} == before
    assert calls == ["track", "sync"]
    moved = tmp_path / "z" / "take"
    moved.parent.mkdir()
    a.rename(moved)
    assert "session moved from" in claim_run_dir(moved, run_dir)
