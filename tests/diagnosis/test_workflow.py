"""The locate -> name -> add workflow on synthetic data with known hidden effects.

Each case: EGPI truth (paper-like yaw+) + one hidden effect + white noise; the
diagnosis starts from an EGPI fitted by the fitting stage. A test fails if the
wrong effect is named, if anything is named on clean data, or if the held-out
error does not fall to near the noise level.
"""

from __future__ import annotations

import numpy as np
import pytest

from i2ris_calib.diagnosis.config import DiagnosisConfig
from i2ris_calib.diagnosis.synthetic import STRENGTHS, make_case
from i2ris_calib.diagnosis.workflow import diagnose, fit_start_model


def _run(seed, effect, params=None, noise=0.2, **cfg):
    case = make_case(seed, effect, params, noise_deg=noise)
    config = DiagnosisConfig(**cfg)
    start = fit_start_model("egpi", case.signals, case.theta_deg, config)
    return case, diagnose(start, case.signals, case.theta_deg, config)


@pytest.mark.parametrize("effect", ["time_delay", "axis_coupling", "saturation"])
def test_hidden_effect_is_named_and_gap_closes(effect):
    case, d = _run(11, effect, max_steps=2)
    assert d.named_effects == [effect]
    # held-out RMSE down to the noise level (0.2 deg) within 25 %
    assert d.final.holdout_rmse_deg < 1.25 * case.noise_deg
    assert d.baseline.holdout_rmse_deg > 1.5 * d.final.holdout_rmse_deg
    step = d.steps[0]
    assert step.comparison.significant and step.comparison.p_value < 0.01
    assert step.comparison.delta_bic < -10


def test_clean_data_names_nothing():
    case, d = _run(12, None, max_steps=1)
    assert d.named_effects == []
    assert d.final == d.baseline
    assert all(not c.comparison.significant for c in d.last_candidates if c.comparison)


def test_recovered_delay_is_close_to_truth():
    case, d = _run(13, "time_delay", {"tau_s": 0.2}, noise=0.1, max_steps=1)
    tau = d.final_model.values[0]
    assert d.named_effects == ["time_delay"]
    assert abs(tau - 0.2) < 0.02  # one sample at 30 Hz is 0.033 s


@pytest.mark.slow
@pytest.mark.parametrize(
    "effect", ["multi_stage_backlash", "rate_dependence", "creep", "dead_zone"]
)
def test_hidden_effect_is_named_slow(effect):
    case, d = _run(21, effect, STRENGTHS[effect][2], noise=0.15, max_steps=2)
    assert d.named_effects[:1] == [effect]
    assert d.final.holdout_rmse_deg < 1.3 * case.noise_deg


@pytest.mark.slow
@pytest.mark.parametrize("seed", [31, 32, 33])
def test_clean_data_names_nothing_slow(seed):
    _, d = _run(seed, None, noise=0.3)
    assert d.named_effects == []


def test_candidate_subset_and_skips():
    """An effect that lacks its signals is skipped, not fitted."""
    from dataclasses import replace

    case = make_case(14, "time_delay", noise_deg=0.2)
    sig = replace(case.signals, v_other=None, theta_other_deg=None)
    config = DiagnosisConfig(candidates=("axis_coupling", "time_delay"), max_steps=1)
    start = fit_start_model("egpi", sig, case.theta_deg, config)
    d = diagnose(start, sig, case.theta_deg, config)
    assert d.named_effects == ["time_delay"]
    skipped = [c for c in d.steps[0].candidates if c.skipped]
    assert [c.effect for c in skipped] == ["axis_coupling"]


def test_too_little_data_is_a_calib_error(egpi):
    from i2ris_calib.errors import CalibError
    from i2ris_calib.hysteresis.model import Signals

    t = np.arange(0, 2, 0.1)
    with pytest.raises(CalibError, match="too few"):
        diagnose(egpi, Signals(v=100 * t, t_s=t), np.zeros(t.size))
