"""Sync's model method holds each block's fitted start state when the clock moves: a
recording that starts mid-loop (both motors moving at the first frame) keeps its
pre-history at every candidate offset and drift instead of dropping back to rest."""

from __future__ import annotations

import numpy as np
import pytest
from two_motor_log import series_and_log

from i2ris_calib.fitting.config import FitConfig
from i2ris_calib.simulation.two_motor import simulate_two_motor
from i2ris_calib.sync.joint import (
    OffsetProfile,
    drift_gauss_newton,
    held_output,
    held_state_fit,
    model_blocks,
    profile_fit_config,
    trimmed_ss,
)

OFFSET_S = 3.0


@pytest.fixture(scope="module")
def profile_at_truth():
    """A mid-loop two-motor recording (30 Hz, 0.05 deg noise) on an exact clock (offset
    3 s, no drift) and its profile evaluated at the true offset."""
    rec = simulate_two_motor(2, n_samples=600, rate_hz=30.0, noise_deg=0.05)
    series, log = series_and_log(rec, OFFSET_S)
    t_c = float(rec.t_s.mean())
    cfg = profile_fit_config(FitConfig())
    blocks = model_blocks(series, log, OFFSET_S, t_c, 0.05, cfg, 50.0)
    profile = OffsetProfile(blocks, log, t_c, 0.0, "egpi", cfg)
    profile(OFFSET_S)
    return profile


def test_the_recording_starts_mid_loop(profile_at_truth):
    fits = profile_at_truth.fits(OFFSET_S)
    assert all(f.initial_state is not None for f in fits)


def test_held_output_is_the_fit_on_its_own_input_and_keeps_the_state_when_shifted(
    profile_at_truth,
):
    p = profile_at_truth
    for b, f in zip(p.blocks, p.fits(OFFSET_S), strict=True):
        v = p.inputs(b, OFFSET_S)
        np.testing.assert_allclose(held_output(f, v), f.predict(v), atol=1e-12)
        # 0.1 ms later the input moves by a fraction of a count: so does the output
        # (0.05 deg bound: the opening transient from rest is degrees)
        shifted = p.inputs(b, OFFSET_S + 1e-4)
        assert np.max(np.abs(held_output(f, shifted) - held_output(f, v))) < 0.05


def test_held_state_refit_is_no_worse_than_its_start(profile_at_truth):
    p = profile_at_truth
    cfg = p.fit_config
    for b, f in zip(p.blocks, p.fits(OFFSET_S), strict=True):
        v = p.inputs(b, OFFSET_S + 2e-3)
        start = trimmed_ss(held_output(f, v) - b.theta_deg)
        refit = held_state_fit(f, v, b.theta_deg, cfg)
        held, st = refit.initial_state, f.initial_state
        # the same levels (clipped to the shifted input's bounds, within 0.01 % of the
        # range), the pre-history now ending at the shifted input's first value
        assert held.v_from == pytest.approx(st.v_from, abs=1.0)
        assert held.other_v_from == pytest.approx(st.other_v_from, abs=1.0)
        assert held.v0 == pytest.approx(float(v.v[0]))
        assert trimmed_ss(refit.residuals) <= start * (1 + 1e-9)


def test_drift_step_from_the_truth_stays_at_the_truth(profile_at_truth):
    """The Gauss-Newton drift step with the models held, from the true clock: within
    3 of its sd (and 30 ppm) of the true drift 0. With the start state dropped at the
    shifted clocks (FitResult.predict's default) the opening transient was read as the
    clock's sensitivity (on the rendered lab session: 68 -> -121 ppm, true 80)."""
    offset, drift, cov = drift_gauss_newton(profile_at_truth, OFFSET_S, 0.0)
    sd_drift = float(np.sqrt(cov[1, 1]))
    assert abs(drift) < max(3 * sd_drift, 30.0) and abs(drift) < 100.0
    assert abs(offset - OFFSET_S) < 2e-3
