"""diagnose on both motors at once (issue 20 item 2): coupling named, or not separable."""

from __future__ import annotations

import pytest

from i2ris_calib.data.dataset import direction_datasets
from i2ris_calib.diagnosis.config import DiagnosisConfig
from i2ris_calib.diagnosis.workflow import diagnose_from_starts
from i2ris_calib.simulation.two_motor import simulate_two_motor

#: Two candidates keep the test fast; the benchmark runs the whole catalogue
CONFIG = DiagnosisConfig(candidates=("axis_coupling", "time_delay"), max_steps=1)


def pitch_dataset(rec):
    (d,) = direction_datasets(
        "pitch", rec.t_s, rec.enc_pitch, rec.pitch_deg, enc_other=rec.enc_yaw,
        theta_other_deg=rec.yaw_deg, signed=True,
    )  # fmt: skip
    return d


def test_diagnose_names_coupling_when_both_motors_move_and_starts_from_agpi():
    rec = simulate_two_motor(21, n_samples=900, rate_hz=30.0, noise_deg=0.25, coupling=0.6)
    auto = diagnose_from_starts(pitch_dataset(rec), CONFIG)
    assert auto.start == "agpi"  # the signed dataset's starting model
    assert "axis_coupling" in auto.diagnosis.named_effects
    assert any(n.startswith("coupling to the yaw motor") for n in auto.diagnosis.notes)


# ~9 s: slow (the default run's 5-minute budget); the coupling named when both motors
# move stays on the default run (above)
@pytest.mark.slow
def test_diagnose_says_lockstep_motors_cannot_separate_coupling():
    rec = simulate_two_motor(22, n_samples=900, rate_hz=30.0, coupling=0.6, lockstep=0.7)
    auto = diagnose_from_starts(pitch_dataset(rec), CONFIG)
    assert "axis_coupling" not in auto.diagnosis.named_effects
    (note,) = [n for n in auto.diagnosis.notes if n.startswith("coupling cannot be separated")]
    assert "lockstep" in note
