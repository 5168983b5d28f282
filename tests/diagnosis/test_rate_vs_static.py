"""Issue 20 item 6: on a recording whose input speed is a function of its level (one
frequency), a rate effect and a static shape cannot be told apart: neither is named,
both are listed with the separating recording."""

from __future__ import annotations

import numpy as np
import pytest

from i2ris_calib.data.dataset import input_bands, make_dataset
from i2ris_calib.diagnosis.config import DiagnosisConfig
from i2ris_calib.diagnosis.stats import (
    SPEED_EXPERIMENT,
    speed_follows_level,
    speed_level_spread,
)
from i2ris_calib.diagnosis.synthetic import make_case
from i2ris_calib.diagnosis.workflow import diagnose, fit_start_model
from i2ris_calib.hysteresis.effects import build_model, model_values
from i2ris_calib.hysteresis.models import i2ris_egpi_model
from i2ris_calib.hysteresis.presets import paper_like_params
from i2ris_calib.model import Signals


def _sine(seed=0, n_periods=10, hz=0.2, rate_hz=30.0, noise=0.2):
    """(signals, theta) of a one-frequency sine 0..6000 counts through an EGPI with
    rate-dependent thresholds."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, n_periods / hz, 1.0 / rate_hz)
    v = np.round(3000.0 - 3000.0 * np.cos(2 * np.pi * hz * t))
    truth = build_model(
        i2ris_egpi_model(**paper_like_params("yaw+")),
        {"rate_dependent_thresholds": {"beta_s": 0.3}},
    )
    sig = Signals(v=v, t_s=t)
    theta = truth.evaluate(sig, model_values(truth)) + rng.normal(0.0, noise, t.size)
    return sig, theta


def test_speed_as_a_function_of_level_is_detected():
    """One-frequency sine: one speed per level (spread ~0); the diagnosis cases'
    ramps at three speeds: not."""
    sig, theta = _sine()
    mask = np.ones(sig.v.size, bool)
    assert speed_level_spread(sig, mask) < 0.12
    assert speed_follows_level(sig, mask)
    case = make_case(1, None, n_cycles=6)
    assert speed_level_spread(case.signals, np.ones(case.signals.v.size, bool)) > 0.3
    assert not speed_follows_level(case.signals, np.ones(case.signals.v.size, bool))
    assert np.isnan(speed_level_spread(Signals(v=sig.v), mask))


# ~6 s: slow (the default run's 5-minute budget)
@pytest.mark.slow
def test_one_frequency_sine_names_no_rate_effect_and_lists_both():
    """A sine through an EGPI with rate-dependent thresholds: the static shape fits
    it as well, so no rate effect is named; the note lists both and the separating
    recording, and the rate candidate is listed as not excluded with it."""
    sig, theta = _sine()
    data = make_dataset("yaw", "+", sig.t_s, sig.v, theta, bands=input_bands(sig.v), source="sine")
    cfg = DiagnosisConfig(candidates=("rate_dependent_thresholds", "saturation"), max_steps=2)
    diag = diagnose(fit_start_model("egpi", data), data, cfg)
    assert not set(diag.named_effects) & {"rate_dependent_thresholds", "rate_dependent_weights"}
    note = " ".join(diag.notes)
    assert "not separable" in note
    assert "static" in note and "rate_dependent_thresholds" in note
    assert SPEED_EXPERIMENT in note
    listed = {a.effect: a for a in diag.not_excluded}
    assert listed["rate_dependent_thresholds"].experiment == SPEED_EXPERIMENT


@pytest.mark.slow  # ~14 s; the one-frequency sine on the default run: the test above
def test_one_frequency_sine_says_rate_dependence_cannot_be_tested():
    """A static EGPI driven by a one-frequency sine: no rate effect fits better, and the
    diagnosis still says the recording could not have shown one, with the recording
    that would."""
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 50.0, 1.0 / 30.0)
    v = np.round(3000.0 - 3000.0 * np.cos(2 * np.pi * 0.2 * t))
    truth = i2ris_egpi_model(**paper_like_params("yaw+"))
    sig = Signals(v=v, t_s=t)
    theta = truth.evaluate(sig, model_values(truth)) + rng.normal(0.0, 0.2, t.size)
    data = make_dataset("yaw", "+", t, v, theta, bands=input_bands(v), source="sine")
    cfg = DiagnosisConfig(candidates=("rate_dependent_thresholds",), max_steps=1)
    diag = diagnose(fit_start_model("egpi", data), data, cfg)
    assert list(diag.named_effects) == []
    (note,) = [n for n in diag.notes if "rate dependence cannot be tested" in n]
    assert "static" in note and note.endswith(SPEED_EXPERIMENT)
