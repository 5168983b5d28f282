"""``i2ris-calib sync`` end to end on synthetic sessions written to disk (no video)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from i2ris_calib.cli import main
from i2ris_calib.sync.synthetic import make_sync_case

FLASHES = ((0.5, 0.4), (12.0, 0.3), (23.0, 0.5))


def write_session(folder: Path, case, encoder_table: str = "", log: pd.DataFrame | None = None):
    """session.toml, encoders.csv and track/angles.csv of a synthetic case."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "session.toml").write_text(
        f'name = "{folder.name}"\n{encoder_table}\n'
        '[cameras.top]\nvideo = "top.mkv"\n[cameras.side]\nvideo = "side.mkv"\n'
    )
    (log if log is not None else case.log_frame).to_csv(
        folder / "encoders.csv", index=False, float_format="%.6f"
    )
    (folder / "track").mkdir(exist_ok=True)
    case.angles.to_csv(folder / "track" / "angles.csv", index=False, float_format="%.6f")
    return folder


def _case(**kw):
    base = dict(
        seed=3, duration_s=25.0, n_cycles=2, log_rate_hz=1000.0, exposure_frac=1.0, log_edge="tick"
    )
    return make_sync_case(**(base | kw))


def _run(args, capsys):
    rc = main([str(a) for a in args])
    return rc, capsys.readouterr().err


def test_event_sync_writes_contract_files(tmp_path, capsys):
    case = _case(flashes=FLASHES)
    cfg = tmp_path / "c.toml"
    cfg.write_text('[sync]\nlog_edge_at = "first_on"\n')
    s = write_session(tmp_path / "s", case)
    rc, err = _run(["sync", s, "--config", cfg], capsys)
    assert rc == 0, err
    js = json.loads((s / "sync" / "sync.json").read_text())
    assert js["method"] == "event"
    # tolerance: 1 ms offset, 10 ppm drift (the sync-event requirement)
    assert abs(js["offset_s"] - case.offset_s) < 1e-3
    assert abs(js["drift_ppm"] - case.drift_ppm) < 10
    assert js["offset_stderr_s"] > 0 and js["drift_stderr_ppm"] > 0
    assert js["provenance"]["inputs"] and "config" in js["provenance"]
    syn = pd.read_csv(s / "sync" / "synced.csv")
    assert list(syn.columns[:7]) == [
        "time_s",
        "enc_yaw",
        "enc_pitch",
        "yaw_deg",
        "pitch_deg",
        "status",
        "frame",
    ]
    assert len(syn) + js["n_dropped_outside_log"] == len(case.angles)
    # encoders interpolated at the mapped time match the log at the true time (1 count
    # of rounding + the clock error times the speed)
    t_true = case.offset_s + (1 + case.drift_ppm * 1e-6) * syn["time_cam_s"].to_numpy()
    enc_true = np.interp(t_true, case.log_frame["time_s"], case.log_frame["enc_yaw"])
    assert np.max(np.abs(syn["enc_yaw"] - enc_true)) < 3.0


def test_frames_outside_log_are_dropped_and_counted(tmp_path, capsys):
    case = _case(flashes=FLASHES)
    lf = case.log_frame
    t_first_frame_ctrl = case.offset_s + case.angles["time_s"].iloc[0]
    short = lf[lf["time_s"] < t_first_frame_ctrl + 20.0]  # log ends 5 s before the video
    s = write_session(tmp_path / "s", case, log=short)
    rc, err = _run(["sync", s, "--method", "event"], capsys)
    assert rc == 0, err
    js = json.loads((s / "sync" / "sync.json").read_text())
    n_out = int((case.offset_s + case.angles["time_s"] > short["time_s"].iloc[-1]).sum())
    assert abs(js["n_dropped_outside_log"] - n_out) <= 1


def test_xcorr_method_and_custom_out(tmp_path, capsys):
    case = _case()
    s = write_session(tmp_path / "s", case)
    rc, err = _run(["sync", s, "--method", "xcorr", "--out", tmp_path / "o"], capsys)
    assert rc == 0, err
    js = json.loads((tmp_path / "o" / "sync.json").read_text())
    assert js["method"] == "xcorr" and "biased" in js["evidence"]["note"]


@pytest.mark.slow  # ~10 s; the core test covers the accuracy by default
def test_auto_without_flash_uses_model(tmp_path, capsys):
    case = _case(backlash_deg=6.0)
    s = write_session(tmp_path / "s", case)
    rc, err = _run(["sync", s], capsys)
    assert rc == 0, err
    js = json.loads((s / "sync" / "sync.json").read_text())
    assert js["method"] == "model" and "no sync_flash" in js["evidence"]["auto"]
    mid = js["t_ref_cam_s"]
    err_mid = js["offset_at_t_ref_s"] - (case.offset_s + case.drift_ppm * 1e-6 * mid)
    assert abs(err_mid) < 5e-3  # 5 ms: the no-event requirement
    assert js["xcorr_comparison"]["offset_s"] is not None


def _one_line_error(rc, err, pattern):
    assert rc == 2
    assert err.startswith("error: ") and len(err.strip().splitlines()) == 1, err
    assert "Traceback" not in err
    assert pattern in err, err


def test_missing_encoder_log(tmp_path, capsys):
    s = write_session(tmp_path / "s", _case())
    (s / "encoders.csv").unlink()
    _one_line_error(*_run(["sync", s], capsys), "encoder log 'encoders.csv' not found")
    assert not (s / "sync").exists()


def test_missing_angles(tmp_path, capsys):
    s = write_session(tmp_path / "s", _case())
    (s / "track" / "angles.csv").unlink()
    _one_line_error(*_run(["sync", s], capsys), "run 'i2ris-calib track")


def test_gap_in_log(tmp_path, capsys):
    case = _case()
    lf = case.log_frame
    gap = lf[(lf["time_s"] < 5.0) | (lf["time_s"] > 6.0)]
    s = write_session(tmp_path / "s", case, log=gap)
    _one_line_error(*_run(["sync", s], capsys), "gap of")


def test_clock_reset_in_log(tmp_path, capsys):
    case = _case()
    lf = case.log_frame.copy()
    lf.loc[lf.index >= 9000, "time_s"] -= 3.0
    s = write_session(tmp_path / "s", case, log=lf)
    _one_line_error(*_run(["sync", s], capsys), "clock reset")


def test_no_overlap_between_video_and_log(tmp_path, capsys):
    case = _case()
    s = write_session(tmp_path / "s", case)
    cfg = tmp_path / "c.toml"
    # the user says the clocks agree within 1 s, but the log is 0.5 s + far away
    cfg.write_text('[sync]\noffset_guess_s = 500.0\noffset_search_s = 1.0\nmethod = "xcorr"\n')
    _one_line_error(*_run(["sync", s, "--config", cfg], capsys), "no overlap")


def test_too_little_overlap_after_event_sync(tmp_path, capsys):
    case = _case(flashes=FLASHES)
    lf = case.log_frame
    flash_only = lf[lf["time_s"] < case.offset_s + 1.2]  # log holds ~2 s around the first flash
    s = write_session(tmp_path / "s", case, log=flash_only)
    cfg = tmp_path / "c.toml"
    cfg.write_text("[sync]\nmin_overlap_frames = 100\n")
    _one_line_error(
        *_run(["sync", s, "--method", "event", "--config", cfg], capsys), "do not overlap"
    )


def test_bag_without_configured_topic(tmp_path, capsys):
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    s = write_session(
        tmp_path / "s", _case(), encoder_table='[encoder]\nfile = "enc.bag"\nformat = "rosbag"\n'
    )
    ts = get_typestore(Stores.ROS1_NOETIC)
    with Writer(s / "enc.bag") as w:
        conn = w.add_connection("/somewhere/else", "std_msgs/msg/Int32", typestore=ts)
        msg = ts.types["std_msgs/msg/Int32"](data=1)
        w.write(conn, 10**9, ts.serialize_ros1(msg, "std_msgs/msg/Int32"))
    _one_line_error(*_run(["sync", s], capsys), "no topic '/i2ris/yaw/encoder'")


def test_event_method_without_flash_column(tmp_path, capsys):
    s = write_session(tmp_path / "s", _case())
    _one_line_error(*_run(["sync", s, "--method", "event"], capsys), "no sync_flash")


def _toml_value(x):
    if isinstance(x, str):
        return f'"{x}"'
    if isinstance(x, tuple | list):
        return "[" + ", ".join(_toml_value(v) for v in x) + "]"
    return repr(x)


@pytest.mark.slow  # ~20 s: renders, tracks and syncs a ci session
def test_rendered_ci_session_event_is_honest_and_auto_refines(tmp_path, capsys):
    """Regression on a rendered session (``ci`` preset, 3 cycles): 10 ms exposure at
    30 fps, a 100 Hz log sampling the LED, 0.2 s (= 6 frame) flashes, [sync] defaults
    (exposure not configured). The event offset was 9 ms off with a stated 1.8 ms;
    now the error in the middle of the recording is within 2.5 stated sd, and ``auto``
    refines it with the model to <= 5 ms (the issue-4 no-event bound; ~0.5 ms measured)."""
    from i2ris_calib.simulation.presets import PRESETS

    # the simulator's former sync defaults, pinned: coarse events that auto must refine
    old_sync = {"exposure_s": 0.01, "encoder_rate_hz": 100.0, "n_flashes": 2, "flash_gain": 0.35}
    keys = PRESETS["ci"] | {"cycles": 3, "cycle_fractions": (1.0, 0.7, 1.0)} | old_sync
    sim = tmp_path / "sim.toml"
    sim.write_text("[simulate]\n" + "".join(f"{k} = {_toml_value(v)}\n" for k, v in keys.items()))
    s = tmp_path / "s"
    for args in (["simulate", "--out", s, "--config", sim], ["track", s]):
        rc, err = _run(args, capsys)
        assert rc == 0, err
    truth = json.loads((s / "truth" / "truth.json").read_text())
    for method in ("event", "auto"):
        rc, err = _run(["sync", s, "--method", method, "--out", tmp_path / method], capsys)
        assert rc == 0, err
        js = json.loads((tmp_path / method / "sync.json").read_text())
        mid = js["t_ref_cam_s"]
        err_mid = js["offset_at_t_ref_s"] - (truth["offset_s"] + truth["drift_ppm"] * 1e-6 * mid)
        if method == "event":
            assert abs(err_mid) <= 2.5 * js["offset_at_t_ref_stderr_s"], err_mid
        else:
            assert js["method"] == "event+model" and "event" in js["evidence"], js["evidence"]
            assert abs(err_mid) <= 5e-3
            assert abs(js["offset_s"] - truth["offset_s"]) <= 5e-3
