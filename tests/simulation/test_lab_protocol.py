"""protocol = "lab": both motors through zero, mid-loop start, the two-motor truth."""

from __future__ import annotations

import numpy as np
import pytest

from i2ris_calib.errors import CalibError
from i2ris_calib.simulation import trajectory as tj
from i2ris_calib.simulation.lab import lab_drive, reference_window
from i2ris_calib.simulation.presets import preset_config
from i2ris_calib.simulation.truth import session_truth, truth_at
from i2ris_calib.simulation.two_motor import two_motor_angles


@pytest.fixture(scope="module")
def lab():
    cfg = preset_config("lab_ci")
    return cfg, session_truth(cfg)


def test_truth_is_the_two_motor_truth_and_deterministic(lab):
    cfg, tr = lab
    yaw, pitch = two_motor_angles(tr.params, tr.enc_yaw, tr.enc_pitch)
    assert np.array_equal(yaw, tr.yaw_deg) and np.array_equal(pitch, tr.pitch_deg)
    assert tr.params["yaw"]["theta0"] == -9.0 and tr.params["pitch"]["theta0"] == 4.0
    again = session_truth(preset_config("lab_ci"))
    assert np.array_equal(again.enc_pitch, tr.enc_pitch)
    other = session_truth(preset_config("lab_ci", seed=1))
    assert not np.array_equal(other.enc_yaw[: tr.enc_yaw.size], tr.enc_yaw[: other.enc_yaw.size])


def test_both_motors_through_zero_starting_mid_loop(lab):
    cfg, tr = lab
    t = np.arange(-tj.LEAD_S, tj.motion_duration_s(cfg) + tj.LEAD_S, 1 / 30.0)
    ey, ep = tj.session_inputs(cfg, t)
    for e, amp in ((ey, cfg.amplitude_counts[0]), (ep, cfg.amplitude_counts[1])):
        assert e.max() > 0.3 * amp and e.min() < -0.3 * amp  # through zero, both tendons
        assert np.count_nonzero(np.diff(np.sign(e[np.abs(e) > 50])))
    assert abs(ey[0]) > 100 or abs(ep[0]) > 100  # the recording does not start at rest
    assert np.any(np.diff(ey[:5]) != 0) or np.any(np.diff(ep[:5]) != 0)  # ... but moving
    moving = (np.abs(np.diff(ey)) > 0) & (np.abs(np.diff(ep)) > 0)
    assert moving.mean() > 0.6  # both motors at once
    assert tj.session_blocks(cfg) == [] and tj.video_duration_s(cfg) == cfg.lab_duration_s


def test_the_tip_is_straight_in_the_tracking_reference_window(lab):
    cfg, tr = lab
    start, duration = reference_window(cfg)
    tq = np.linspace(start, start + duration, 50) - tj.LEAD_S  # motion time of video time
    yaw, pitch = truth_at(cfg, tr, tq)
    assert np.abs(yaw).max() < 0.01 and np.abs(pitch).max() < 0.01
    d = lab_drive(cfg)
    s0, s1 = d.straight_s
    assert s0 <= tq[0] and tq[-1] <= s1


def test_truth_at_is_exact_between_grid_points(lab):
    cfg, tr = lab
    tq = np.arange(-1.0, 20.0, 1 / 30.0) + 4.37e-4
    yaw, pitch = truth_at(cfg, tr, tq)
    # the 1 kHz grid's linear interpolation differs only next to a play operator's kink
    for got, grid in ((yaw, tr.yaw_deg), (pitch, tr.pitch_deg)):
        diff = np.abs(got - np.interp(tq, tr.t_s, grid))
        assert diff.max() < 0.05 and np.median(diff) < 1e-3


@pytest.mark.parametrize(
    "bad",
    [dict(protocol="lab2"), dict(lab_offset_deg=(-30.0, 0.0)), dict(lab_coupling=-0.1),
     dict(lab_period_s=(8.0, 4.0)), dict(lab_duration_s=5.0), dict(lab_reference_s=28.0)],
)  # fmt: skip
def test_bad_lab_settings_are_one_line_errors(bad):
    with pytest.raises((CalibError, ValueError)) as exc:
        preset_config("lab_ci", **bad)
    assert "\n" not in str(exc.value)
