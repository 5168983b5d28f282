"""`i2ris-calib diagnose`: outputs on a synced CSV with a hidden delay; bad input."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from i2ris_calib.cli import main
from i2ris_calib.commands.diagnose import diagnosis_dataset
from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.config import FitConfig


def _synced_csv(path, effect="time_delay", params=None, seed=3, n_cycles=8):
    from i2ris_calib.diagnosis.synthetic import make_case

    case = make_case(seed, effect, params or {"tau_s": 0.2}, noise_deg=0.15, n_cycles=n_cycles)
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
    from i2ris_calib.commands.diagnose import diagnosis_dataset
    from i2ris_calib.fitting.config import FitConfig
    from i2ris_calib.hysteresis.codec import model_from_dict
    from i2ris_calib.hysteresis.effects import model_values

    _, out, _, csv = diagnosed
    obj = json.loads((out / "final_model.json").read_text())
    model = model_from_dict(obj)
    assert [e["name"] for e in obj["effects"]] == ["time_delay"]
    assert [p.name for p in model.parameters] == list(obj["params"])
    data = diagnosis_dataset(csv, "yaw", "auto", FitConfig())
    assert obj["dataset"] == data.name == "yaw+" and obj["direction"] == "+"
    theta = data.theta_deg
    y = model.evaluate(data.signals, model_values(model))
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
        (lambda df: df.iloc[::-1], "strictly increasing"),
        (
            lambda df: df.assign(enc_yaw=df["enc_yaw"].astype(object).where(df.index != 5, "x")),
            "not numeric at line 7",
        ),
        (lambda df: df.iloc[:5], "fewer than 50 samples leave the zero band"),
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
        (["--axis", "yaw", "--start", "gip"], "--start must be one of auto, gpi, egpi"),
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
    from i2ris_calib.errors import CalibError
    from i2ris_calib.hysteresis.codec import model_from_dict

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


def test_direction_dataset_is_the_whole_history(tmp_path):
    """--direction picks one Dataset of the one reader: every row in time order, the
    direction's input, the angle in its convention (-theta = |theta| for "-") only on
    its own samples; auto = the direction with more in-direction samples."""
    from i2ris_calib.commands.diagnose import diagnosis_dataset
    from i2ris_calib.errors import CalibError
    from i2ris_calib.fitting.config import FitConfig

    # out to +3000 and back, out to -2000 and back (ramps, no jumps: read_synced refuses
    # encoder jumps faster than the motor moves), then a rest at 0
    t = np.arange(0, 50, 0.1)
    enc = np.round(np.interp(t, [0, 10, 20, 30, 40, 50], [0, 3000, 0, -2000, 0, 0]))
    csv = tmp_path / "s.csv"
    pd.DataFrame({"time_s": t, "enc_yaw": enc, "yaw_deg": 0.01 * enc, "status": "measured"}).to_csv(
        csv, index=False
    )
    minus = diagnosis_dataset(csv, "yaw", "-", FitConfig())
    assert minus.name == "yaw-" and minus.abs_fitted and minus.n_samples == t.size
    np.testing.assert_array_equal(minus.v, np.maximum(-enc, 0.0))
    mine = minus.in_direction
    zb = minus.bands.zero_band
    assert mine[(enc < -zb)].all() and not mine[enc > zb].any()
    assert mine[t >= 40].all()  # the rest after the "-" excursion belongs to it
    np.testing.assert_allclose(minus.theta_deg[mine], np.abs(0.01 * enc[mine]))
    assert np.isnan(minus.theta_deg[~mine]).all()
    plus = diagnosis_dataset(csv, "yaw", "+", FitConfig())
    assert plus.name == "yaw+" and plus.n_samples == t.size and plus.v.max() == enc.max()
    np.testing.assert_array_equal(plus.in_direction, ~minus.in_direction)
    # "+": the + excursion and the zero-band samples after it (up to the start of the
    # "-" one); "-": the rest, with the final rest: auto takes the larger one
    first_minus = int(np.flatnonzero(enc < -zb)[0])
    assert (
        plus.in_direction[: first_minus - 1].all() or plus.in_direction[1 : first_minus - 1].all()
    )
    assert plus.rows["in_direction"] < minus.rows["in_direction"]
    assert plus.rows["in_direction"] + minus.rows["in_direction"] == t.size
    # auto follows fit's model choice: the input crosses zero (no rest at t = 20 s) ->
    # the signed dataset; with the paper's split forced, the larger direction
    assert diagnosis_dataset(csv, "yaw", "auto", FitConfig()).name == "yaw±"
    assert diagnosis_dataset(csv, "yaw", "auto", FitConfig(split=True)).name == "yaw-"
    pd.DataFrame({"time_s": t, "enc_yaw": -enc, "yaw_deg": -0.01 * enc}).to_csv(csv, index=False)
    assert diagnosis_dataset(csv, "yaw", "auto", FitConfig(split=True)).name == "yaw+"
    # [fit] signed = true: one signed dataset, chosen by auto; + / - are refused
    signed = FitConfig(signed=True)
    assert diagnosis_dataset(csv, "yaw", "auto", signed).name == "yaw±"
    with pytest.raises(CalibError, match="signed = true"):
        diagnosis_dataset(csv, "yaw", "+", signed)


def test_bad_direction_is_a_one_line_error(tmp_path, capsys):
    csv = tmp_path / "s.csv"
    t = np.arange(0, 10, 0.1)
    pd.DataFrame({"time_s": t, "enc_yaw": 100 * t, "yaw_deg": t}).to_csv(csv, index=False)
    rc, err = _run_error(capsys, [str(csv), "--axis", "yaw", "--direction", "up"])
    assert rc == 2 and "--direction must be" in err


def _one_direction_csv(path):
    """A yaw recording whose input goes 0 -> 6000 -> 0 and never crosses zero."""
    t = np.arange(0, 20, 0.05)
    enc = np.round(3000 * (1 - np.cos(2 * np.pi * t / 5)))
    pd.DataFrame({"time_s": t, "enc_yaw": enc, "yaw_deg": enc / 200}).to_csv(path, index=False)


@pytest.mark.parametrize("start", ["agpi", "bouc_wen", "maxwell_slip"])
def test_signed_start_on_a_direction_dataset_is_refused(tmp_path, capsys, start):
    """docs/diagnosis.md: agpi, maxwell_slip, bouc_wen start on the signed input only."""
    csv = tmp_path / "s.csv"
    _one_direction_csv(csv)
    out = tmp_path / "o"
    rc, err = _run_error(capsys, [str(csv), "--axis", "yaw", "--start", start, "--out", str(out)])
    assert rc == 2 and "\n" not in err, err
    assert f"--start {start}" in err and "yaw+" in err and "--start auto, gpi, egpi" in err
    assert not out.exists()


def test_signed_start_on_a_direction_dataset_is_refused_from_python(tmp_path):
    from i2ris_calib import diagnose_from_starts, load_synced

    csv = tmp_path / "s.csv"
    _one_direction_csv(csv)
    data = load_synced(csv, "yaw")[0]
    with pytest.raises(CalibError, match=r"diagnose_from_starts: starts \('agpi',\)") as exc:
        diagnose_from_starts(data, starts=("agpi",))
    assert "--" not in str(exc.value)  # no CLI flag named to a Python caller


def test_signed_direction_of_an_input_that_never_crosses_zero(tmp_path, capsys):
    """It leaves the zero band (up to 6000): the message says it never crosses zero."""
    csv = tmp_path / "s.csv"
    _one_direction_csv(csv)
    out = tmp_path / "o"
    rc, err = _run_error(capsys, [str(csv), "--axis", "yaw", "--direction", "±", "--out", str(out)])
    assert rc == 2 and "\n" not in err, err
    assert "never crosses zero" in err and "0..6000" in err and "--direction +" in err
    assert "zero band" not in err
    assert not out.exists()


def test_output_starts_with_the_verdict_not_a_blank_line(tmp_path, capsys):
    csv = tmp_path / "s.csv"
    t = np.arange(0, 20, 0.05)
    enc = np.round(3000 * np.sin(2 * np.pi * t / 5))
    pd.DataFrame({"time_s": t, "enc_yaw": enc, "yaw_deg": enc / 200}).to_csv(csv, index=False)
    out = tmp_path / "o"
    assert main(["diagnose", str(csv), "--axis", "yaw", "--start", "gpi", "--out", str(out)]) == 0
    text, err = capsys.readouterr()
    assert text.startswith("yaw±: ") and err == "", (text, err)


def test_signed_direction_of_an_input_that_crosses_zero(tmp_path):
    """docs/diagnosis.md: ``±`` is the signed dataset of an input that crosses zero."""
    csv = tmp_path / "s.csv"
    t = np.arange(0, 20, 0.05)
    enc = np.round(3000 * np.sin(2 * np.pi * t / 5))
    pd.DataFrame({"time_s": t, "enc_yaw": enc, "yaw_deg": enc / 200}).to_csv(csv, index=False)
    dset = diagnosis_dataset(csv, "yaw", "±", FitConfig())
    assert dset.name == "yaw±" and dset.rows["in_direction"] == t.size


def _two_direction_csv(path, seed=4, tau_s=0.15, noise_deg=0.1):
    """A yaw recording with + then - loading cycles (paper-like EGPI per direction,
    driven by the direction's input over the whole history, a hidden delay)."""
    from i2ris_calib.data.dataset import direction_of_samples
    from i2ris_calib.diagnosis.synthetic import excitation
    from i2ris_calib.hysteresis.effects import build_model, model_values
    from i2ris_calib.hysteresis.models import i2ris_egpi_model
    from i2ris_calib.hysteresis.presets import paper_like_params
    from i2ris_calib.model import Signals

    rng = np.random.default_rng(seed)
    t, v = excitation(rng, n_cycles=4)
    dt = t[1] - t[0]
    time = np.concatenate([t, t[-1] + dt + t])
    enc = np.concatenate([v, -v])
    angle = {}
    for d, sign in (("+", 1.0), ("-", -1.0)):
        truth = build_model(
            i2ris_egpi_model(**paper_like_params(f"yaw{d}")), {"time_delay": {"tau_s": tau_s}}
        )
        sig = Signals(v=np.maximum(sign * enc, 0.0), t_s=time)
        angle[d] = sign * truth.evaluate(sig, model_values(truth))
    side = direction_of_samples(enc, 30.0)
    theta = np.where(side > 0, angle["+"], angle["-"]) + rng.normal(0, noise_deg, enc.size)
    pd.DataFrame({"time_s": time, "enc_yaw": enc, "yaw_deg": theta}).to_csv(path, index=False)


# ~14 s: slow (the default run's 5-minute budget)
@pytest.mark.slow
def test_fit_model_file_refits_on_exactly_the_diagnosed_samples(tmp_path):
    """diagnose and fit build the same Dataset: the "-" dataset diagnosed over the
    whole history is the one `fit --model-file` refits the final model on (same rows,
    same loss mask, same held-out cycles), and the refit keeps the diagnosed fit."""
    from i2ris_calib.commands.diagnose import diagnosis_dataset
    from i2ris_calib.config import PipelineConfig
    from i2ris_calib.io.synced import load_datasets

    csv = tmp_path / "synced.csv"
    _two_direction_csv(csv)
    cfg = tmp_path / "cfg.toml"
    cfg.write_text('[diagnose]\nmax_steps = 1\ncandidates = ["time_delay", "dead_zone"]\n')
    dout = tmp_path / "diag"
    args = [str(csv), "--axis", "yaw", "--direction", "-", "--config", str(cfg)]
    assert main(["diagnose", *args, "--out", str(dout)]) == 0
    rec = json.loads((dout / "diagnosis.json").read_text())
    assert rec["dataset"] == "yaw-" and rec["direction"] == "-" and rec["abs_input"]
    assert rec["named_effects"] == ["time_delay"]

    fout = tmp_path / "fit"
    model_file = str(dout / "final_model.json")
    fit_args = [str(csv), "--axis", "yaw", "--model", "gpi", "--config", str(cfg)]
    assert main(["fit", *fit_args, "--model-file", model_file, "--out", str(fout)]) == 0
    doc = json.loads((fout / "fit.json").read_text())
    ds = {d["name"]: d for d in doc["datasets"]}
    assert set(ds) == {"yaw+", "yaw-"}
    minus = ds["yaw-"]
    # the same rows, loss mask and held-out cycles as the diagnosis
    assert minus["n_samples"] == rec["n_samples"] and minus["rows"] == rec["rows"]
    assert minus["bands"] == rec["bands"]
    refit = minus["models"]["diagnosed"]
    assert refit["n_samples"] == rec["rows"]["fitted"]
    assert refit["n_holdout"] == rec["rows"]["holdout"] > 0
    pred = pd.read_csv(fout / "predictions.csv")
    pm = pred[pred["dataset"] == "yaw-"]
    assert len(pm) == rec["n_samples"]
    assert (pm["split"] == "holdout").sum() >= rec["rows"]["holdout"]
    # array level: diagnose's dataset is fit's dataset
    pc = PipelineConfig()
    mine = diagnosis_dataset(csv, "yaw", "-", pc.fit)
    theirs = {d.name: d for d in load_datasets([csv], "yaw", pc.fit)}["yaw-"]
    np.testing.assert_array_equal(mine.v, theirs.v)
    np.testing.assert_array_equal(mine.theta_deg, theirs.theta_deg)
    np.testing.assert_array_equal(mine.holdout, theirs.holdout)
    np.testing.assert_array_equal(mine.fit_mask, theirs.fit_mask)
    np.testing.assert_array_equal(pm["split"].to_numpy() == "holdout", theirs.holdout)
    # refitting from the diagnosed values keeps the delay and the held-out error
    assert abs(refit["params"]["time_delay.tau_s"] - 0.15) < 0.03
    assert refit["holdout_metrics"]["rmse_deg"] < 1.5 * 0.1


def test_one_cycle_is_refused_stating_the_real_minimum(tmp_path, capsys):
    csv = tmp_path / "s.csv"
    t = np.arange(0, 20, 0.05)
    enc = np.round(3000 * (1 - np.cos(2 * np.pi * t / 20)))  # one loading cycle
    pd.DataFrame({"time_s": t, "enc_yaw": enc, "yaw_deg": 0.005 * enc}).to_csv(csv, index=False)
    rc, err = _run_error(capsys, [str(csv), "--axis", "yaw", "--out", str(tmp_path / "o")])
    assert rc == 2 and "\n" not in err
    assert "only 1 loading cycle" in err and "at least 2 loading cycles" in err
    assert not (tmp_path / "o").exists()


def test_run_diagnose_stage_writes_what_the_report_reads(tmp_path):
    """`[run] diagnose = true`: one stage per axis and direction under
    <run>/diagnose/<axis><direction>/; a direction without motion is skipped with
    its reason, and the report's loader picks the diagnosis up."""
    from i2ris_calib.commands.run import diagnose_direction, session_stages
    from i2ris_calib.config import PipelineConfig
    from i2ris_calib.diagnosis.config import DiagnosisConfig
    from i2ris_calib.io.run_folder import load_run

    run = tmp_path / "run"
    csv = run / "sync" / "synced.csv"
    csv.parent.mkdir(parents=True)
    _synced_csv(csv, n_cycles=4)
    cfg = PipelineConfig(
        diagnose=DiagnosisConfig(candidates=("time_delay", "creep"), max_steps=1, max_samples=1500)
    )
    diagnose_direction(csv, "yaw", "+", run / "diagnose" / "yaw+", cfg)
    diagnose_direction(csv, "yaw", "-", run / "diagnose" / "yaw-", cfg)
    rec = json.loads((run / "diagnose" / "yaw+" / "diagnosis.json").read_text())
    assert rec["start"] == "auto" and set(rec["paths"]) == {"gpi", "egpi"}
    assert rec["named_effects"] == ["time_delay"]
    skipped = json.loads((run / "diagnose" / "yaw-" / "skipped.json").read_text())
    assert "yaw" in skipped["reason"] and skipped["direction"] == "-"
    data, _ = load_run(run)
    assert [d.axis for d in data.diagnoses] == ["yaw+"]
    assert "time_delay" in data.diagnoses[0].markdown
    # the stages exist only when asked for, after the fits and before the report
    session = tmp_path / "session"  # the stages read the files session.toml names
    sample = Path(__file__).resolve().parents[2] / "sample_data" / "session"
    shutil.copytree(sample, session, ignore=shutil.ignore_patterns("truth"))
    names = [s.name for s in session_stages(session, run, PipelineConfig())]
    assert not any(n.startswith("diagnose") for n in names)
    on = PipelineConfig(run=type(PipelineConfig().run)(diagnose=True))
    names = [s.name for s in session_stages(session, run, on)]
    diag = [n for n in names if n.startswith("diagnose")]
    assert diag == [f"diagnose {a}{d}" for a in ("yaw", "pitch") for d in ("+", "-", "±")]
    assert names.index(diag[0]) > names.index("fit pitch") and names[-1] == "report"
    # the paper's protocol: the default fit splits, so the signed stage records why not
    diagnose_direction(csv, "yaw", "±", run / "diagnose" / "yaw±", cfg)
    skipped = json.loads((run / "diagnose" / "yaw±" / "skipped.json").read_text())
    assert "fits yaw+ and yaw-, not yaw± (split: " in skipped["reason"]
    assert [d.axis for d in load_run(run)[0].diagnoses] == ["yaw+"]


def test_run_says_a_diagnose_stage_was_skipped_and_why(tmp_path):
    """Was: "diagnose yaw±: ran" for a folder holding only skipped.json."""
    from i2ris_calib.commands.run import Stage, diagnose_direction, run_stage
    from i2ris_calib.config import PipelineConfig

    csv = tmp_path / "synced.csv"
    _synced_csv(csv, n_cycles=4)
    cfg = PipelineConfig()
    out = tmp_path / "diagnose" / "yaw±"
    stage = Stage("diagnose yaw±", out, (csv,), (cfg.fit, cfg.diagnose),
                  lambda: diagnose_direction(csv, "yaw", "±", out, cfg))  # fmt: skip
    said = run_stage(stage, force=False)
    assert said.startswith("skipped: the default fit of yaw fits yaw+ and yaw-"), said
    assert run_stage(stage, force=False) == f"up to date ({said})"


def test_run_diagnoses_what_the_default_fit_fits_through_zero(tmp_path):
    """A recording through zero: the default fit models the axis over its signed input,
    so `run` diagnoses yaw± and records for yaw+ and yaw- that the fit does not split."""
    from i2ris_calib.commands.run import diagnose_direction
    from i2ris_calib.config import PipelineConfig

    csv = tmp_path / "synced.csv"
    t = np.arange(0, 60, 0.05)
    enc = np.round(3000 * np.sin(2 * np.pi * t / 10))
    rng = np.random.default_rng(0)
    pd.DataFrame(
        {"time_s": t, "enc_yaw": enc, "yaw_deg": 0.005 * enc + rng.normal(0, 0.1, t.size)}
    ).to_csv(csv, index=False)
    for d in ("+", "-"):
        diagnose_direction(csv, "yaw", d, tmp_path / f"yaw{d}", PipelineConfig())
        reason = json.loads((tmp_path / f"yaw{d}" / "skipped.json").read_text())["reason"]
        assert f"fits yaw±, not yaw{d} (signed:" in reason and "crosses zero" in reason


def test_run_section_is_validated(tmp_path):
    from i2ris_calib.errors import CalibError
    from i2ris_calib.io.config_io import load_config

    good = tmp_path / "good.toml"
    good.write_text("[run]\ndiagnose = true\n")
    assert load_config(good).run.diagnose is True
    bad = tmp_path / "bad.toml"
    bad.write_text('[run]\ndiagnose = "yes"\n')
    with pytest.raises(CalibError, match="diagnose"):
        load_config(bad)
    typo = tmp_path / "typo.toml"
    typo.write_text("[run]\ndiagnoze = true\n")
    with pytest.raises(CalibError, match="did you mean 'diagnose'"):
        load_config(typo)


@pytest.mark.parametrize("direction", ["auto", "+", "-", "±"])
def test_the_synced_csv_is_read_and_validated_once(tmp_path, monkeypatch, direction):
    """``diagnose`` reads its synced CSV once (it read it twice: fit's model choice
    then the split) and builds the datasets from that one validated frame: the same
    dataset as two reads gave."""
    import i2ris_calib.io.synced as synced

    t = np.arange(0, 50, 0.1)
    enc = np.round(np.interp(t, [0, 10, 20, 30, 40, 50], [0, 3000, 0, -2000, 0, 0]))
    csv = tmp_path / "s.csv"
    pd.DataFrame({"time_s": t, "enc_yaw": enc, "yaw_deg": 0.01 * enc, "status": "measured"}).to_csv(
        csv, index=False
    )
    config = FitConfig(split=direction == "auto")
    reads, read = [], synced.read_synced
    monkeypatch.setattr(synced, "read_synced", lambda *a, **k: reads.append(a) or read(*a, **k))
    got = diagnosis_dataset(csv, "yaw", direction, config)
    assert len(reads) == 1
    if direction == "auto":  # the split forced: the larger direction, as fit's datasets
        want = synced.datasets_for_fit([csv], "yaw", config)[0]
        want = max(want, key=lambda d: d.rows["in_direction"])
    else:
        signed = direction == "±"
        cfg = FitConfig(signed=True, split=False) if signed else config
        (want,) = synced.load_datasets([csv], "yaw", cfg, (direction,))
    assert got.name == want.name and got.rows == want.rows
    np.testing.assert_array_equal(got.in_direction, want.in_direction)
    np.testing.assert_array_equal(got.holdout, want.holdout)


def test_the_diagnose_command_reads_its_csv_once(tmp_path, monkeypatch):

    csv = tmp_path / "synced.csv"
    _synced_csv(csv, n_cycles=6)
    cfg = tmp_path / "cfg.toml"
    cfg.write_text('[diagnose]\nmax_steps = 1\ncandidates = ["time_delay"]\n')
    reads, read = [], pd.read_csv
    monkeypatch.setattr(pd, "read_csv", lambda *a, **k: reads.append(a) or read(*a, **k))
    rc = main(["diagnose", str(csv), "--axis", "yaw", "--start", "gpi", "--out",
               str(tmp_path / "out"), "--config", str(cfg)])  # fmt: skip
    assert rc == 0 and [Path(a[0]) for a in reads] == [csv]
