"""The default fit of an axis driven through zero: the two-tendon GPI on the signed input."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from through_zero import yaw_recording

from i2ris_calib.cli import main
from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.config import FitConfig
from i2ris_calib.fitting.pipeline import choose_model
from i2ris_calib.hysteresis.presets import random_two_tendon_params, through_zero_trajectory
from i2ris_calib.hysteresis.registry import SIGNED_KINDS, model_for_kind

NOISE = 0.25  # deg


def lab_frame(seed: int, n: int = 3000, rate_hz: float = 30.0):
    """A two-tendon axis (different gains per side, offset -9 deg) driven through zero by
    loops of varying amplitude, the recording starting mid-loop; noise 0.25 deg.
    Returns (synced frame, true angle)."""
    rng = np.random.default_rng(seed)
    truth = random_two_tendon_params(rng, offset_deg=-9.0)
    t, v, start = through_zero_trajectory(rng, n, rate_hz)
    y = model_for_kind("agpi").with_values(truth)(v)[start:]
    v, t = v[start:], t[start:]
    frame = yaw_recording(rng, t, v, y, NOISE)
    return frame, y


@pytest.mark.parametrize(
    ("seed", "rate_hz", "n"),
    [pytest.param(11, 30.0, 3000, marks=pytest.mark.slow), (12, 5.0, 400)],  # 3000: ~8 s
)
def test_default_fit_through_zero_is_the_two_tendon_model_at_the_noise(tmp_path, seed, rate_hz, n):
    frame, truth = lab_frame(seed, n, rate_hz)
    frame.to_csv(tmp_path / "s.csv", index=False)
    assert (
        main(["fit", str(tmp_path / "s.csv"), "--axis", "yaw", "--out", str(tmp_path / "o")]) == 0
    )
    doc = json.loads((tmp_path / "o" / "fit.json").read_text())
    assert doc["model_choice"]["input"] == "signed"
    assert doc["model_choice"]["line"].startswith("model: two-tendon GPI over the signed input")
    assert "crosses zero" in doc["model_choice"]["why"]
    (d,) = doc["datasets"]
    assert d["direction"] == "±" and set(d["models"]) == set(SIGNED_KINDS)
    held = {k: rec["holdout_metrics"]["rmse_deg"] for k, rec in d["models"].items()}
    assert doc["model_choice"]["main"] == "agpi" and doc["model_choice"]["picked_after_fit"]
    picked = f"picked after fitting: agpi: held-out {held['agpi']:.3g} deg vs "
    assert picked in doc["model_choice"]["why"]
    assert f"gpi {held['gpi']:.3g} deg" in doc["model_choice"]["why"]
    assert d["models"]["agpi"]["holdout_metrics"]["rmse_deg"] <= 1.2 * NOISE
    pred = pd.read_csv(tmp_path / "o" / "predictions.csv")["agpi_deg"].to_numpy()
    assert np.abs(np.diff(pred)).max() <= np.abs(np.diff(truth)).max() + 3 * NOISE


def test_split_forces_the_paper_models_and_signed_only_kinds_refuse_it(tmp_path):
    frame, _ = lab_frame(13, 1500)
    frame.to_csv(tmp_path / "s.csv", index=False)
    args = ["fit", str(tmp_path / "s.csv"), "--axis", "yaw", "--model", "gpi", "--split"]
    assert main([*args, "--out", str(tmp_path / "o")]) == 0
    doc = json.loads((tmp_path / "o" / "fit.json").read_text())
    assert doc["model_choice"]["input"] == "split"
    assert doc["model_choice"]["why"].startswith("--split; the recording: the input crosses zero")
    assert [d["name"] for d in doc["datasets"]] == ["yaw+", "yaw-"]
    with pytest.raises(CalibError, match="--model agpi is fitted on the signed input"):
        choose_model(None, FitConfig(split=True), "agpi")
    assert choose_model(None, FitConfig(signed=True)).kinds == SIGNED_KINDS
    assert choose_model(None, FitConfig(), "egpi").kinds == ("egpi",)


def test_paper_protocol_keeps_the_paper_split_by_default(tmp_path):
    """Excursions from rest at zero, one direction at a time: the per-direction split."""
    from i2ris_calib.commands.fit import datasets_for_fit
    from i2ris_calib.hysteresis.presets import loading_trajectory

    rng = np.random.default_rng(2)
    t1, v1 = loading_trajectory(rng, 4, n_samples=1500)
    t2, v2 = loading_trajectory(rng, 4, n_samples=1500, start_s=t1[-1] + 1.0)
    enc = np.concatenate([v1, -v2])
    frame = pd.DataFrame(
        {
            "time_s": np.concatenate([t1, t2]),
            "enc_yaw": enc,
            "enc_pitch": 0.0,
            "yaw_deg": 0.006 * enc + rng.normal(0, NOISE, enc.size),
            "pitch_deg": 0.0,
            "status": "measured",
            "frame": np.arange(enc.size),
        }
    )
    frame.to_csv(tmp_path / "s.csv", index=False)
    datasets, choice = datasets_for_fit([tmp_path / "s.csv"], "yaw", FitConfig())
    assert not choice.signed and choice.kinds == ("gpi", "egpi", "egpi_c")
    assert [d.name for d in datasets] == ["yaw+", "yaw-"]
    assert "starts at rest at zero" in choice.line
