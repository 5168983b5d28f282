"""Fault matrix of the tracking side (issue 9): session.toml, timestamps, videos,
calibration files, interrupts, and what a lab hits next (dropped frames, frame count
mismatches, a moved session). Each case: the CLI as a user runs it."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from robust_cli import assert_one_line_error, edit_toml, run_cli, tree_digest


@pytest.fixture(scope="session")
def tracked(rendered, serial_config, tmp_path_factory) -> Path:
    """The rendered session with good track/ outputs (tracked once)."""
    from i2ris_calib.cli import main

    folder = tmp_path_factory.mktemp("tracked") / "s"
    shutil.copytree(rendered, folder)
    assert main(["track", str(folder), "-c", str(serial_config)]) == 0
    return folder


@pytest.fixture
def tracked_copy(tracked, tmp_path) -> Path:
    dst = tmp_path / "s"
    shutil.copytree(tracked, dst)
    return dst


def _swap_views(folder: Path) -> None:
    toml = folder / "session.toml"
    text = toml.read_text()
    text = text.replace('view = "top"', "VIEW_A").replace('view = "side"', 'view = "top"')
    toml.write_text(text.replace("VIEW_A", 'view = "side"'))


# ------------------------------------------------------------------ item 1: view labels
def test_correct_view_labels_are_verified(tracked):
    js = json.loads((tracked / "track" / "track.json").read_text())
    check = js["view_check"]
    assert check["verdict"] == "consistent"
    spread = check["rigid_rig_spread_mm"]
    # as labelled: corner noise (micrometres); swapped: the face offsets move (~ cube/4)
    assert spread["as_labelled"] < 0.005 < 0.1 < spread["swapped"]


def test_swapped_view_labels_are_refused(tracked_copy, serial_config, capsys):
    """Swapped top/side labels fit as well as the truth (a mirror image: yaw and pitch
    exchanged, sign-flipped): refused with the fix, the earlier good outputs kept."""
    before = tree_digest(tracked_copy / "track")
    _swap_views(tracked_copy)
    rc, _, err = run_cli(capsys, ["track", tracked_copy, "-c", serial_config])
    line = assert_one_line_error(rc, err, "session.toml", "view labels look swapped")
    # camera 'side' now says view = "top": the fix names each camera's right label
    assert 'set view = "side" in [cameras.side] and view = "top" in [cameras.top]' in line
    assert tree_digest(tracked_copy / "track") == before


def test_swapped_view_labels_weak_perspective(session, serial_config, capsys):
    """The same with the uncalibrated camera model (no perspective cue at all)."""
    for cam in ("top", "side"):
        edit_toml(session / "session.toml", f'calibration = "{cam}.yaml"', "")
    text = (session / "session.toml").read_text().replace('"pinhole"', '"weak_perspective"')
    (session / "session.toml").write_text(text)
    _swap_views(session)
    rc, _, err = run_cli(capsys, ["track", session, "-c", serial_config])
    assert_one_line_error(rc, err, "view labels look swapped")
    assert not (session / "track").exists()


# -------------------------------------------------- item 7: backward timestamps tolerated
def test_backward_timestamps_are_tolerated_by_track_and_sync(session, serial_config, capsys):
    ts = pd.read_csv(session / "top_timestamps.csv")
    rows = [40, 80, 120]
    for r in rows:
        ts.loc[r, "time_s"] = ts.loc[r - 2, "time_s"]  # goes backwards once
    ts.to_csv(session / "top_timestamps.csv", index=False, float_format="%.6f")
    rc, _, err = run_cli(capsys, ["track", session, "-c", serial_config])
    assert rc == 0, err
    a = pd.read_csv(session / "track" / "angles.csv")
    assert (a.loc[rows, "status"] == "rejected").all()
    rc, _, err = run_cli(capsys, ["sync", session, "-c", serial_config])
    assert rc == 0, err
    js = json.loads((session / "sync" / "sync.json").read_text())
    assert js["n_backward_rejected"] == 3
    assert js["axis_check"]["swapped_axes"] == [] and js["warnings"] == []
    synced = pd.read_csv(session / "sync" / "synced.csv")
    assert not set(rows) & set(synced["frame"])
    assert np.all(np.diff(synced["time_cam_s"]) > 0)


def test_angles_following_the_other_motor_are_flagged_by_sync(tracked_copy, serial_config, capsys):
    """Once synced, each angle must follow its own motor: swapped encoder columns (or
    view labels that got past track) are flagged in the terminal and sync.json."""
    edit_toml(tracked_copy / "session.toml", 'format = "csv"',
              'format = "csv"\nyaw_column = "enc_pitch"\npitch_column = "enc_yaw"')  # fmt: skip
    rc, _, err = run_cli(capsys, ["sync", tracked_copy, "-c", serial_config])
    assert rc == 0, err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("warning: yaw, pitch follow(s) the other motor")
    js = json.loads((tracked_copy / "sync" / "sync.json").read_text())
    check = js["axis_check"]
    assert check["swapped_axes"] == ["yaw", "pitch"] and js["warnings"] == [lines[0][9:]]
    for axis in ("yaw", "pitch"):  # steps follow the other motor, not their own
        assert check[axis]["other"] > 0.5 > 0.1 > check[axis]["own"]


def test_sync_still_refuses_a_real_clock_reset(tracked_copy, serial_config, capsys):
    """A time going backwards on a frame that track did not reject is still refused."""
    p = tracked_copy / "track" / "angles.csv"
    a = pd.read_csv(p)
    a.loc[100:, "time_s"] -= 2.0
    a.to_csv(p, index=False)
    rc, _, err = run_cli(capsys, ["sync", tracked_copy, "-c", serial_config])
    assert_one_line_error(rc, err, "angles.csv", "camera clock reset")
    assert not (tracked_copy / "sync").exists()


# ------------------------------------------------------------- internal errors -> one line
@pytest.mark.parametrize(
    "old, new, needles",
    [
        ("marker_size_mm = 0.8", "marker_size_mm = 0", ("[marker]", "marker_size_mm = 0.0 must be > 0")),
        ("marker_size_mm = 0.8", "marker_size_mm = -0.8", ("[marker]", "must be > 0")),
        ("marker_size_mm = 0.8", "marker_size_mm = nan", ("[marker]", "must be > 0")),
        ("cube_size_mm = 1.0", "cube_size_mm = 0.5", ("[marker]", "cube_size_mm = 0.5 must be >= marker_size_mm")),
        ("marker_id = 1", "marker_id = -1", ("[cameras.side]", "marker_id = -1 must be >= 0")),
        ('format = "csv"', 'format = "csv"\ntime_unit_s = 0', ("[encoder]", "time_unit_s = 0.0 must be a number > 0")),
        ('name = "s"', 'name = "../escape"', ("name = '../escape' must be usable as one folder name",)),
    ],
)  # fmt: skip
def test_invalid_session_values_are_refused_on_load(
    session, serial_config, capsys, old, new, needles
):
    edit_toml(session / "session.toml", old, new)
    t0 = time.perf_counter()
    rc, _, err = run_cli(capsys, ["track", session, "-c", serial_config])
    assert_one_line_error(rc, err, "session.toml", *needles)
    assert time.perf_counter() - t0 < 5.0  # refused on load, before any decoding
    assert not (session / "track").exists()


@pytest.mark.parametrize(
    "content",
    [b"hello world\nthis is not yaml: [1, 2\n", b"", bytes(range(256)) * 3,
     b"camera_matrix:\n  rows: 3\n  cols: 3\n  data: [a, b, c, d, e, f, g, h, i]\n",
     b"%YAML:1.0\n---\ncamera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n"
     b"   data: [ 1, 2 ]\n"],
    ids=["text", "empty", "binary", "non-numeric", "short-matrix"],
)  # fmt: skip
def test_garbage_calibration_yaml(session, serial_config, capsys, content):
    """Refused with the file's name, before decoding: the side video is corrupt too, and
    the calibration file is the error reported."""
    (session / "top.yaml").write_bytes(content)
    (session / "side.mkv").write_bytes(np.random.default_rng(0).bytes(20000))
    rc, _, err = run_cli(capsys, ["track", session, "-c", serial_config])
    assert_one_line_error(rc, err, "top.yaml", "calibrate")
    assert not (session / "track").exists()


def test_invalid_track_and_simulate_config_values(tmp_path, capsys):
    cases = {
        "[track]\nmax_interp_gap_s = -1\n": "max_interp_gap_s = -1.0 must be a finite number >= 0",
        "[track]\nweak_perspective_focal_px = 0\n": "weak_perspective_focal_px = 0.0 must be",
        "[track]\nreference_start_s = nan\n": "[track]: TrackingConfig: reference_start_s is NaN",
        "[simulate]\nfps = nan\n": "[simulate]: SimulationConfig: fps is NaN",
        "[simulate]\nbackground_gray = 300\n": "background_gray = 300.0 must be a grey level",
        "[simulate]\nmarker_size_mm = 0\n": "marker_size_mm = 0.0 must be a finite number > 0",
        "[simulate]\namplitude_counts = [0, 6000]\n": "amplitude_counts must be",
    }
    for i, (text, needle) in enumerate(cases.items()):
        p = tmp_path / f"c{i}.toml"
        p.write_text(text)
        rc, out, err = run_cli(capsys, ["config", "-c", p])
        assert_one_line_error(rc, err, str(p), needle)
        assert out == ""
    out_dir = tmp_path / "sim"
    rc, _, err = run_cli(capsys, ["simulate", "--out", out_dir, "-c", tmp_path / "c3.toml"])
    assert_one_line_error(rc, err, "fps")
    assert not out_dir.exists()


# ------------------------------------------------------------------- unclear messages
@pytest.mark.parametrize("text", ["frame,time_s\n", "frame,time_s\n0,0.0\n"])
def test_header_only_timestamps_checked_before_decoding(session, serial_config, capsys, text):
    (session / "side_timestamps.csv").write_text(text)
    (session / "top.mkv").write_bytes(np.random.default_rng(1).bytes(20000))  # never decoded
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no numpy "mean of empty slice" on the way
        rc, _, err = run_cli(capsys, ["track", session, "-c", serial_config])
    assert_one_line_error(rc, err, "side_timestamps.csv", "frame row(s) below the header")


@pytest.mark.parametrize(
    "scale, needle",
    [(1000.0, "look like milliseconds: divide by 1000"), (1e9, "look like ms, us or ns")],
)
def test_timestamps_not_in_seconds(session, serial_config, capsys, scale, needle):
    """Camera times exported in ms (or ns) would make every window and gap 1000x off."""
    p = session / "side_timestamps.csv"
    ts = pd.read_csv(p)
    ts["time_s"] *= scale
    ts.to_csv(p, index=False)
    rc, _, err = run_cli(capsys, ["track", session, "-c", serial_config])
    assert_one_line_error(rc, err, "side_timestamps.csv", "time_s must be in seconds", needle)
    assert not (session / "track").exists()


def test_timestamps_header_with_spaces(tmp_path):
    """'frame, time_s' (a space after the comma, as spreadsheets write) is read."""
    from i2ris_calib.io.timestamps import read_timestamps

    p = tmp_path / "t.csv"
    p.write_text("frame, time_s\n0, 0.0\n1, 0.05\n2, 0.1\n")
    ts = read_timestamps(p)
    assert ts["time_s"].tolist() == [0.0, 0.05, 0.1] and ts["valid"].all()


def _cli_subprocess(args: list[str], **kw) -> subprocess.Popen:
    env = {k: v for k, v in os.environ.items() if not k.startswith("OPENCV_")}
    return subprocess.Popen(
        [sys.executable, "-m", "i2ris_calib.cli", *map(str, args)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, **kw,
    )  # fmt: skip


def test_ffmpeg_lines_are_quiet_unless_debug(session, serial_config):
    """A corrupt video: FFmpeg's own '[matroska,webm @ 0x...] EBML header parsing
    failed' stays out of the way (a fresh process: the log level is read when OpenCV
    loads FFmpeg)."""
    (session / "side.mkv").write_bytes(np.random.default_rng(2).bytes(20000))
    p = _cli_subprocess(["track", session, "-c", serial_config])
    out, err = p.communicate(timeout=120)
    assert_one_line_error(p.returncode, err, "side.mkv", "cannot decode video")
    assert not (session / "track").exists()
    p = _cli_subprocess(["--debug", "track", session, "-c", serial_config])
    out, err = p.communicate(timeout=120)
    assert p.returncode != 0 and "[matroska" in err  # --debug shows everything


def test_ctrl_c_prints_the_message(session, capsys, monkeypatch):
    import i2ris_calib.commands.track as track_command

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(track_command, "track_session", interrupted)
    rc, _, err = run_cli(capsys, ["track", session])
    assert rc == 130
    assert err.strip() == "interrupted (no partial outputs were kept)"


def _children(pid: int) -> list[int]:
    try:
        text = Path(f"/proc/{pid}/task/{pid}/children").read_text()
    except OSError:
        return []
    return [int(c) for c in text.split()]


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs /proc")
def test_ctrl_c_with_worker_processes(session, tmp_path):
    """Ctrl-C reaches the whole process group (both detection workers too): one line,
    exit 130, no worker traceback, nothing written, no worker left running."""
    cfg = tmp_path / "two.toml"
    cfg.write_text("[track]\nworkers = 2\n")
    p = _cli_subprocess(["track", session, "-c", cfg], start_new_session=True,
                        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))  # fmt: skip
    deadline = time.monotonic() + 60
    while len(_children(p.pid)) < 2 and time.monotonic() < deadline and p.poll() is None:
        time.sleep(0.05)
    workers = _children(p.pid)
    assert len(workers) >= 2, "the workers never started"
    time.sleep(0.3)
    os.killpg(p.pid, signal.SIGINT)  # what the terminal does on Ctrl-C
    _, err = p.communicate(timeout=60)
    assert p.returncode == 130, err
    assert err.strip() == "interrupted (no partial outputs were kept)", err
    assert not (session / "track").exists()
    time.sleep(0.5)
    assert not [w for w in workers if Path(f"/proc/{w}").exists()
                and "zombie" not in Path(f"/proc/{w}/status").read_text()]  # fmt: skip


# ------------------------------------------------------- what a lab hits next (extended)
def _drop_video_frames(video: Path, timestamps: Path, drop: range) -> None:
    """Re-encode ``video`` without the frames ``drop`` and remove their timestamp rows
    (a camera that dropped them: absent from both files, docs/session.md)."""
    from i2ris_calib.io.video import iter_frames, open_writer

    frames = list(iter_frames(video))
    h, w = frames[0].shape
    tmp = video.with_name("tmp_" + video.name)
    writer = open_writer(tmp, 30.0, (w, h))
    for k, f in enumerate(frames):
        if k not in drop:
            writer.write(f)
    writer.release()
    tmp.replace(video)
    ts = pd.read_csv(timestamps)
    ts = ts.drop(index=list(drop)).reset_index(drop=True)
    ts["frame"] = np.arange(len(ts))
    ts.to_csv(timestamps, index=False, float_format="%.6f")


def test_dropped_frames_are_flagged_not_guessed(session, serial_config, capsys):
    side_t = pd.read_csv(session / "side_timestamps.csv")["time_s"].to_numpy()
    gap = (side_t[99], side_t[120])  # 20 frames, 1 s > max_interp_gap_s
    _drop_video_frames(session / "side.mkv", session / "side_timestamps.csv", range(100, 120))
    rc, _, err = run_cli(capsys, ["track", session, "-c", serial_config])
    assert rc == 0, err
    assert "warning: camera 'side' dropped about 20 frame(s) in 1 gap(s)" in err
    a = pd.read_csv(session / "track" / "angles.csv")
    inside = (a["time_s"] > gap[0] + 1e-4) & (a["time_s"] < gap[1] - 1e-4)
    assert inside.sum() >= 18
    assert (a.loc[inside, "status"] == "not_found").all()
    assert a.loc[inside, ["yaw_deg", "pitch_deg"]].isna().all().all()
    js = json.loads((session / "track" / "track.json").read_text())
    g = js["cameras"]["side"]["gaps"]
    assert g["count"] == 1 and g["missing_frames"] == 20 and g["over_max_interp_gap"] == 1
    assert js["cameras"]["top"]["gaps"]["count"] == 0
    assert any("dropped about 20" in w for w in js["warnings"])


@pytest.mark.parametrize("extra", [-5, 5])
def test_video_and_timestamps_frame_counts_differ(tracked_copy, serial_config, capsys, extra):
    """More or fewer timestamp rows than video frames: refused, earlier outputs kept."""
    before = tree_digest(tracked_copy / "track")
    p = tracked_copy / "top_timestamps.csv"
    ts = pd.read_csv(p)
    if extra < 0:
        ts = ts.iloc[:extra]
    else:
        t_last, n = ts["time_s"].iloc[-1], len(ts)
        more = pd.DataFrame(
            {"frame": n + np.arange(extra), "time_s": t_last + (1 + np.arange(extra)) / 30}
        )
        ts = pd.concat([ts, more], ignore_index=True)  # fmt: skip
    ts.to_csv(p, index=False, float_format="%.6f")
    rc, _, err = run_cli(capsys, ["track", tracked_copy, "-c", serial_config])
    n = len(ts)
    assert_one_line_error(
        rc, err, "top.mkv", f"but {n} rows in top_timestamps.csv", "one row per frame"
    )
    assert tree_digest(tracked_copy / "track") == before


def test_moved_session_keeps_working(tracked, serial_config, tmp_path, capsys):
    """Paths in session.toml are relative to the session folder: a moved (and renamed)
    session syncs from its own files; a path written absolute names itself when gone."""
    moved = tmp_path / "elsewhere" / "deeper" / "renamed"
    shutil.copytree(tracked, tmp_path / "orig")
    moved.parent.mkdir(parents=True)
    shutil.move(tmp_path / "orig", moved)
    rc, _, err = run_cli(capsys, ["sync", moved, "-c", serial_config])
    assert rc == 0, err
    js = json.loads((moved / "sync" / "sync.json").read_text())
    assert all(p.startswith(str(moved)) for p in js["provenance"]["inputs"])
    gone = tmp_path / "was_here" / "top.mkv"
    edit_toml(moved / "session.toml", 'video = "top.mkv"', f'video = "{gone}"')
    rc, _, err = run_cli(capsys, ["track", moved, "-c", serial_config])
    assert_one_line_error(rc, err, str(gone), "not found", "fix the path in session.toml")
