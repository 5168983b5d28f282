"""`i2ris-calib diagnose`: outputs on a synced CSV with a hidden delay; bad input."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from i2ris_calib.cli import main


def _synced_csv(path, effect="time_delay", params=None, seed=3):
    from i2ris_calib.diagnosis.synthetic import make_case

    case = make_case(seed, effect, params or {"tau_s": 0.2}, noise_deg=0.15)
    s = case.signals
    df = pd.DataFrame(
        {
            "time_s": s.t_s,
            "enc_yaw": s.v,
            "enc_pitch": s.v_other,
            "yaw_deg": case.theta_deg,
            "pitch_deg": s.theta_other_deg,
            "status": "measured",
            "frame": np.arange(s.v.size),
        }
    )
    df.loc[::40, "status"] = "not_found"
    df.loc[::40, ["yaw_deg", "pitch_deg"]] = np.nan
    df.to_csv(path, index=False)
    return case


@pytest.fixture(scope="module")
def diagnosed(tmp_path_factory):
    root = tmp_path_factory.mktemp("diag")
    csv = root / "synced.csv"
    case = _synced_csv(csv)
    cfg = root / "cfg.toml"
    cfg.write_text('[diagnose]\nmax_steps = 2\ncandidates = ["time_delay", "creep", "dead_zone"]\n')
    out = root / "out"
    rc = main(["diagnose", str(csv), "--axis", "yaw", "--out", str(out), "--config", str(cfg)])
    return rc, out, case, csv


def test_outputs_are_complete_and_name_the_delay(diagnosed):
    rc, out, case, _ = diagnosed
    assert rc == 0
    rec = json.loads((out / "diagnosis.json").read_text())
    assert rec["schema"] == "i2ris-calib.diagnosis/1" and rec["axis"] == "yaw"
    assert rec["named_effects"] == ["time_delay"]
    assert rec["final"]["holdout_rmse_deg"] < 1.3 * case.noise_deg
    assert rec["baseline"]["holdout_rmse_deg"] > 2 * rec["final"]["holdout_rmse_deg"]
    step = rec["steps"][0]
    assert abs(step["params"]["tau_s"] - 0.2) < 0.03
    assert step["holdout_rmse_after_deg"] < step["holdout_rmse_before_deg"]
    assert step["delta_bic"] < -10 and step["evidence"]["significant"]
    for name in rec["figures"]:
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert step["figures"] == {"before": rec["figures"][0], "after": rec["figures"][1]}
    md = (out / "diagnosis.md").read_text()
    assert md.startswith("## Model diagnosis (yaw)") and "time_delay" in md
    assert "inputs" in rec["provenance"]
    assert not [p for p in out.parent.iterdir() if p.name.startswith(".")]


def test_final_model_file_rebuilds_the_fitted_model(diagnosed):
    from i2ris_calib.diagnosis.effects import model_values
    from i2ris_calib.diagnosis.serialize import model_from_dict
    from i2ris_calib.io.diagnose import read_synced

    _, out, _, csv = diagnosed
    obj = json.loads((out / "final_model.json").read_text())
    model = model_from_dict(obj)
    assert [e["name"] for e in obj["effects"]] == ["time_delay"]
    assert [p.name for p in model.parameters] == list(obj["params"])
    sig, theta, _ = read_synced(csv, "yaw")
    y = model.evaluate(sig, model_values(model))
    ok = np.isfinite(theta)
    rmse = float(np.sqrt(np.mean((y[ok] - theta[ok]) ** 2)))
    assert rmse < 0.25  # noise 0.15 deg


def _run_error(capsys, args):
    rc = main(["diagnose", *args])
    err = capsys.readouterr().err.strip()
    return rc, err


@pytest.mark.parametrize(
    "mutate, needle",
    [
        (lambda df: df.drop(columns=["yaw_deg"]), "missing column(s) yaw_deg"),
        (lambda df: df.iloc[::-1], "must increase"),
        (
            lambda df: df.assign(enc_yaw=df["enc_yaw"].astype(object).where(df.index != 5, "x")),
            "non-numeric",
        ),
        (lambda df: df.iloc[:5], "only 5 rows"),
    ],
)
def test_bad_csv_is_a_one_line_error(tmp_path, capsys, mutate, needle):
    csv = tmp_path / "s.csv"
    t = np.arange(0, 10, 0.1)
    df = pd.DataFrame(
        {"time_s": t, "enc_yaw": 100 * t, "enc_pitch": 0.0, "yaw_deg": t, "pitch_deg": 0.0}
    )
    mutate(df).to_csv(csv, index=False)
    out = tmp_path / "out"
    rc, err = _run_error(capsys, [str(csv), "--axis", "yaw", "--out", str(out)])
    assert rc == 2 and err.startswith("error:") and needle in err and "\n" not in err
    assert not out.exists()


@pytest.mark.parametrize(
    "args, needle",
    [
        (["--axis", "roll"], "--axis must be yaw or pitch"),
        (["--axis", "yaw", "--start", "pi"], "--start must be gpi or egpi"),
    ],
)
def test_bad_options_are_one_line_errors(tmp_path, capsys, args, needle):
    csv = tmp_path / "s.csv"
    t = np.arange(0, 10, 0.1)
    pd.DataFrame({"time_s": t, "enc_yaw": 100 * t, "yaw_deg": t}).to_csv(csv, index=False)
    rc, err = _run_error(capsys, [str(csv), *args, "--out", str(tmp_path / "o")])
    assert rc == 2 and needle in err


def test_missing_file_is_a_one_line_error(tmp_path, capsys):
    rc, err = _run_error(capsys, [str(tmp_path / "nope.csv"), "--axis", "yaw"])
    assert rc == 2 and "not found" in err


def test_bad_model_file_is_a_calib_error():
    from i2ris_calib.diagnosis.serialize import model_from_dict
    from i2ris_calib.errors import CalibError

    with pytest.raises(CalibError, match="schema"):
        model_from_dict({"schema": "other"})
    with pytest.raises(CalibError, match="base"):
        model_from_dict({"schema": "i2ris-calib.model/1", "base": {"kind": "egpi"}})
    with pytest.raises(CalibError, match="unknown effect"):
        model_from_dict(
            {
                "schema": "i2ris-calib.model/1",
                "base": {"kind": "gpi", "params": {}},
                "effects": [{"name": "wobble", "params": {}}],
            }
        )


def test_read_synced_selects_one_direction(tmp_path):
    from i2ris_calib.io.diagnose import read_synced

    t = np.arange(0, 30, 0.1)
    enc = np.where(t < 10, 300 * t, np.where(t < 20, -200 * (t - 10), 0.0))  # +, -, rest
    csv = tmp_path / "s.csv"
    pd.DataFrame({"time_s": t, "enc_yaw": enc, "yaw_deg": 0.01 * enc, "status": "measured"}).to_csv(
        csv, index=False
    )
    sig, theta, neg = read_synced(csv, "yaw", "-")
    assert neg and np.all(sig.v >= 0) and np.all(theta[np.isfinite(theta)] >= 0)
    assert sig.v.size == int((enc < 5).sum())  # negative excursion and the rests
    np.testing.assert_allclose(theta, 0.01 * sig.v)
    sig, _, neg = read_synced(csv, "yaw", "auto")
    assert not neg and sig.v.max() == enc.max()  # more samples on the + side


def test_bad_direction_is_a_one_line_error(tmp_path, capsys):
    csv = tmp_path / "s.csv"
    t = np.arange(0, 10, 0.1)
    pd.DataFrame({"time_s": t, "enc_yaw": 100 * t, "yaw_deg": t}).to_csv(csv, index=False)
    rc, err = _run_error(capsys, [str(csv), "--axis", "yaw", "--direction", "up"])
    assert rc == 2 and "--direction must be" in err
