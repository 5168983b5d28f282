"""``simulate``: session layout, clock convention, determinism, refusal to overwrite."""

from __future__ import annotations

import hashlib
import io
import sys

import numpy as np
import pandas as pd
import pytest

from i2ris_calib.cli import main
from i2ris_calib.io.session import load_session

TOML = """
[simulate]
width_px = 192
height_px = 160
marker_size_px = 60.0
focal_px = 20000.0
pivot_mm = 0.6
datasets = ["yaw-"]
cycles = 1
cycle_fractions = [1.0]
ramp_s = 0.5
pause_s = 0.2
rest_s = 0.6
settle_s = 0.3
offset_s = 5.0
drift_ppm = 150.0
drop_fraction = 0.1
"""


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    root = tmp_path_factory.mktemp("sim")
    (root / "c.toml").write_text(TOML)
    with pytest.MonkeyPatch.context() as mp:
        out = io.StringIO()
        mp.setattr(sys, "stdout", out)
        assert (
            main(["simulate", "--out", str(root / "a"), "-c", str(root / "c.toml"), "--seed", "4"])
            == 0
        )
    (root / "stdout.txt").write_text(out.getvalue())
    return root


def test_says_what_it_wrote(sim):
    """Off a terminal too: the last line names the session folder."""
    last = (sim / "stdout.txt").read_text().strip().splitlines()[-1]
    assert last.startswith(f"wrote {sim / 'a'} ") and "session.toml" in last


def test_layout_matches_docs(sim):
    s = sim / "a"
    spec = load_session(s)
    for cam in spec.cameras.values():
        assert (s / cam.video).is_file() and (s / cam.timestamps).is_file()
    for f in (
        "encoders.csv",
        "truth/truth.json",
        "truth/truth_controller.csv",
        "truth/truth_frames.csv",
    ):
        assert (s / f).is_file()
    enc = pd.read_csv(s / "encoders.csv")
    assert list(enc.columns) == ["time_s", "enc_yaw", "enc_pitch", "sync_flash"]
    assert (
        enc["sync_flash"].sum() > 0
        and enc["enc_yaw"].min() < -1000
        and (enc["enc_pitch"] == 0).all()
    )


def test_clock_convention(sim):
    tf = pd.read_csv(sim / "a" / "truth" / "truth_frames.csv")
    assert np.allclose(tf["time_ctrl_s"], 5.0 + (1 + 150e-6) * tf["time_s"], atol=2e-6)


def test_dropped_frames_leave_gaps_in_the_timestamps(sim):
    ts = pd.read_csv(sim / "a" / "top_timestamps.csv")
    assert (ts["frame"] == np.arange(len(ts))).all()
    dt = np.diff(ts["time_s"])
    assert dt.min() > 0 and dt.max() > 1.5 / 30.0


def test_same_seed_same_session_and_no_overwrite(sim, tmp_path):
    assert main(["simulate", "--out", str(sim / "a"), "-c", str(sim / "c.toml")]) == 2  # exists
    assert (
        main(["simulate", "--out", str(tmp_path / "b"), "-c", str(sim / "c.toml"), "--seed", "4"])
        == 0
    )

    def h(p):
        return hashlib.sha256(p.read_bytes()).hexdigest()

    for f in ("encoders.csv", "top_timestamps.csv", "truth/truth_frames.csv"):
        assert h(sim / "a" / f) == h(tmp_path / "b" / f), f
    # container metadata may differ; the decoded frames must not
    from i2ris_calib.io.video import iter_frames

    for fa, fb in zip(
        iter_frames(sim / "a" / "top.mkv"), iter_frames(tmp_path / "b" / "top.mkv"), strict=True
    ):
        assert np.array_equal(fa, fb)
