"""``compensate`` start state (issue 21): a conditioning sweep when the fit cannot know
the robot's state at rest, a known history, both stated in the outputs."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from i2ris_calib.cli import main
from i2ris_calib.commands.compensate import compensate_files
from i2ris_calib.compensation.inverse import forward
from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.pipeline import model_from_params
from i2ris_calib.hysteresis.presets import gpi_values, paper_like_params

RATE = 3000.0
MID_LOOP = {
    "v_from": 4000.0,
    "n_samples": 40,
    "v0": 1500.0,
    "text": "the recording starts mid-range",
}


def _fit_json(path, initial_state="absent"):
    P = paper_like_params("yaw+")
    models = {}
    for k, hold in (("gpi", 0.3), ("egpi_c", 0.1)):
        models[k] = {
            "params": gpi_values(P) if k == "gpi" else P, "n_operators": 30,
            "deadband_counts": 2.0, "metrics": {"rmse_deg": 0.1},
            "holdout_metrics": {"rmse_deg": hold},
        }  # fmt: skip
        if initial_state != "absent":
            models[k]["initial_state"] = initial_state
    doc = {
        "schema": "i2ris-calib.fit/1", "axis": "yaw",
        "datasets": [{"name": "yaw+", "input_range_counts": [0.0, 6000.0],
                      "max_input_rate_counts_per_s": RATE, "models": models}],
    }  # fmt: skip
    path.write_text(json.dumps(doc))
    return P


@pytest.fixture
def tmp(tmp_path):
    t = np.arange(0, 6, 0.02)
    pd.DataFrame({"time_s": t, "yaw_deg": 15 + 5 * np.sin(t)}).to_csv(
        tmp_path / "target.csv", index=False
    )
    return tmp_path


def _run(tmp, fit, out="c.csv", **kw):
    doc = compensate_files([tmp / fit], ["yaw+"], tmp / "target.csv", tmp / out, **kw)
    return doc["axes"]["yaw"], pd.read_csv(tmp / out)


def test_mid_loop_fit_gets_a_conditioning_sweep(tmp):
    P = _fit_json(tmp / "fit.json", MID_LOOP)
    rec, df = _run(tmp, "fit.json", model="egpi_c")
    flags = df["flags"].fillna("").astype(str)
    cond = flags == "conditioning"
    n = rec["n_conditioning"]
    assert rec["start_state"] == "conditioning_sweep" and "mid-loop" in rec["start_state_reason"]
    assert n > 0 and cond.to_numpy()[:n].all() and cond.sum() == n
    assert rec["conditioning_counts"] == [6000.0, 0.0]  # the target rises first: ends at 0
    enc = df["enc_yaw"].to_numpy()
    assert enc[:n].max() == 6000 and enc[n - 1] == 0
    # every row sent, the sweep included, within the rate limit
    steps = np.abs(np.diff(np.concatenate(([0], enc)))) / 0.02
    assert steps.max() <= RATE + 1e-9 and rec["max_command_rate_per_s"] <= RATE + 1e-9
    # conditioning and entry rows come before the target's first time; the predicted
    # angle is the model over every row from rest at the start counts (truth)
    t = df["time_s"].to_numpy()
    assert np.all(np.diff(t) > 0) and (t[~flags.str.contains("conditioning|entry")] >= 0).all()
    model = model_from_params("egpi_c", P, 30, 2.0)
    y = forward(model, enc.astype(float), None, 0.0)
    np.testing.assert_allclose(df["predicted_yaw_deg"], y, atol=1e-9)
    target = pd.read_csv(tmp / "target.csv")["yaw_deg"].to_numpy()
    on = t >= 0
    assert np.sqrt(np.mean((y[on] - target) ** 2)) < 0.3


def test_start_at_rest_when_the_fit_knows_it_and_older_files(tmp, capsys):
    _fit_json(tmp / "rest.json", None)
    _fit_json(tmp / "old.json")
    rec, df = _run(tmp, "rest.json")
    assert rec["start_state"] == "rest" and rec["n_conditioning"] == 0
    assert "started at rest" in rec["start_state_reason"]
    assert not df["flags"].fillna("").str.contains("conditioning").any()
    rec, _ = _run(tmp, "old.json")  # c.csv again: one compensate.json per commands file
    assert rec["start_state"] == "rest" and "does not say" in rec["start_state_reason"]
    # forced either way
    rec, _ = _run(tmp, "old.json", conditioning="sweep")
    assert rec["start_state"] == "conditioning_sweep" and rec["n_conditioning"] > 0
    _fit_json(tmp / "mid.json", MID_LOOP)
    rec, _ = _run(tmp, "mid.json", conditioning="none")
    assert rec["start_state"] == "rest" and rec["n_conditioning"] == 0


def test_history_gives_the_state_and_the_start_counts(tmp):
    P = _fit_json(tmp / "fit.json", MID_LOOP)
    _run(tmp, "fit.json", out="first.csv", model="gpi")  # with its sweep
    rec, df = _run(
        tmp, "fit.json", out="second/second.csv", model="gpi", history=tmp / "first.csv"
    )  # its own folder: first.csv keeps its compensate.json
    first = pd.read_csv(tmp / "first.csv")["enc_yaw"].to_numpy(float)
    assert rec["start_state"] == "history" and rec["n_history"] == first.size
    assert rec["start_counts"] == first[-1] and rec["n_conditioning"] == 0
    # truth: the model over the history and then these rows, from rest at the first row
    model = model_from_params("gpi", gpi_values(P), 30, 2.0)
    enc = df["enc_yaw"].to_numpy(float)
    y = forward(model, np.concatenate((first, enc)))[first.size :]
    np.testing.assert_allclose(df["predicted_yaw_deg"], y, atol=1e-9)
    assert abs(enc[0] - first[-1]) <= RATE * 0.02


@pytest.mark.parametrize(
    ("setup", "kw", "match"),
    [
        (None, {"conditioning": "always"}, "--conditioning must be one of auto, sweep, none"),
        ("missing", {}, "file not found"),
        (pd.DataFrame({"enc_pitch": [0, 1]}), {}, "needs the column"),
        (pd.DataFrame({"enc_yaw": [0, 9000]}), {}, "outside the yaw\\+ fit's input range"),
        (pd.DataFrame({"enc_yaw": [0, "x"]}), {}, "non-numeric"),
        (pd.DataFrame({"enc_yaw": [0, 10]}), {"start_counts": 0.0}, "not the history's last"),
    ],
)
def test_bad_start_options_one_line(tmp, setup, kw, match):
    _fit_json(tmp / "fit.json", MID_LOOP)
    hist = None
    if setup is not None:
        hist = tmp / "h.csv"
        if isinstance(setup, pd.DataFrame):
            setup.to_csv(hist, index=False)
    with pytest.raises(CalibError, match=match) as exc:
        _run(tmp, "fit.json", out="o/c.csv", history=hist, **kw)
    assert "\n" not in str(exc.value) and not (tmp / "o" / "c.csv").exists()


def test_cli(tmp, capsys):
    _fit_json(tmp / "fit.json", MID_LOOP)
    code = main(["compensate", str(tmp / "fit.json"), "--target", str(tmp / "target.csv"),
                 "--out", str(tmp / "c.csv"), "--dataset", "yaw+"])  # fmt: skip
    out = capsys.readouterr().out
    assert code in (0, None) and "start: conditioning sweep" in out and "mid-loop" in out
    assert main(["compensate", "--help"]) in (0, None)
    helptext = capsys.readouterr().out
    assert "--conditioning" in helptext and "--history" in helptext
