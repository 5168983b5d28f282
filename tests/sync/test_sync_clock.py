"""Clock model, weighted line through local offsets, encoder-log validation."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from i2ris_calib.errors import CalibError
from i2ris_calib.sync.clock import ClockModel, clock_from_offsets, clock_model
from i2ris_calib.sync.estimate import combine_clocks, largest_clock_sd
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


def _clk(o, sd_o, d, sd_d, method="event"):
    fitted = np.isfinite(sd_d)
    cov = np.diag([sd_o**2, sd_d**2 if fitted else 0.0])
    return clock_model(o, d, cov, method, {"t_ref_cam_s": 0.0}, bool(fitted))


def test_auto_combination_is_the_product_of_likelihoods():
    """Event (0.500 s +- 2 ms, 100 +- 50 ppm) x model (0.503 s +- 1 ms, 80 +- 10 ppm):
    precision-weighted means, variances 1 / (sum of precisions)."""

    clk, info = combine_clocks(_clk(0.5, 2e-3, 100, 50), _clk(0.503, 1e-3, 80, 10, "model"), 0.0)
    assert clk.method == "event+model" and info["reason"] == "combined"
    w_e, w_m = 1 / 2e-3**2, 1 / 1e-3**2
    assert clk.offset_s == pytest.approx((w_e * 0.5 + w_m * 0.503) / (w_e + w_m), abs=1e-12)
    assert clk.offset_stderr_s == pytest.approx((w_e + w_m) ** -0.5, rel=1e-9)
    wd_e, wd_m = 1 / 50**2, 1 / 10**2
    assert clk.drift_ppm == pytest.approx((wd_e * 100 + wd_m * 80) / (wd_e + wd_m), rel=1e-9)
    assert clk.drift_stderr_ppm == pytest.approx((wd_e + wd_m) ** -0.5, rel=1e-9)
    # an event without drift: the drift is the model's alone
    clk, _ = combine_clocks(_clk(0.5, 2e-3, 0, np.nan), _clk(0.503, 1e-3, 80, 10, "model"), 0.0)
    assert clk.drift_ppm == pytest.approx(80) and clk.drift_stderr_ppm == pytest.approx(10)


def test_auto_keeps_the_event_when_the_model_disagrees_or_is_flat():
    event = _clk(0.5, 1e-3, 100, 50)
    clk, info = combine_clocks(event, _clk(0.505, 1e-3, 80, 10, "model"), 0.0)  # 3.5 sd apart
    assert (
        clk is None
        and info["z"] == pytest.approx(5e-3 / np.sqrt(2e-6))
        and "sd from" in info["reason"]
    )
    clk, info = combine_clocks(event, _clk(0.5005, np.nan, 80, 10, "model"), 0.0)
    assert clk is None and "no usable curvature" in info["reason"]


def test_largest_clock_sd_is_at_the_ends_when_the_drift_is_uncertain():
    """offset sd 0.1 ms at t = 30 s, drift sd 20 ppm: 0.1 ms in the middle of a 0-60 s
    recording but sqrt(0.1^2 + 0.6^2) = 0.61 ms at both ends (what auto compares with
    auto_refine_stderr_s)."""
    t_c, s_o, s_d = 30.0, 1e-4, 20.0
    j = np.array([[1.0, -t_c * 1e-6], [0.0, 1.0]])  # (offset at t_c, drift) -> (offset at 0, drift)
    cov = j @ np.diag([s_o**2, s_d**2]) @ j.T
    clk = clock_model(1.0 - 50e-6 * t_c, 50.0, cov, "event", {}, True)
    t = np.linspace(0.0, 60.0, 1801)
    assert clk.offset_stderr_at(t_c) == pytest.approx(s_o, rel=1e-6)
    assert largest_clock_sd(clk, t) == pytest.approx(np.hypot(s_o, 30 * s_d * 1e-6), rel=1e-6)
    flat = clock_model(1.0, 0.0, np.diag([s_o**2, 0.0]), "event", {}, False)
    assert largest_clock_sd(flat, t) == pytest.approx(s_o)
