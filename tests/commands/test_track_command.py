"""``track`` on rendered sessions: outputs, and every kind of bad input (issue 3)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from i2ris_calib.cli import main
from i2ris_calib.commands.simulate import build_session
from i2ris_calib.commands.track import track_session
from i2ris_calib.errors import CalibError
from i2ris_calib.io.timestamps import read_timestamps
from i2ris_calib.simulation.presets import preset_config


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    """pitch- only; pivot 1.5 mm drives the side marker out of the 320x256 frame at
    large pitch; 5 % dropped frames; one occlusion per camera."""
    folder = tmp_path_factory.mktemp("trk") / "s"
    folder.mkdir()
    cfg = preset_config("ci", datasets=("pitch-",), pivot_mm=1.5, drop_fraction=0.05,
                        occlusions=1, occlusion_s=0.3, seed=3)  # fmt: skip
    build_session(folder, cfg, name="s")
    return folder


def _copy(session, tmp_path):
    dst = tmp_path / "s"
    shutil.copytree(session, dst)
    return dst


def _config():
    """Serial streams: spawning worker processes costs more than these tiny videos."""
    from i2ris_calib.config import PipelineConfig
    from i2ris_calib.tracking.config import TrackingConfig

    return PipelineConfig(track=TrackingConfig(workers=1))


def test_cli_writes_documented_outputs(session, tmp_path):
    out = tmp_path / "track"
    assert main(["track", str(session), "--out", str(out)]) == 0
    a = pd.read_csv(out / "angles.csv")
    for col in ("frame", "time_s", "yaw_deg", "pitch_deg", "status", "reproj_err_px",
                "mean_gray_top", "mean_gray_side"):  # fmt: skip
        assert col in a.columns
    assert set(a["status"]) <= {"measured", "not_found", "ambiguous", "rejected"}
    js = json.loads((out / "track.json").read_text())
    assert js["frames"] == len(a) and "inputs" in js["provenance"]
    # out-of-image and occluded frames are flagged, never guessed
    truth = pd.read_csv(session / "truth" / "truth_frames.csv")
    m = a.merge(truth, on="frame", suffixes=("", "_true"))
    hidden = (m["visible_top"] == 0) | (m["visible_side"] == 0)
    assert hidden.sum() > 5 and (m.loc[hidden, "status"] != "measured").all()
    ok = m["status"] == "measured"
    assert ok.sum() > 0.6 * len(m)
    assert (m["pitch_deg"] - m["pitch_deg_true"])[ok].abs().max() < 0.35


def test_missing_video(session, tmp_path):
    s = _copy(session, tmp_path)
    (s / "top.mkv").unlink()
    with pytest.raises(CalibError, match="video of camera 'top'.*not found"):
        track_session(s, None, _config())


def test_corrupt_video(session, tmp_path):
    s = _copy(session, tmp_path)
    (s / "side.mkv").write_bytes(np.random.default_rng(0).bytes(20000))
    with pytest.raises(CalibError, match="side.mkv"):
        track_session(s, None, _config())
    assert not (s / "track").exists()  # nothing half-written


def test_truncated_video(session, tmp_path):
    s = _copy(session, tmp_path)
    data = (s / "top.mkv").read_bytes()
    (s / "top.mkv").write_bytes(data[: len(data) // 2])
    with pytest.raises(CalibError, match="top.mkv"):
        track_session(s, None, _config())


def test_timestamp_count_mismatch(session, tmp_path):
    s = _copy(session, tmp_path)
    ts = pd.read_csv(s / "side_timestamps.csv").iloc[:-7]
    ts.to_csv(s / "side_timestamps.csv", index=False)
    with pytest.raises(CalibError, match="rows in side_timestamps.csv"):
        track_session(s, None, _config())


def test_a_few_non_monotonic_timestamps_are_flagged(session, tmp_path):
    s = _copy(session, tmp_path)
    ts = pd.read_csv(s / "top_timestamps.csv")
    ts.loc[40, "time_s"] = ts.loc[38, "time_s"]  # goes backwards once
    ts.to_csv(s / "top_timestamps.csv", index=False)
    track_session(s, None, _config())
    a = pd.read_csv(s / "track" / "angles.csv")
    assert a.loc[40, "status"] == "rejected" and np.isnan(a.loc[40, "yaw_deg"])


def test_many_non_monotonic_timestamps_are_refused(tmp_path):
    p = tmp_path / "t.csv"
    pd.DataFrame({"frame": range(10), "time_s": [0, 1, 2, 1, 3, 2, 4, 5, 4, 6]}).to_csv(
        p, index=False
    )
    with pytest.raises(CalibError, match="not increasing"):
        read_timestamps(p)


def test_wrong_marker_id(session, tmp_path):
    s = _copy(session, tmp_path)
    text = (s / "session.toml").read_text().replace("marker_id = 1", "marker_id = 7")
    (s / "session.toml").write_text(text)
    with pytest.raises(CalibError, match="marker id 7 never found, but ids 1"):
        track_session(s, None, _config())


def test_wrong_dictionary(session, tmp_path):
    s = _copy(session, tmp_path)
    text = (s / "session.toml").read_text().replace("DICT_4X4_50", "DICT_6X6_250")
    (s / "session.toml").write_text(text)
    with pytest.raises(CalibError, match="no DICT_6X6_250 marker found"):
        track_session(s, None, _config())


def test_unknown_dictionary_name(session, tmp_path):
    s = _copy(session, tmp_path)
    text = (s / "session.toml").read_text().replace("DICT_4X4_50", "DICT_4X4_5O")
    (s / "session.toml").write_text(text)
    assert main(["track", str(s)]) == 2


# --- issue 19: the other camera's video; backward times are not dropped frames ------------
def _blind_stream(other_ids: dict, n: int = 6):
    """A stream in which the camera's own marker was never found."""
    from i2ris_calib.commands.track import StreamResult

    return StreamResult(np.full((n, 4, 2), np.nan), np.zeros(n), np.zeros(n, bool), other_ids,
                        (256, 320), 0, 0, 0.0, 0.0)  # fmt: skip


def _two_camera_spec():
    from i2ris_calib.session import CameraSpec, SessionSpec

    return SessionSpec(cameras={
        "top": CameraSpec(video="top.mkv", timestamps="top_timestamps.csv", marker_id=0),
        "side": CameraSpec(video="copy.mkv", timestamps="side_timestamps.csv", marker_id=1,
                           view="side"),
    })  # fmt: skip


def test_side_camera_reading_the_top_video_is_not_told_to_change_marker_id():
    """Seeing only the top camera's id means the side camera reads the top camera's film:
    setting its marker_id to that id would track one face twice (issue 19)."""
    from i2ris_calib.commands.track import check_stream

    spec = _two_camera_spec()
    ts = pd.DataFrame({"frame": range(6), "time_s": np.arange(6) / 30})
    with pytest.raises(CalibError) as exc:
        check_stream("side", Path("copy.mkv"), ts, _blind_stream({0: 6, 5: 1}),
                     spec.cameras["side"], spec)  # fmt: skip
    msg = str(exc.value)
    assert "\n" not in msg and "set marker_id" not in msg, msg
    assert "id 0 of camera 'top'" in msg and "[cameras.side] video 'copy.mkv'" in msg, msg
    assert "films the top camera's face" in msg and "videos are swapped" in msg, msg
    # an id of no camera (a wrong marker_id) still gets the marker_id advice
    with pytest.raises(CalibError, match="set marker_id of camera 'side'"):
        check_stream("side", Path("copy.mkv"), ts, _blind_stream({7: 6, 0: 1}),
                     spec.cameras["side"], spec)  # fmt: skip


def _timestamps(tmp_path, t):
    p = tmp_path / "t.csv"
    pd.DataFrame({"frame": range(len(t)), "time_s": t}).to_csv(p, index=False, float_format="%.6f")
    return read_timestamps(p)


@pytest.mark.parametrize(
    "case,dropped,backward,first",
    [
        ("duplicates", 0, 3, 40),  # times equal to two frames earlier (test above)
        ("swapped pair", 0, 1, 51),  # two frames' times exchanged
        ("late spike", 0, 2, 31),  # one time too late: the next two look backwards
        ("drop and duplicate", 5, 1, 40),  # 5 frames really dropped, one backward time
    ],
)
def test_backward_times_are_not_reported_as_dropped_frames(tmp_path, case, dropped, backward,
                                                           first):  # fmt: skip
    from i2ris_calib.commands.track import frame_gaps, track_warnings
    from i2ris_calib.tracking.config import TrackingConfig

    t = np.arange(200) / 30.0
    if case == "duplicates":
        for r in (40, 80, 120):
            t[r] = t[r - 2]
    elif case == "swapped pair":
        t[[50, 51]] = t[[51, 50]]
    elif case == "late spike":
        t[30] = t[32] + 0.5 / 30
    else:
        t = np.delete(t, range(100, 105))
        t[40] = t[38]
    g = frame_gaps(_timestamps(tmp_path, t), TrackingConfig())
    assert (g["missing_frames"], g["count"]) == (dropped, int(dropped > 0))
    assert (g["backward_frames"], g["first_backward_frame"]) == (backward, first)
    warnings = track_warnings({"cameras": {"top": {"gaps": g}}})
    assert any(f"{backward} frame(s) have a timestamp that goes backwards" in w and
               f"frame {first}" in w and "rejected" in w for w in warnings)  # fmt: skip
    assert any("dropped" in w for w in warnings) == (dropped > 0)
    if dropped:
        assert any(f"dropped about {dropped} frame(s) in 1 gap(s)" in w for w in warnings)


def test_a_moving_reference_window_is_a_warning():
    """track.json's reference.window_motion -> one terminal warning naming the window
    and the motion when the tip moved in it, none when it held still."""
    from i2ris_calib.commands.track import track_warnings, window_motion_record
    from i2ris_calib.tracking.config import TrackingConfig
    from i2ris_calib.tracking.reference_window import reference_window_motion

    t = np.arange(0.0, 5.0, 1 / 30)
    window = t <= 0.8
    lines = {}
    for name, yaw in (("still", 0.01 * np.sin(40 * t)), ("moving", 15 * np.sin(t))):
        motion = reference_window_motion(t, yaw, 0 * t, window)
        rec = window_motion_record(motion, TrackingConfig())
        summary = {"cameras": {}, "reference": {"window_motion": rec}}
        lines[name] = [w for w in track_warnings(summary) if "reference window" in w]
    assert lines["still"] == []
    (w,) = lines["moving"]
    moved = np.ptp(15 * np.sin(t[window]))  # the quadratic's excursion is close to it
    assert "reference window 0-0.8 s (yaw " in w and ", pitch 0.00 deg)" in w
    shown = float(w.split("(yaw ")[1].split(",")[0])
    assert abs(shown - moved) < 0.05 * moved
    assert "reference_start_s" in w and "\n" not in w
