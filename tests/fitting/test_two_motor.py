"""Both motors at once (issue 20 item 2): the default fit models coupling to the other motor."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from i2ris_calib.cli import main
from i2ris_calib.data.coupling import motors_together
from i2ris_calib.fitting.pipeline import choose_model
from i2ris_calib.hysteresis.registry import SIGNED_KINDS
from i2ris_calib.simulation.two_motor import simulate_two_motor

NOISE = 0.25  # deg


def write_csv(path, rec, still_yaw: bool = False):
    cols = rec.columns()
    if still_yaw:
        cols["enc_yaw"] = np.zeros_like(cols["enc_yaw"])
    frame = pd.DataFrame(cols)
    frame["status"] = "measured"
    frame["frame"] = np.arange(len(frame))
    frame.to_csv(path, index=False)


def fit_doc(tmp_path, rec, axis="pitch", **kw):
    write_csv(tmp_path / "s.csv", rec, **kw)
    out = tmp_path / "o"
    assert main(["fit", str(tmp_path / "s.csv"), "--axis", axis, "--out", str(out)]) == 0
    return json.loads((out / "fit.json").read_text()), pd.read_csv(out / "predictions.csv")


# ~12 s: slow (the default run's 5-minute budget); the default run keeps a coupled fit at
# its optimum (agpi_coupled:2 in tests/fitting/test_optimum.py) and the coupling named
# by diagnose (tests/diagnosis/test_two_motor_coupling.py)
@pytest.mark.slow
def test_default_fit_of_pitch_following_the_yaw_motor_is_coupled_at_the_noise(tmp_path, capsys):
    rec = simulate_two_motor(5, n_samples=1500, rate_hz=30.0, noise_deg=NOISE, coupling=0.6)
    doc, pred = fit_doc(tmp_path, rec)
    choice = doc["model_choice"]
    assert choice["input"] == "signed" and choice["main"] == "agpi_coupled"
    assert choice["coupling"]["coupled"] and choice["coupling"]["other"] == "yaw"
    assert "coupling" in choice["line"] and "yaw motor moves while this one does" in choice["why"]
    assert "coupling to the other motor" in capsys.readouterr().err.replace("\n", " ")
    models = doc["models"]
    assert set(models) == {"gpi", "agpi", "agpi_coupled"}
    assert models["agpi_coupled"]["holdout_metrics"]["rmse_deg"] <= 1.2 * NOISE
    assert models["agpi"]["holdout_metrics"]["rmse_deg"] > 3 * NOISE  # the coupling is needed
    jump = np.abs(np.diff(pred["agpi_coupled_deg"].to_numpy())).max()
    assert jump <= np.abs(np.diff(rec.pitch_true_deg)).max() + 3 * NOISE


def test_other_motor_still_keeps_the_uncoupled_model(tmp_path):
    rec = simulate_two_motor(6, n_samples=900, rate_hz=30.0, noise_deg=NOISE, coupling=0.0)
    doc, _ = fit_doc(tmp_path, rec, still_yaw=True)
    assert doc["model_choice"]["main"] == "agpi"
    assert set(doc["models"]) == set(SIGNED_KINDS)  # no coupling: the one-loop kinds too
    assert "coupling" not in doc["model_choice"]["line"]


def test_lockstep_motors_cannot_separate_coupling():
    rec = simulate_two_motor(7, n_samples=900, rate_hz=30.0, coupling=0.6, lockstep=0.7)
    together = motors_together(rec.enc_pitch, rec.enc_yaw, "yaw")
    assert together.moves_together and together.cannot_separate and not together.coupled
    choice = choose_model(None, model="all", together=together)
    assert "agpi_coupled" not in choice.kinds
    # --model agpi_coupled fits coupling terms: the words say so (issue 32 item 6)
    forced = choose_model(None, model="agpi_coupled", together=together)
    assert forced.kinds == ("agpi_coupled",) and "no coupling term" not in forced.why
    assert "coupling terms fitted as --model asks" in forced.why
    free = simulate_two_motor(7, n_samples=900, rate_hz=30.0, coupling=0.6)
    assert motors_together(free.enc_pitch, free.enc_yaw, "yaw").coupled
