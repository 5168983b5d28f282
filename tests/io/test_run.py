"""Stage stamping of `run`: skip when up to date, redo after changes or interruption."""

from dataclasses import dataclass

import pytest

from i2ris_calib.io.run import STAMP, Stage, is_up_to_date, run_stage


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


def _fake_session(folder, name, payload):
    folder.mkdir(parents=True)
    (folder / "session.toml").write_text(f'name = "{name}"\n')
    (folder / "top.mp4").write_bytes(payload)
    return folder


def test_run_dir_refuses_another_session_with_the_same_name(tmp_path):
    """Two sessions named alike, one --out: the second is refused, the first's outputs
    stay; the same session moved to another folder keeps its run folder."""
    from i2ris_calib.errors import CalibError
    from i2ris_calib.io.run import claim_run_dir

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
