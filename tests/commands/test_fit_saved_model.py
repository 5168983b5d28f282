"""`fit --model-file final_model.json`: the model named by `diagnose` is refitted by `fit`."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from i2ris_calib.cli import main


@pytest.mark.slow  # ~17 s: a diagnose then a fit; fit --model-file on the default run: test_diagnose_command.py
def test_diagnosed_model_is_refitted_and_beats_plain_egpi(tmp_path):
    from i2ris_calib.diagnosis.synthetic import make_case

    case = make_case(5, "time_delay", {"tau_s": 0.2}, noise_deg=0.1)
    s = case.signals
    csv = tmp_path / "synced.csv"
    pd.DataFrame(
        {"time_s": s.t_s, "enc_yaw": s.v, "enc_pitch": s.v_other, "yaw_deg": case.theta_deg,
         "pitch_deg": s.theta_other_deg}
    ).to_csv(csv, index=False)  # fmt: skip
    cfg = tmp_path / "cfg.toml"
    cfg.write_text('[diagnose]\nmax_steps = 1\ncandidates = ["time_delay", "dead_zone"]\n')
    assert (
        main(["diagnose", str(csv), "--axis", "yaw", "--out", str(tmp_path / "d"), "-c", str(cfg)])
        == 0
    )
    model_file = tmp_path / "d" / "final_model.json"
    assert json.loads(model_file.read_text())["effects"][0]["name"] == "time_delay"

    out = tmp_path / "fit"
    rc = main(
        ["fit", str(csv), "--axis", "yaw", "--model-file", str(model_file), "--out", str(out)]
    )
    assert rc == 0
    doc = json.loads((out / "fit.json").read_text())
    diag, egpi = doc["models"]["diagnosed"], doc["models"]["egpi"]
    assert abs(diag["params"]["time_delay.tau_s"] - 0.2) < 0.03
    # the delay is what plain EGPI misses: with it, held-out error comes down to the noise
    assert diag["holdout_metrics"]["rmse_deg"] < 2.0 * case.noise_deg
    assert egpi["holdout_metrics"]["rmse_deg"] > 2 * diag["holdout_metrics"]["rmse_deg"]
    pred = pd.read_csv(out / "predictions.csv")
    assert np.isfinite(pred["diagnosed_deg"]).all()
    assert str(model_file) in doc["provenance"]["inputs"]


def test_bad_model_file_is_one_line_error(tmp_path, capsys):
    csv = tmp_path / "s.csv"
    t = np.arange(200) / 30
    v = np.round(3000 * np.abs(np.sin(t)))
    pd.DataFrame(
        {"time_s": t, "enc_yaw": v, "enc_pitch": 0, "yaw_deg": v / 100, "pitch_deg": 0}
    ).to_csv(csv, index=False)
    bad = tmp_path / "m.json"
    bad.write_text('{"schema": "nope"}')
    assert (
        main(
            [
                "fit",
                str(csv),
                "--axis",
                "yaw",
                "--model-file",
                str(bad),
                "--out",
                str(tmp_path / "o"),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "m.json" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


def test_model_file_of_the_other_axis_is_refused(tmp_path, capsys):
    """final_model.json records the axis it was diagnosed on: a pitch± model is not
    refitted on yaw as "diagnosed"."""
    from i2ris_calib.hysteresis.codec import model_to_dict
    from i2ris_calib.hysteresis.registry import model_for_kind

    csv = tmp_path / "s.csv"
    t = np.arange(400) / 30
    v = np.round(3000 * np.sin(t / 2))
    pd.DataFrame(
        {"time_s": t, "enc_yaw": v, "enc_pitch": 0, "yaw_deg": v / 100, "pitch_deg": 0}
    ).to_csv(csv, index=False)
    rec = model_to_dict(model_for_kind("agpi"))
    rec.update(axis="pitch", dataset="pitch±", direction="±", abs_input=False)
    mf = tmp_path / "final_model.json"
    mf.write_text(json.dumps(rec))
    out = tmp_path / "o"
    rc = main(["fit", str(csv), "--axis", "yaw", "--model-file", str(mf), "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and err.startswith("error:") and "\n" not in err
    assert "pitch±" in err and "--axis yaw" in err and "final_model.json" in err
    assert not out.exists()
