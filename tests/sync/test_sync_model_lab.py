"""The model clock method on a lab-style recording (both motors through zero, any start):
each axis gets the model `fit` would choose (choose_model), not the paper's split."""

from __future__ import annotations

import numpy as np
from two_motor_log import series_and_log as _series_and_log

from i2ris_calib.fitting.config import FitConfig
from i2ris_calib.simulation.two_motor import simulate_two_motor
from i2ris_calib.sync.joint import model_blocks


def test_lab_recording_gets_the_signed_coupled_model():
    rec = simulate_two_motor(1, n_samples=600, rate_hz=30.0, noise_deg=0.2)
    series, log = _series_and_log(rec)
    blocks = model_blocks(series, log, 3.0, float(rec.t_s.mean()), 0.05, FitConfig(), 50.0)
    assert [b.name for b in blocks] == ["yaw±", "pitch±"]
    assert {b.kind for b in blocks} == {"agpi_coupled"}
    assert [b.other_channel for b in blocks] == ["enc_pitch", "enc_yaw"]
    assert all("signed input" in b.why for b in blocks)


def test_paper_split_is_kept_when_forced_and_one_motor_records_keep_no_coupling():
    rec = simulate_two_motor(1, n_samples=600, rate_hz=30.0, noise_deg=0.2)
    series, log = _series_and_log(rec)
    split = model_blocks(series, log, 3.0, 10.0, 0.05, FitConfig(split=True), 50.0)
    assert {b.name for b in split} == {"yaw+", "yaw-", "pitch+", "pitch-"}
    assert {b.kind for b in split} == {""} and {b.other_channel for b in split} == {None}
    only_yaw = model_blocks(series[:1], log, 3.0, 10.0, 0.05, FitConfig(), 50.0)
    assert [(b.name, b.kind, b.other_channel) for b in only_yaw] == [("yaw±", "agpi", None)]
    assert np.isfinite(only_yaw[0].theta_deg).sum() > 500
