"""Encoder values between log samples: corners of piecewise-linear motion restored."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from i2ris_calib.sync.log import Channel, EncoderLog, corner_knots

RATE_HZ = 100.0


def _ramps(durations_s, speeds, t_s):
    """Piecewise-linear motion (counts) at ``t_s``: segments of the given durations and
    speeds (counts/s), starting at 0 counts at t = 0."""
    knots_t = np.concatenate([[0.0], np.cumsum(durations_s)])
    knots_v = np.concatenate([[0.0], np.cumsum(np.asarray(durations_s) * np.asarray(speeds))])
    return np.interp(t_s, knots_t, knots_v)


def _log(t, v, interpolation="corners") -> EncoderLog:
    return EncoderLog({"enc_yaw": Channel(t, v)}, interpolation=interpolation)


@settings(max_examples=60, deadline=None)
@given(
    durations=st.lists(st.floats(0.06, 0.8), min_size=3, max_size=8),
    speeds=st.lists(
        st.sampled_from([-2400.0, -1600.0, -800.0, 0.0, 800.0, 1600.0, 2400.0]),
        min_size=8,
        max_size=8,
    ),  # fmt: skip
    phase=st.floats(0.0, 1.0),
)
def test_piecewise_linear_motion_is_restored_to_the_rounding(durations, speeds, phase):
    """Ramps, reversals and holds of at least 6 samples, logged at 100 Hz as whole counts
    at a random phase: between samples the restored input is within 1.6 counts of the
    truth (rounding of the samples that place each corner), wherever the corner falls."""
    speeds = speeds[: len(durations)] + [0.0]  # a final hold: every corner has samples after it
    durations = durations + [0.1]
    t_log = (np.arange(int(sum(durations) * RATE_HZ)) + phase) / RATE_HZ
    v_log = np.round(_ramps(durations, speeds, t_log))
    t_q = np.linspace(t_log[0], t_log[-1], 20 * t_log.size)
    truth = _ramps(durations, speeds, t_q)
    err = np.abs(_log(t_log, v_log).interpolate("enc_yaw", t_q) - truth)
    assert err.max() <= 1.6, err.max()


def test_corners_shrink_the_error_of_linear_interpolation_at_reversals():
    """A 1600 counts/s triangle wave reversing half-way between two 100 Hz samples:
    linear interpolation cuts each peak by ~8 counts, the restored corners by < 1.5."""
    t_log = np.arange(0, 4.0, 1 / RATE_HZ)
    durations, speeds = [0.505, 1.0, 1.0, 1.0], [1600.0, -1600.0, 1600.0, -1600.0]
    v_log = np.round(_ramps(durations, speeds, t_log))
    t_q = np.linspace(0.02, 3.9, 20000)  # three reversals and the stop
    truth = _ramps(durations, speeds, t_q)
    lin = np.abs(_log(t_log, v_log, "linear").interpolate("enc_yaw", t_q) - truth).max()
    cor = np.abs(_log(t_log, v_log).interpolate("enc_yaw", t_q) - truth).max()
    assert lin > 6.5 and cor < 1.5, (lin, cor)
    np.testing.assert_allclose(
        corner_knots(t_log, v_log)[0], [0.505, 1.505, 2.505, 3.505], atol=3e-4
    )


def test_smooth_or_noisy_motion_keeps_linear_interpolation(rng):
    """No corner is invented: a sinusoid (accelerating at every sample) and a hold with
    encoder noise of 2 counts keep plain linear interpolation."""
    t = np.arange(0, 20.0, 1 / RATE_HZ)
    for v in (np.round(2000 * np.sin(2 * np.pi * 0.2 * t)), np.round(rng.normal(500, 2.0, t.size))):
        assert corner_knots(t, v)[0].size == 0
        t_q = np.linspace(0, 19.9, 5000)
        np.testing.assert_array_equal(_log(t, v).interpolate("enc_yaw", t_q), np.interp(t_q, t, v))


def test_outside_the_log_is_nan_and_shifted_log_keeps_the_interpolation():
    t = np.arange(10) / RATE_HZ
    log = _log(t, np.arange(10.0) * 5, "linear").shifted(1.0)
    assert log.interpolation == "linear"
    out = log.interpolate("enc_yaw", np.array([0.5, 1.045, 2.0]))
    assert np.isnan(out[[0, 2]]).all() and out[1] == pytest.approx(22.5)
