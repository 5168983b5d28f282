"""``track`` on rendered sessions: outputs, and every kind of bad input (issue 3)."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pandas as pd
import pytest

from i2ris_calib.cli import main
from i2ris_calib.errors import CalibError
from i2ris_calib.io.simulate import build_session
from i2ris_calib.io.track import read_timestamps, track_session
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
