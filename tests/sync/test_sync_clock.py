"""Clock model, weighted line through local offsets, encoder-log validation."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from i2ris_calib.errors import CalibError
from i2ris_calib.sync.clock import ClockModel, clock_from_offsets
from i2ris_calib.sync.log import make_encoder_log


@settings(max_examples=40, deadline=None)
@given(o=st.floats(-1e4, 1e4), d=st.floats(-500, 500), t=st.floats(0, 1e4))
def test_clock_maps_with_convention(o, d, t):
    c = ClockModel(o, d)
    assert c.to_ctrl(t) == pytest.approx(o + (1 + d * 1e-6) * t, rel=1e-12, abs=1e-9)
    assert c.offset_at(t) == pytest.approx(c.to_ctrl(t) - t, abs=1e-6)


def test_line_through_offsets_recovers_truth_and_stderr(rng):
    t = np.linspace(0, 100, 20)
    truth_o, truth_d, sd = 0.25, 75.0, 2e-4
    errs = []
    for _ in range(200):
        y = truth_o + truth_d * 1e-6 * t + rng.normal(0, sd, t.size)
        o, d, cov, _ = clock_from_offsets(t, y, np.full(t.size, sd))
        errs.append(((o - truth_o) / np.sqrt(cov[0, 0]), (d - truth_d) / np.sqrt(cov[1, 1])))
    z = np.array(errs)
    # standard errors calibrated: z-scores have sd ~1 (tolerance for 200 trials)
    assert 0.8 < z[:, 0].std() < 1.25 and 0.8 < z[:, 1].std() < 1.25
    assert abs(z.mean(axis=0)).max() < 0.3


def test_line_without_drift_holds_it_at_zero():
    o, d, cov, _ = clock_from_offsets(np.array([3.0]), np.array([1.5]), np.array([1e-3]))
    assert (o, d) == (1.5, 0.0) and cov[1, 1] == 0.0


def test_residual_scaling_always_uses_scatter(rng):
    t = np.linspace(0, 10, 30)
    y = 1.0 + rng.normal(0, 1e-2, t.size)
    _, _, cov_trust, _ = clock_from_offsets(t, y, np.full(t.size, 1.0))  # sd claimed 1 s
    _, _, cov_always, _ = clock_from_offsets(t, y, np.full(t.size, 1.0), scale="always")
    assert np.sqrt(cov_always[0, 0]) < 0.01 < np.sqrt(cov_trust[0, 0])


def test_encoder_log_interpolates_and_refuses_to_extrapolate():
    t = np.arange(5, dtype=float)
    log = make_encoder_log({"enc_yaw": (t, 10 * t), "enc_pitch": (t, -t)}, None, "x", 2.0)
    out = log.interpolate("enc_yaw", np.array([-0.5, 1.5, 4.5]))
    assert np.isnan(out[0]) and out[1] == 15.0 and np.isnan(out[2])
    assert log.time_range() == (0.0, 4.0)


@pytest.mark.parametrize(
    ("t", "msg"),
    [
        (np.array([0.0, 1.0, 0.5, 2.0]), "clock reset"),
        (np.array([0.0, 1.0, 1.0, 2.0]), "repeated timestamp"),
        (np.array([0.0, 1.0, 5.0, 6.0]), "gap of 4.000 s"),
        (np.array([0.0, np.nan, 2.0, 3.0]), "non-numeric"),
    ],
)
def test_encoder_log_validation(t, msg):
    with pytest.raises(CalibError, match=msg):
        make_encoder_log({"enc_yaw": (t, np.zeros(4))}, None, "log.csv", max_gap_s=2.0)
