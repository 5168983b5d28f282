"""The tip's motion within the reference window (tracking/reference_window.py)."""

from __future__ import annotations

import numpy as np
import pytest

from i2ris_calib.tracking.reference_window import (
    REFERENCE_MOTION_DEG,
    reference_window_motion,
)


def _window(rate_hz, duration_s=3.0, start_s=0.0, length_s=0.8):
    t = np.arange(0, duration_s, 1 / rate_hz)
    return t, (t >= start_s) & (t <= start_s + length_s)


@pytest.mark.parametrize("rate_hz, noise", [(30, 0.01), (30, 0.5), (5, 0.3)])
def test_a_still_tip_is_not_flagged_even_with_a_noisy_tracker(rate_hz, noise):
    rng = np.random.default_rng(1)
    t, w = _window(rate_hz)
    flagged = 0
    for _ in range(50):
        yaw = 0.2 + rng.normal(0, noise, t.size)  # a small constant bend: not motion
        pitch = rng.normal(0, noise, t.size)
        flagged += reference_window_motion(t, yaw, pitch, w).moving
    assert flagged == 0


def test_a_tip_bending_through_the_window_is_flagged_with_its_excursion():
    t, w = _window(30)
    yaw = 15 * np.sin(2 * np.pi * t / 6)  # a lab circle, 6 s period: 12 deg in 0.8 s
    pitch = 10 * np.cos(2 * np.pi * t / 6)
    m = reference_window_motion(t, yaw, pitch, w)
    assert m.moving and m.frames == int(w.sum())
    truth_yaw = np.ptp(yaw[w])
    assert abs(m.yaw_deg - truth_yaw) < 0.05 * truth_yaw
    assert m.pitch_deg > 0.5 and m.threshold_deg == pytest.approx(REFERENCE_MOTION_DEG)


def test_slow_drift_below_the_limit_passes_and_few_frames_say_nothing():
    t, w = _window(30)
    m = reference_window_motion(t, 0.3 * t, 0 * t, w)  # 0.24 deg over the window
    assert not m.moving and m.yaw_deg == pytest.approx(0.24, abs=0.01)
    t2, w2 = _window(2)  # 0.8 s at 2 Hz: 2 frames
    m2 = reference_window_motion(t2, 10 * t2, 0 * t2, w2)
    assert not m2.moving and np.isnan(m2.yaw_deg) and m2.frames == 2
    nan = np.full(t.size, np.nan)
    assert reference_window_motion(t, nan, nan, w).frames == 0
