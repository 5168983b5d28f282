"""Inputs, clocks and truth angles of the simulator."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from i2ris_calib.simulation import trajectory as tj
from i2ris_calib.simulation.presets import preset_config
from i2ris_calib.simulation.truth import session_truth


def test_clock_convention_round_trip_and_definition():
    cfg = preset_config("ci", offset_s=3.0, drift_ppm=100.0)
    t = np.array([0.0, 10.0, 100.0])
    assert np.allclose(tj.ctrl_from_cam(cfg, t), 3.0 + (1 + 1e-4) * t)
    assert np.allclose(tj.cam_from_ctrl(cfg, tj.ctrl_from_cam(cfg, t)), t)


def test_one_motor_moves_at_a_time_with_the_dataset_sign():
    cfg = preset_config("ci", datasets=("yaw+", "yaw-", "pitch+", "pitch-"))
    t = np.arange(-1, tj.motion_duration_s(cfg) + 1, 0.01)
    ey, ep = tj.session_inputs(cfg, t)
    assert not np.any((ey != 0) & (ep != 0))
    for b in tj.session_blocks(cfg):
        inside = (t >= b.t0_s) & (t <= b.t1_s)
        v = (ey if b.axis == "yaw" else ep)[inside]
        assert np.all(np.sign(v[v != 0]) == b.sign) and np.abs(v).max() == 4500


def test_truth_is_continuous_and_zero_at_every_dataset_boundary():
    cfg = preset_config("ci", datasets=("yaw+", "yaw-", "pitch+", "pitch-"), truth="blocks")
    tr = session_truth(cfg)
    for b in tj.session_blocks(cfg):
        for t in (b.t0_s, b.t1_s):
            k = np.argmin(np.abs(tr.t_s - t))
            assert abs(tr.yaw_deg[k]) < 1e-9 and abs(tr.pitch_deg[k]) < 1e-9
        theta = (tr.yaw_deg if b.axis == "yaw" else tr.pitch_deg)[
            tr.block == tj.session_blocks(cfg).index(b)
        ]
        big = np.abs(theta) > 0.5  # the model may dip ~0.1 deg below zero near v = 0
        assert np.all(np.sign(theta[big]) == b.sign)
    assert 20 < np.abs(tr.yaw_deg).max() < 60  # paper-like range (deg)


@given(st.floats(0.0, 0.4))
def test_dropped_frames_keep_first_and_last(frac):
    cfg = preset_config("ci", drop_fraction=frac)
    keep = tj.kept_frames(cfg, 200, np.random.default_rng(1))
    assert keep[0] and keep[-1]


def test_hidden_effect_changes_the_truth():
    base = session_truth(preset_config("ci"))
    delayed = session_truth(preset_config("ci", effects={"time_delay": {"tau_s": 0.2}}))
    assert np.abs(base.yaw_deg - delayed.yaw_deg).max() > 1.0
