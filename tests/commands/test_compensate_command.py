"""``i2ris-calib compensate``: files, sign conventions, one-line errors, atomic outputs."""

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


def _fit_json(path, axis="yaw", kinds=("egpi", "egpi_c", "gpi"), rate=1e6):
    P = paper_like_params(f"{axis}+")
    hold = {"egpi": 0.2, "egpi_c": 0.1, "gpi": 0.5}
    datasets = []
    for name in (f"{axis}+", f"{axis}-"):
        models = {
            k: {
                "params": gpi_values(P) if k == "gpi" else P,
                "n_operators": 30,
                "deadband_counts": 2.0,
                "metrics": {"rmse_deg": 0.1},
                "holdout_metrics": {"rmse_deg": hold[k]},
            }
            for k in kinds
        }
        datasets.append(
            {
                "name": name,
                "input_range_counts": [0.0, 6000.0],
                "max_input_rate_counts_per_s": rate,
                "models": models,
            }
        )
    doc = {"schema": "i2ris-calib.fit/1", "axis": axis, "datasets": datasets}
    path.write_text(json.dumps(doc))
    return P


@pytest.fixture
def files(tmp_path):
    P = _fit_json(tmp_path / "fit.json")
    t = np.arange(0, 10, 0.02)
    pd.DataFrame({"time_s": t, "yaw_deg": -(14 + 8 * np.sin(t))}).to_csv(
        tmp_path / "target.csv", index=False
    )
    return tmp_path, P


def test_minus_dataset_signs_and_exact_prediction(files):
    tmp, P = files
    doc = compensate_files(
        [tmp / "fit.json"], ["yaw-"], tmp / "target.csv", tmp / "out" / "cmd.csv", model="egpi"
    )
    df = pd.read_csv(tmp / "out" / "cmd.csv")
    assert list(df.columns) == ["time_s", "enc_yaw", "predicted_yaw_deg", "reachable", "flags"]
    assert df["enc_yaw"].dtype == np.int64 and (df["enc_yaw"] <= 0).all()
    model = model_from_params("egpi", P, 30, 2.0)
    # predicted angle = -(model output for |counts|): the "-" dataset's convention
    np.testing.assert_allclose(
        df["predicted_yaw_deg"], -forward(model, -df["enc_yaw"].to_numpy(float)), atol=1e-8
    )
    target = pd.read_csv(tmp / "target.csv")["yaw_deg"]
    ok = df["reachable"] == 1
    assert ok.mean() > 0.9
    assert np.max(np.abs(df["predicted_yaw_deg"][ok] - target[ok])) < 0.01
    saved = json.loads((tmp / "out" / "compensate.json").read_text())
    assert saved["axes"]["yaw"]["model"] == "egpi" == doc["axes"]["yaw"]["model"]
    assert saved["axes"]["yaw"]["n_unreachable"] == int((~ok).sum())
    assert "v_f" in saved["method"]


def test_default_model_is_the_fit_decision_and_rate_limit(files):
    """One decision (issue 32): compensate inverts the model fit.json recommends, not
    its own ranking's best; this hand-made fit.json has no ``decision`` (an older
    file): its converged model with the lowest held-out RMSE."""
    tmp, _ = files
    doc = compensate_files(
        [tmp / "fit.json"], ["yaw-"], tmp / "target.csv", tmp / "c.csv",
        max_counts_per_s=2000.0, start_counts=0.0,
    )  # fmt: skip
    rec = doc["axes"]["yaw"]
    fit = json.loads((tmp / "fit.json").read_text())
    (ds,) = [d for d in fit["datasets"] if d["name"] == "yaw-"]
    held = {k: m["holdout_metrics"]["rmse_deg"] for k, m in ds["models"].items()}
    assert rec["model"] == min(held, key=held.__getitem__) == rec["recommended_model"]
    assert rec["model_choice"] == "fit decision" and rec["substitute"] is None
    assert [r["model"] for r in rec["ranking"] if r["chosen"]] == [rec["model"]]
    assert {r["model"] for r in rec["ranking"]} == {"egpi", "egpi_c", "gpi"}
    enc = pd.read_csv(tmp / "c.csv")["enc_yaw"].to_numpy()
    assert np.max(np.abs(np.diff(np.concatenate(([0], enc))))) <= 2000 * 0.02 + 1e-9


def test_both_axes(files):
    tmp, _ = files
    _fit_json(tmp / "fit_pitch.json", axis="pitch")
    t = np.arange(0, 5, 0.02)
    pd.DataFrame(
        {"time_s": t, "yaw_deg": 12 + 5 * np.sin(t), "pitch_deg": 10 + 4 * np.cos(t)}
    ).to_csv(tmp / "both.csv", index=False)
    compensate_files(
        [tmp / "fit.json", tmp / "fit_pitch.json"], ["yaw+", "pitch+"], tmp / "both.csv",
        tmp / "b.csv",
    )  # fmt: skip
    cols = pd.read_csv(tmp / "b.csv").columns
    assert {"enc_yaw", "enc_pitch", "reachable_yaw", "reachable_pitch", "reachable"} <= set(cols)


@pytest.mark.parametrize("second", ["fit.json", "sub/../fit.json", "fit_yaw2.json"])
def test_one_fit_per_axis_says_what_is_wrong(files, capsys, second):
    """The same fit.json twice (or two yaw fits) with a two-axis target and no
    --dataset: the message names the files, not --dataset."""
    tmp, _ = files
    (tmp / "sub").mkdir()
    _fit_json(tmp / "fit_yaw2.json")
    t = np.arange(0, 5, 0.02)
    pd.DataFrame(
        {"time_s": t, "yaw_deg": 12 + 5 * np.sin(t), "pitch_deg": 10 + 4 * np.cos(t)}
    ).to_csv(tmp / "both.csv", index=False)
    out = tmp / "o" / "c.csv"
    rc = main(["compensate", str(tmp / "fit.json"), str(tmp / second), "--target",
               str(tmp / "both.csv"), "--out", str(out)])  # fmt: skip
    err = capsys.readouterr().err.strip()
    assert rc == 2 and err.startswith("error:") and "\n" not in err
    assert "--dataset" not in err and "per axis" in err
    assert ("given twice" in err) == (second != "fit_yaw2.json")
    assert not out.exists() and not (out.parent / "compensate.json").exists()


@pytest.mark.parametrize(
    ("edit", "args", "match"),
    [
        (lambda df: df.drop(columns="yaw_deg"), {}, "missing column"),
        (lambda df: df.assign(time_s=df["time_s"][::-1].to_numpy()), {}, "increase strictly"),
        (
            lambda df: df.assign(yaw_deg=np.where(df.index == 5, np.nan, df["yaw_deg"])),
            {},
            "line 7",
        ),
        (None, {"datasets": ["pitch+"]}, r"missing column\(s\) pitch_deg"),
        (None, {"datasets": ["yaw*"]}, "--dataset must be"),
        (None, {"model": "diagnosed"}, "no 'diagnosed' model"),
        (None, {"out_name": "x.txt"}, "ending in .csv"),
    ],
)
def test_bad_inputs_one_line_errors_and_nothing_written(files, edit, args, match):
    tmp, _ = files
    if edit is not None:
        edit(pd.read_csv(tmp / "target.csv")).to_csv(tmp / "target.csv", index=False)
    out = tmp / "o" / args.get("out_name", "c.csv")
    with pytest.raises(CalibError, match=match) as exc:
        compensate_files(
            [tmp / "fit.json"], args.get("datasets", ["yaw+"]), tmp / "target.csv", out,
            model=args.get("model"),
        )  # fmt: skip
    assert "\n" not in str(exc.value)
    assert not out.exists() and not (out.parent / "compensate.json").exists()


def test_missing_model_kind(tmp_path):
    _fit_json(tmp_path / "fit.json", kinds=("gpi",))
    pd.DataFrame({"time_s": [0.0, 1.0], "yaw_deg": [5.0, 6.0]}).to_csv(
        tmp_path / "t.csv", index=False
    )
    with pytest.raises(CalibError, match="no 'egpi' model"):
        compensate_files(
            [tmp_path / "fit.json"], ["yaw+"], tmp_path / "t.csv", tmp_path / "c.csv", model="egpi"
        )


def test_outputs_atomic_on_failure(files, monkeypatch):
    tmp, _ = files

    def boom(*a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(pd.DataFrame, "to_csv", boom)
    with pytest.raises(CalibError, match="cannot write"):
        compensate_files([tmp / "fit.json"], ["yaw+"], tmp / "target.csv", tmp / "o" / "c.csv")
    assert not any((tmp / "o").glob("*")) if (tmp / "o").exists() else True


def test_cli_one_line_error_and_success(files, capsys):
    tmp, _ = files
    code = main(["compensate", str(tmp / "fit.json"), "--dataset", "yaw+", "--target",
                 str(tmp / "nope.csv"), "--out", str(tmp / "c.csv")])  # fmt: skip
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error:") and "\n" not in err
    code = main(["compensate", str(tmp / "fit.json"), "--dataset", "yaw-", "--target",
                 str(tmp / "target.csv"), "--out", str(tmp / "c.csv"), "--model", "gpi"])  # fmt: skip
    assert code == 0
    assert "gpi" in capsys.readouterr().out
    assert (tmp / "c.csv").is_file() and (tmp / "compensate.json").is_file()


def test_diagnosed_model_with_delay(tmp_path):
    from i2ris_calib.hysteresis.codec import model_to_dict
    from i2ris_calib.hysteresis.effects import add_effect

    P = _fit_json(tmp_path / "fit.json", kinds=("egpi",))
    model = add_effect(model_from_params("egpi", P, 30, 2.0), "time_delay", {"tau_s": 0.1})
    (tmp_path / "final_model.json").write_text(json.dumps(model_to_dict(model)))
    doc = json.loads((tmp_path / "fit.json").read_text())
    rec = dict(doc["datasets"][0]["models"]["egpi"])
    rec["params"] = {p.name: p.value for p in model.parameters}
    doc["datasets"][0]["models"]["diagnosed"] = rec
    (tmp_path / "fit.json").write_text(json.dumps(doc))
    t = np.arange(0, 10, 0.01)
    pd.DataFrame({"time_s": t, "yaw_deg": 15 + 5 * np.sin(t)}).to_csv(
        tmp_path / "t.csv", index=False
    )
    with pytest.raises(CalibError, match="needs --model-file"):
        compensate_files(
            [tmp_path / "fit.json"],
            ["yaw+"],
            tmp_path / "t.csv",
            tmp_path / "c.csv",
            model="diagnosed",
        )
    out = compensate_files(
        [tmp_path / "fit.json"], ["yaw+"], tmp_path / "t.csv", tmp_path / "c.csv",
        model="diagnosed", model_file=tmp_path / "final_model.json",
    )  # fmt: skip
    assert out["axes"]["yaw"]["delay_s"] == pytest.approx(0.1)
    df = pd.read_csv(tmp_path / "c.csv")
    late = df["time_s"] > 0.1
    err = df["predicted_yaw_deg"][late] - 15 - 5 * np.sin(df["time_s"][late])
    assert np.max(np.abs(err)) < 0.02
    assert out["axes"]["yaw"]["unreachable"]["within_delay"] == int((~late).sum())


def test_fit_json_written_by_fit(tmp_path):
    # the real fit.json format (records written by 'fit'), both directions of one axis
    from i2ris_calib.commands.fit import fit_files
    from i2ris_calib.hysteresis.presets import loading_trajectory
    from i2ris_calib.io.config_io import load_config

    rng = np.random.default_rng(5)
    t, v = loading_trajectory(rng, n_cycles=4, n_samples=1200)
    P = {d: gpi_values(paper_like_params(d)) for d in ("yaw+", "yaw-")}
    enc = np.concatenate([v, -v])
    yp = forward(model_from_params("gpi", P["yaw+"]), np.maximum(enc, 0))
    ym = -forward(model_from_params("gpi", P["yaw-"]), np.maximum(-enc, 0))
    theta = np.where(enc > 0, yp, np.where(enc < 0, ym, 0.0)) + rng.normal(0, 0.05, enc.size)
    time_s = np.concatenate([t, t + t[-1] + t[1]])
    pd.DataFrame({"time_s": time_s, "enc_yaw": enc, "yaw_deg": theta}).to_csv(
        tmp_path / "synced.csv", index=False
    )
    fit_files([tmp_path / "synced.csv"], "yaw", "gpi", tmp_path / "fit", load_config(None))
    tt = np.arange(0, 20, 0.01)
    target = -(14 + 8 * np.sin(0.7 * tt))
    pd.DataFrame({"time_s": tt, "yaw_deg": target}).to_csv(tmp_path / "target.csv", index=False)
    doc = compensate_files(
        [tmp_path / "fit" / "fit.json"], ["yaw-"], tmp_path / "target.csv", tmp_path / "c.csv",
        max_counts_per_s=float("inf"),  # exact tracking; the fit's own rate: test_safe_*
    )  # fmt: skip
    rec = doc["axes"]["yaw"]
    assert rec["model"] == "gpi"
    df = pd.read_csv(tmp_path / "c.csv")
    assert (df["enc_yaw"] <= 0).all()
    # the fitted GPI inverse, played through the TRUE yaw- GPI: close to the target
    # (measured 0.20 deg; a linear calibration is ~4 deg off on such loops)
    achieved = -forward(model_from_params("gpi", P["yaw-"]), -df["enc_yaw"].to_numpy(float))
    ok = df["reachable"] == 1
    assert np.sqrt(np.mean((achieved[ok] - target[ok]) ** 2)) < 0.3
    assert ok.mean() > 0.9


# ---------------------------------------------------------------- fit.json checked on load


def _broken(doc, how):
    ds = doc["datasets"][0]
    egpi = ds["models"]["egpi"]
    if how == "null":
        egpi["params"]["a1"] = None
    elif how == "text":
        egpi["params"]["a1"] = "abc"
    elif how == "nan":
        egpi["params"]["a1"] = float("nan")  # json writes NaN
    elif how == "missing":
        del egpi["params"]["v_f"]
    elif how == "reversed":
        ds["input_range_counts"] = [6000.0, 0.0]
    elif how == "range_nan":
        ds["input_range_counts"] = [0.0, float("nan")]
    elif how == "deadband":
        egpi["deadband_counts"] = None
    elif how == "operators":
        egpi["n_operators"] = 0
    return doc


@pytest.mark.parametrize(
    ("how", "key", "problem"),
    [
        ("null", "datasets[0].models.egpi.params.a1", "is null, not a finite number"),
        ("text", "datasets[0].models.egpi.params.a1", "= 'abc' is not a number"),
        ("nan", "datasets[0].models.egpi.params.a1", "= NaN is not a finite number"),
        ("missing", "datasets[0].models.egpi.params", "has no v_f"),
        ("reversed", "datasets[0].input_range_counts", "= [6000.0, 0.0] is not ordered: min"),
        ("range_nan", "datasets[0].input_range_counts[1]", "= NaN is not a finite number"),
        ("deadband", "datasets[0].models.egpi.deadband_counts", "is null, not a finite number"),
        ("operators", "datasets[0].models.egpi.n_operators", "= 0 is not a whole number >= 1"),
    ],
)
def test_broken_fit_json_is_one_line_naming_file_dataset_and_key(files, capsys, how, key, problem):
    tmp, _ = files
    bad = tmp / "bad_fit.json"
    bad.write_text(json.dumps(_broken(json.loads((tmp / "fit.json").read_text()), how)))
    rc = main(["compensate", str(bad), "--dataset", "yaw+", "--model", "egpi", "--target",
               str(tmp / "target.csv"), "--out", str(tmp / "o" / "c.csv")])  # fmt: skip
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1, err
    assert err.startswith(f"error: {bad} [yaw+]: {key} {problem}")
    assert err.endswith("re-run 'fit' or restore the file")
    assert "target.csv" not in err  # the target is fine: not blamed
    assert not (tmp / "o").exists()


def test_fit_json_not_an_object_or_missing_keys(files, capsys):
    tmp, _ = files
    bad = tmp / "bad_fit.json"
    doc = json.loads((tmp / "fit.json").read_text())
    for text, expect in [
        ("[1, 2]", "expected a JSON object at top level, got list"),
        ("{nope", "not a JSON file"),
        (json.dumps({**doc, "axis": None}), "axis = null is not one of yaw, pitch"),
        (json.dumps({**doc, "datasets": [{"name": "yaw+"}]}), "datasets[0] has no 'models'"),
    ]:
        bad.write_text(text)
        rc = main(["compensate", str(bad), "--dataset", "yaw+", "--target",
                   str(tmp / "target.csv"), "--out", str(tmp / "o" / "c.csv")])  # fmt: skip
        err = capsys.readouterr().err.strip()
        assert rc == 2 and err.startswith(f"error: {bad}") and expect in err, err
    del doc["datasets"][0]["input_range_counts"]
    bad.write_text(json.dumps(doc))
    with pytest.raises(
        CalibError, match=r"\[yaw\+\]: datasets\[0\]\.input_range_counts is missing"
    ):
        compensate_files([bad], ["yaw+"], tmp / "target.csv", tmp / "o" / "c.csv")


def test_broken_final_model_json_names_file_and_key(tmp_path, capsys):
    from i2ris_calib.hysteresis.codec import model_to_dict
    from i2ris_calib.hysteresis.effects import add_effect

    P = _fit_json(tmp_path / "fit.json", kinds=("egpi",))
    model = add_effect(model_from_params("egpi", P, 30, 2.0), "time_delay", {"tau_s": 0.1})
    saved = model_to_dict(model)
    doc = json.loads((tmp_path / "fit.json").read_text())
    rec = dict(doc["datasets"][0]["models"]["egpi"])
    rec["params"] = {p.name: p.value for p in model.parameters}
    doc["datasets"][0]["models"]["diagnosed"] = rec
    (tmp_path / "fit.json").write_text(json.dumps(doc))
    t = np.arange(0, 5, 0.01)
    pd.DataFrame({"time_s": t, "yaw_deg": 15 + 5 * np.sin(t)}).to_csv(
        tmp_path / "t.csv", index=False
    )
    for where, value, key in [
        ("base", None, "base.params.a1 is null, not a finite number"),
        ("base", "abc", "base.params.a1 = 'abc' is not a number"),
        ("effect", float("nan"), "effects[0].params.tau_s = NaN is not a finite number"),
    ]:
        doc = json.loads(json.dumps(saved))
        if where == "base":
            doc["base"]["params"]["a1"] = value
        else:
            doc["effects"][0]["params"]["tau_s"] = value
        (tmp_path / "final_model.json").write_text(json.dumps(doc))
        rc = main(["compensate", str(tmp_path / "fit.json"), "--dataset", "yaw+", "--model",
                   "diagnosed", "--model-file", str(tmp_path / "final_model.json"), "--target",
                   str(tmp_path / "t.csv"), "--out", str(tmp_path / "o" / "c.csv")])  # fmt: skip
        err = capsys.readouterr().err.strip()
        assert rc == 2 and len(err.splitlines()) == 1
        assert err.startswith(f"error: {tmp_path / 'final_model.json'}: {key}"), err


# ------------------------------------------------- a target in radians or of the wrong sign


@pytest.mark.parametrize(
    ("dataset", "target", "says"),
    [
        ("yaw+", np.radians(14 + 8 * np.sin(np.arange(0, 10, 0.02))),
         "if the target is in radians, convert it to degrees (6 to 22 deg)"),
        ("yaw+", -(14 + 8 * np.sin(np.arange(0, 10, 0.02))),
         "the target has the other sign: give --dataset yaw- (the other motion direction) or "
         "negate the target"),
        ("yaw-", 14 + 8 * np.sin(np.arange(0, 10, 0.02)),
         "the target has the other sign: give --dataset yaw+"),
        ("yaw+", -np.radians(14 + 8 * np.sin(np.arange(0, 10, 0.02))),
         "the target looks like radians (-22 to -6 deg) of the other sign"),
        ("yaw+", 100 + 8 * np.sin(np.arange(0, 10, 0.02)),
         "give a target within the model's angles"),
    ],
)  # fmt: skip
def test_mostly_unreachable_target_says_ranges_and_likely_mistake(
    tmp_path, capsys, dataset, target, says
):
    P = _fit_json(tmp_path / "fit.json")
    t = np.arange(0, 10, 0.02)
    pd.DataFrame({"time_s": t, "yaw_deg": target}).to_csv(tmp_path / "t.csv", index=False)
    rc = main(["compensate", str(tmp_path / "fit.json"), "--dataset", dataset, "--model", "egpi",
               "--target", str(tmp_path / "t.csv"), "--out", str(tmp_path / "c.csv")])  # fmt: skip
    captured = capsys.readouterr()
    assert rc == 0  # a warning: the commands are still written
    rec = json.loads((tmp_path / "compensate.json").read_text())["axes"]["yaw"]
    assert rec["n_unreachable"] > 0.5 * rec["n_samples"]
    # the model's angles over its input range, in the dataset's sign (truth: its forward output)
    sign = -1.0 if dataset.endswith("-") else 1.0
    up = np.linspace(0, 6000, 1001)
    y = sign * forward(model_from_params("egpi", P, 30, 2.0), np.concatenate([up, up[::-1]]))
    np.testing.assert_allclose(rec["reachable_deg"], [y.min(), y.max()], rtol=1e-9)
    (warning,) = rec["warnings"]
    assert says in warning
    lo, hi = rec["reachable_deg"]
    assert f"the target spans {target.min():.3g} to {target.max():.3g} deg" in warning
    assert f"the model {lo:.3g} to {hi:.3g} deg" in warning
    assert f"warning: {warning}" in " ".join(captured.err.split())


def test_reachable_target_has_no_range_warning(files, capsys):
    tmp, _ = files
    rc = main(["compensate", str(tmp / "fit.json"), "--dataset", "yaw-", "--model", "egpi",
               "--target", str(tmp / "target.csv"), "--out", str(tmp / "c.csv")])  # fmt: skip
    assert rc == 0
    assert "warning" not in capsys.readouterr().err
    assert json.loads((tmp / "compensate.json").read_text())["axes"]["yaw"]["warnings"] == []


# ------------------------------------------------------------------ Ctrl-C (SIGINT)

INTERRUPT_CHILD = """
import os, signal, sys, threading
from i2ris_calib.cli import main
from i2ris_calib.compensation import kernel as K

original = K.invert


def invert(*args, **kwargs):  # Ctrl-C arrives while the compiled inversion runs
    short = list(args)
    short[7], short[8] = args[7][:10], args[8][:10]  # target, t
    original(*short, **kwargs)  # compiled (or loaded from numba's cache) before the Ctrl-C
    threading.Timer(float(os.environ["SIGINT_AFTER_S"]), os.kill,
                    (os.getpid(), signal.SIGINT)).start()
    return original(*args, **kwargs)


K.invert = invert
sys.argv = ["i2ris-calib", *sys.argv[1:]]
sys.exit(main())
"""


def _large_target(path, n):
    t = np.arange(n) * 0.001
    pd.DataFrame({"time_s": t, "yaw_deg": 20 + 15 * np.sin(2 * np.pi * 0.5 * t)}).to_csv(
        path, index=False, float_format="%.6f"
    )


def test_ctrl_c_inside_the_compiled_inversion_is_one_line_and_130(tmp_path):
    # 0.2 s into an inversion of 3e5 samples (~1 s here): the compiled loop is running.
    # Before the inversion was chunked, the SIGINT was handled while numba converted the
    # returned arrays: SystemError ("returned a result with an exception set") or SIGSEGV
    import os
    import subprocess
    import sys

    _fit_json(tmp_path / "fit.json")
    _large_target(tmp_path / "target.csv", 300_000)
    out = tmp_path / "o" / "c.csv"
    proc = subprocess.run(
        [sys.executable, "-c", INTERRUPT_CHILD, "compensate", str(tmp_path / "fit.json"),
         "--dataset", "yaw+", "--model", "egpi", "--target", str(tmp_path / "target.csv"),
         "--out", str(out)],
        capture_output=True, text=True, timeout=300,
        env={**os.environ, "SIGINT_AFTER_S": "0.2", "NUMBA_NUM_THREADS": "1"},
    )  # fmt: skip
    assert proc.returncode == 130, (proc.returncode, proc.stderr[-2000:])
    assert proc.stderr == "interrupted (no partial outputs were kept)\n"
    assert not out.exists() and not out.with_name("compensate.json").exists()


@pytest.mark.slow  # ~1 min: a 1e6-sample target, interrupted at 1-6 s, two launchers
@pytest.mark.parametrize("launcher", ["console script", "python -m"])
def test_ctrl_c_at_any_time_during_compensate_is_130(tmp_path, launcher):
    # the case: Ctrl-C 2-4 s into compensate of a 1e6-row target gave SIGSEGV
    # (5 of 5 tries), at 6 s rc -2 without a message
    import os
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    _fit_json(tmp_path / "fit.json")
    _large_target(tmp_path / "target.csv", 1_000_000)
    if launcher == "console script":
        cmd = [str(Path(sys.executable).with_name("i2ris-calib"))]
    else:
        cmd = [sys.executable, "-m", "i2ris_calib.cli"]
    for delay in (1.0, 2.0, 3.0, 4.0, 6.0):
        out = tmp_path / f"o{delay:g}" / "c.csv"
        proc = subprocess.Popen(
            [*cmd, "compensate", str(tmp_path / "fit.json"), "--dataset", "yaw+", "--target",
             str(tmp_path / "target.csv"), "--out", str(out)],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            env={**os.environ, "NUMBA_NUM_THREADS": "1"},
        )  # fmt: skip
        time.sleep(delay)
        finished = proc.poll() is not None
        if not finished:
            proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=300)
        if finished:  # a fast machine: done before the Ctrl-C
            assert proc.returncode == 0 and out.is_file(), err
            continue
        assert proc.returncode in (0, 130), (delay, proc.returncode, err[-2000:])
        if proc.returncode == 130:
            assert err == "interrupted (no partial outputs were kept)\n", (delay, err)
            assert not out.exists() and not out.with_name("compensate.json").exists()
        else:  # the Ctrl-C came after the outputs were complete (while Python shut down)
            assert out.is_file() and out.with_name("compensate.json").is_file()


# ---------------------------------------------------------------- safe by default (issue 21)


def test_ms_times_refused_or_converted(files):
    tmp, _ = files
    t = np.arange(0, 10, 0.01)
    pd.DataFrame({"time_s": t * 1000, "yaw_deg": 15 + 5 * np.sin(t)}).to_csv(
        tmp / "ms.csv", index=False
    )
    with pytest.raises(CalibError, match=r"look like ms: give --time-unit-s 0.001") as exc:
        compensate_files([tmp / "fit.json"], ["yaw+"], tmp / "ms.csv", tmp / "c.csv",
                         max_counts_per_s=5000.0)  # fmt: skip
    assert "\n" not in str(exc.value) and not (tmp / "c.csv").exists()
    doc = compensate_files([tmp / "fit.json"], ["yaw+"], tmp / "ms.csv", tmp / "c.csv",
                           max_counts_per_s=5000.0, time_unit_s=0.001)  # fmt: skip
    df = pd.read_csv(tmp / "c.csv")
    assert np.max(np.abs(np.diff(df["enc_yaw"])) / np.diff(df["time_s"])) <= 5000 + 1e-6
    assert doc["axes"]["yaw"]["max_command_rate_per_s"] <= 5000 + 1e-6
    assert df["time_s"].iloc[-1] == pytest.approx(9.99)


def test_start_counts_outside_the_fitted_range_refused(files):
    tmp, _ = files
    with pytest.raises(CalibError, match=r"--start-counts 1e\+06 is outside") as exc:
        compensate_files([tmp / "fit.json"], ["yaw+"], tmp / "target.csv", tmp / "c.csv",
                         start_counts=1e6)  # fmt: skip
    assert "\n" not in str(exc.value)
    with pytest.raises(CalibError, match="outside the yaw- fit's input range -6000..0"):
        compensate_files([tmp / "fit.json"], ["yaw-"], tmp / "target.csv", tmp / "c.csv",
                         start_counts=500)  # fmt: skip


def test_default_rate_is_the_fits_and_flags_are_counted(tmp_path, capsys):
    # yaw- target -15 - 10 sin(t) without --start-counts (the case)
    _fit_json(tmp_path / "fit.json", rate=420.0)
    t = np.arange(0, 20, 0.01)
    pd.DataFrame({"time_s": t, "yaw_deg": -15 - 10 * np.sin(t)}).to_csv(
        tmp_path / "t.csv", index=False
    )
    out = tmp_path / "c.csv"
    code = main(["compensate", str(tmp_path / "fit.json"), "--dataset", "yaw-", "--target",
                 str(tmp_path / "t.csv"), "--out", str(out)])  # fmt: skip
    assert code == 0
    text = capsys.readouterr().out
    assert "rate limit 420 counts/s (fit.json max_input_rate_counts_per_s" in text
    assert "rate_limited" in text and "entry" in text
    df = pd.read_csv(out, keep_default_na=False)
    doc = json.loads((tmp_path / "compensate.json").read_text())["axes"]["yaw"]
    assert doc["max_counts_per_s"] == 420.0 and doc["start_counts"] == 0.0
    enc = np.concatenate(([0], df["enc_yaw"].to_numpy()))
    tt = np.concatenate(([df["time_s"].iloc[0] - 0.01], df["time_s"]))
    assert np.max(np.abs(np.diff(enc)) / np.diff(tt)) <= 420 + 1e-6
    d = np.diff(enc)
    assert not np.any((d[:-1] * d[1:] < 0) & (np.minimum(abs(d[:-1]), abs(d[1:])) > 60))
    for name, n in doc["flags"].items():
        assert df["flags"].str.contains(name).sum() == n, name
    assert (df["flags"] == "entry").sum() == doc["n_entry"] > 0
    assert (df["time_s"] < 0).sum() == doc["n_entry"]


def test_older_fit_json_without_rate_falls_back_with_a_line(files, capsys):
    tmp, _ = files
    doc = json.loads((tmp / "fit.json").read_text())
    for d in doc["datasets"]:
        del d["max_input_rate_counts_per_s"]
    (tmp / "fit.json").write_text(json.dumps(doc))
    code = main(["compensate", str(tmp / "fit.json"), "--dataset", "yaw-", "--target",
                 str(tmp / "target.csv"), "--out", str(tmp / "c.csv")])  # fmt: skip
    assert code == 0
    err = capsys.readouterr().err
    assert "has no max_input_rate_counts_per_s" in err and "rate limit 600 counts/s" in err


def test_model_file_lacking_the_fits_delay_refused(tmp_path):
    from i2ris_calib.hysteresis.codec import model_to_dict
    from i2ris_calib.hysteresis.effects import add_effect

    P = _fit_json(tmp_path / "fit.json", kinds=("egpi",))
    base = model_from_params("egpi", P, 30, 2.0)
    delayed = add_effect(base, "time_delay", {"tau_s": 0.15})
    (tmp_path / "final_model.json").write_text(json.dumps(model_to_dict(base)))  # no delay
    doc = json.loads((tmp_path / "fit.json").read_text())
    rec = dict(doc["datasets"][0]["models"]["egpi"])
    rec["params"] = {p.name: p.value for p in delayed.parameters}
    doc["datasets"][0]["models"]["diagnosed"] = rec
    (tmp_path / "fit.json").write_text(json.dumps(doc))
    pd.DataFrame({"time_s": [0.0, 0.01, 0.02], "yaw_deg": [15.0, 15.1, 15.2]}).to_csv(
        tmp_path / "t.csv", index=False
    )
    with pytest.raises(CalibError, match="does not match .* has time_delay.tau_s") as exc:
        compensate_files([tmp_path / "fit.json"], ["yaw+"], tmp_path / "t.csv",
                         tmp_path / "c.csv", model="diagnosed",
                         model_file=tmp_path / "final_model.json")  # fmt: skip
    assert "\n" not in str(exc.value) and not (tmp_path / "c.csv").exists()


def test_signed_fit_compensated_and_dataset_chosen(tmp_path):
    from dataclasses import replace

    from i2ris_calib.commands.fit import fit_files
    from i2ris_calib.io.config_io import load_config

    rng = np.random.default_rng(3)
    t = np.arange(0, 60, 1 / 30)
    enc = np.round(3000 * np.sin(2 * np.pi * t / 20))  # through zero
    truth = model_from_params("gpi", gpi_values(paper_like_params("yaw+")))
    theta = forward(truth, enc, t) + rng.normal(0, 0.02, t.size)
    pd.DataFrame({"time_s": t, "enc_yaw": enc, "yaw_deg": theta}).to_csv(
        tmp_path / "s.csv", index=False
    )
    cfg = load_config(None)
    cfg = replace(cfg, fit=replace(cfg.fit, signed=True))
    fit_files([tmp_path / "s.csv"], "yaw", "gpi", tmp_path / "fit", cfg)
    fit_doc = json.loads((tmp_path / "fit" / "fit.json").read_text())
    assert fit_doc["datasets"][0]["max_input_rate_counts_per_s"] > 0
    tt = np.arange(0, 20, 0.02)
    target = forward(truth, np.round(2500 * np.sin(2 * np.pi * tt / 10)), tt)
    pd.DataFrame({"time_s": tt, "yaw_deg": target}).to_csv(tmp_path / "t.csv", index=False)
    doc = compensate_files([tmp_path / "fit" / "fit.json"], None, tmp_path / "t.csv",
                           tmp_path / "c.csv", max_counts_per_s=float("inf"))  # fmt: skip
    rec = doc["axes"]["yaw"]
    assert rec["dataset"] == "yaw±" and rec["model"] == "gpi"
    df = pd.read_csv(tmp_path / "c.csv")
    assert (df["enc_yaw"] < 0).any() and (df["enc_yaw"] > 0).any()
    achieved = forward(truth, df["enc_yaw"].to_numpy(float), df["time_s"].to_numpy())
    assert np.sqrt(np.mean((achieved - target) ** 2)) < 0.3


def test_stepping_model_flagged_in_summary_and_warnings(tmp_path, capsys):
    # the paper EGPI on a target that falls through v_f again and again (the continuous
    # EGPI's output), under a rate limit: each reversal below v_f switches its shown
    # family and its output steps (the kernel's status says rate_limit there)
    P = _fit_json(tmp_path / "fit.json", rate=5000.0)
    t = np.arange(0, 10, 0.01)
    v = 3500 + 2000 * np.sin(2 * np.pi * 0.3 * t)
    y = forward(model_from_params("egpi_c", P, 30, 2.0), v)
    pd.DataFrame({"time_s": t, "yaw_deg": y}).to_csv(tmp_path / "t.csv", index=False)
    code = main(["compensate", str(tmp_path / "fit.json"), "--dataset", "yaw+", "--model",
                 "egpi", "--target", str(tmp_path / "t.csv"), "--out",
                 str(tmp_path / "c.csv")])  # fmt: skip
    assert code == 0
    text = capsys.readouterr().out
    doc = json.loads((tmp_path / "compensate.json").read_text())["axes"]["yaw"]
    n = doc["flags"]["output_step"]
    assert n > 0
    (warn,) = [w for w in doc["warnings"] if "steps at v_f" in w]
    score = {r["model"]: f"{r['score_deg']:.3g}" for r in doc["ranking"]}
    df = pd.read_csv(tmp_path / "c.csv", keep_default_na=False)
    target = pd.read_csv(tmp_path / "t.csv")["yaw_deg"].to_numpy()
    at = df["flags"].str.contains("output_step").to_numpy()[-target.size :]
    miss = np.max(np.abs(df["predicted_yaw_deg"].to_numpy()[-target.size :] - target)[at])
    assert warn == (  # the forced model steps: the others ranked to name the continuous ones
        f"egpi steps at v_f where the target passes ({n} samples flagged output_step, "
        f"missing the target by up to {miss:.3g} deg there); "
        f"gpi ({score['gpi']} deg) or egpi_c ({score['egpi_c']} deg) track it without steps "
        f"(predicted tracking error; egpi {score['egpi']} deg): --model gpi"
    )
    assert doc["model"] == "egpi" and doc["model_choice"] == "--model"
    assert warn in text
    df = pd.read_csv(tmp_path / "c.csv", keep_default_na=False)
    assert df["flags"].str.contains("output_step").sum() == n
    # ranked: the stepping EGPI after the continuous models, named in the warning
    doc = compensate_files([tmp_path / "fit.json"], ["yaw+"], tmp_path / "t.csv",
                           tmp_path / "c.csv")  # fmt: skip
    rows = {r["model"]: r for r in doc["axes"]["yaw"]["ranking"]}
    assert not rows["egpi"]["continuous"] and rows["egpi"]["output_steps"] == n
    assert rows["egpi"]["rank"] == 3 and doc["axes"]["yaw"]["model"] != "egpi"


def test_ranking_steps_double_the_score_not_last_whatever_the_error():
    from i2ris_calib.compensation.choice import rank_models

    class Res:  # a CompensationResult's summary and flags: n samples, `steps` output steps
        def __init__(self, rmse, steps, n=600):
            self.rmse, self.n = rmse, n
            self.flags = {"output_step": np.arange(n) < steps, "spike_removed": np.zeros(n, bool)}

        def summary(self):
            flags = {k: int(v.sum()) for k, v in self.flags.items()}
            return {"rmse_deg": self.rmse, "n_samples": self.n, "flags": flags}

    holdout = {"gpi": 5.75, "agpi_coupled": 0.41, "egpi": 5.0}
    rows = rank_models(
        {"gpi": Res(0.003, 0), "agpi_coupled": Res(0.004, 15), "egpi": Res(0.003, 30)}, holdout
    )
    assert [r["model"] for r in rows] == ["agpi_coupled", "gpi", "egpi"]
    assert rows[0]["rank_score_deg"] == pytest.approx(2 * rows[0]["score_deg"])
    assert not rows[0]["continuous"] and rows[1]["continuous"]


# ---------------------------------------------------------------- issue 33: numbers kept


def test_epoch_clock_target_times_written_exactly(files):
    """A target on an epoch clock (~1.7e9 s, 5 Hz): every row of COMMANDS.csv keeps its
    own time (``%.10g`` wrote whole seconds: 2216 rows, 23 distinct times)."""
    tmp, _ = files
    t = 1.7e9 + 0.123 + np.arange(0, 60, 0.2)
    target = pd.DataFrame({"time_s": t, "yaw_deg": 14 + 8 * np.sin(t - t[0])})
    target.to_csv(tmp / "epoch.csv", index=False, float_format="%.17g")
    doc = compensate_files([tmp / "fit.json"], ["yaw+"], tmp / "epoch.csv", tmp / "c.csv",
                           max_counts_per_s=5000.0)  # fmt: skip
    df = pd.read_csv(tmp / "c.csv")
    n_pre = df["time_s"].size - t.size
    assert doc["axes"]["yaw"]["n_entry"] <= n_pre
    assert df["time_s"].nunique() == df["time_s"].size
    np.testing.assert_array_equal(df["time_s"].to_numpy()[n_pre:], t)
    assert np.all(np.diff(df["time_s"]) > 0)


@pytest.mark.parametrize(
    ("write", "match"),
    [
        (lambda p: p.write_text("time_s,yaw_deg\n0,5\n0.1,6\n", encoding="utf-16"),
         "not a readable CSV"),
        (lambda p: p.write_bytes(b""), "not a readable CSV"),
        (lambda p: None, "target file not found"),
    ],
)  # fmt: skip
def test_unreadable_target_without_dataset_is_one_line(files, capsys, write, match):
    """Without --dataset the target's header is read to choose the datasets: a UTF-16
    or empty file was an internal UnicodeDecodeError / EmptyDataError there."""
    tmp, _ = files
    write(tmp / "bad.csv")
    code = main(["compensate", str(tmp / "fit.json"), "--target", str(tmp / "bad.csv"),
                 "--out", str(tmp / "o" / "c.csv")])  # fmt: skip
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.startswith("error:") and "\n" not in err
    assert match in err and "bad.csv" in err and "internal" not in err
    assert not (tmp / "o").exists() or not any((tmp / "o").iterdir())


def test_epoch_seconds_target_read_as_ms_refused(files):
    """--time-unit-s 0.001 on an epoch-second 5 Hz target would pace it at 5 kHz."""
    tmp, _ = files
    t = 1.7e9 + np.arange(0, 60, 0.2)
    pd.DataFrame({"time_s": t, "yaw_deg": 14 + 8 * np.sin(t - t[0])}).to_csv(
        tmp / "epoch.csv", index=False, float_format="%.17g"
    )
    with pytest.raises(CalibError, match=r"1970-01-20 at 5000 Hz; as epoch s .* at 5 Hz") as exc:
        compensate_files([tmp / "fit.json"], ["yaw+"], tmp / "epoch.csv", tmp / "c.csv",
                         time_unit_s=0.001)  # fmt: skip
    assert "--time-unit-s" in str(exc.value) and "\n" not in str(exc.value)
    assert not (tmp / "c.csv").exists()


@pytest.mark.parametrize(
    "extra",
    [["--max-counts-per-s", "1e-9"], ["--max-counts-per-s", "1e-6", "--conditioning", "sweep"]],
    ids=["entry", "sweep"],
)
def test_absurd_rate_limit_is_one_line_not_a_memory_error(files, capsys, extra):
    """'internal error: MemoryError: Unable to allocate 610 TiB' before."""
    tmp, _ = files
    code = main(["compensate", str(tmp / "fit.json"), "--dataset", "yaw+", "--target",
                 str(tmp / "target.csv"), "--out", str(tmp / "o" / "c.csv"), *extra])  # fmt: skip
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.startswith("error:") and "\n" not in err, err
    assert "--max-counts-per-s" in err and "yaw+ fit's input range 0..6000" in err
    assert "give a rate limit of at least 0.03 counts/s" in err
    assert not (tmp / "o").exists() or not any((tmp / "o").iterdir())
