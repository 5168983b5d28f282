"""``i2ris-calib fit``: synced CSV in, fit.json + predictions.csv out, one-line errors."""

from __future__ import annotations

import json
import re

import numpy as np
import pandas as pd
import pytest

from i2ris_calib.cli import main
from i2ris_calib.data.dataset import direction_of_samples, input_bands
from i2ris_calib.hysteresis.models import i2ris_egpi_model
from i2ris_calib.hysteresis.presets import loading_trajectory, paper_like_params

NOISE = 0.1


def synced_frame(directions=("yaw+", "yaw-"), n=1500, seed=3) -> pd.DataFrame:
    """A session with yaw+ then yaw- excursions (pitch at rest). Truth as the data layer
    defines it: each direction's EGPI over the whole history of its input
    (max(+-enc, 0)), the angle of a sample from the model of the direction it belongs to."""
    rng = np.random.default_rng(seed)
    times, encs, t0 = [], [], 0.0
    for ds in directions:
        t, v = loading_trajectory(rng, n_cycles=4, n_samples=n, start_s=t0)
        times.append(t)
        encs.append((-1.0 if ds.endswith("-") else 1.0) * v)
        t0 = t[-1] + 1.0
    t, enc = np.concatenate(times), np.concatenate(encs)
    axis = directions[0][:-1]
    other = "pitch" if axis == "yaw" else "yaw"
    model = i2ris_egpi_model(deadband_counts=2.0)
    d = direction_of_samples(enc, input_bands(enc).zero_band)
    y_pos = model.evaluate_dict(np.maximum(enc, 0), paper_like_params(f"{axis}+"))
    y_neg = model.evaluate_dict(np.maximum(-enc, 0), paper_like_params(f"{axis}-"))
    y = np.where(d >= 0, y_pos, -y_neg) + rng.normal(0, NOISE, enc.size)
    return pd.DataFrame(
        {
            "time_s": t,
            f"enc_{axis}": enc,
            f"enc_{other}": 0.0,
            f"{axis}_deg": y,
            f"{other}_deg": rng.normal(0, 0.05, enc.size),
            "status": "measured",
            "frame": np.arange(enc.size),
        }
    )


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    d = tmp_path_factory.mktemp("fit")
    df = synced_frame()
    df.loc[50:60, "status"] = "not_found"
    df.loc[70:75, "yaw_deg"] = np.nan
    df.to_csv(d / "synced.csv", index=False)
    rc = main(["fit", str(d / "synced.csv"), "--axis", "yaw", "--out", str(d / "out")])
    return rc, d / "out", df


def test_fit_json_contract(fitted):
    rc, out, _ = fitted
    assert rc == 0
    doc = json.loads((out / "fit.json").read_text())
    assert doc["schema"] == "i2ris-calib.fit/1" and doc["axis"] == "yaw"
    names = [d["name"] for d in doc["datasets"]]
    assert names == ["yaw+", "yaw-"]
    assert [d["abs_fitted"] for d in doc["datasets"]] == [False, True]
    assert "models" not in doc  # two datasets: no top-level shortcut
    for d in doc["datasets"]:
        assert set(d["models"]) == {"gpi", "egpi", "egpi_c"}
        rows = d["rows"]
        assert rows["total"] == len(fitted[2])  # every sample drives every model
        assert rows["fitted"] + rows["holdout"] + rows["angle_missing"] == rows["in_direction"]
        for kind, m in d["models"].items():
            for key in ("params", "stderr", "metrics", "holdout_metrics", "aic", "bic", "converged",
                        "message", "nfev", "n_samples", "v_f"):  # fmt: skip
                assert key in m, (kind, key)
            assert set(m["metrics"]) == {
                "rmse_deg", "nrmse_pct", "max_abs_err_deg", "explained_variance",
                "p99_abs_err_deg", "rmse_without_worst_deg",
            }  # fmt: skip
            assert isinstance(m["warnings"], list)
        eg = d["models"]["egpi"]
        # both directions recovered; 2x noise: at ~20 counts per sample one held-out sample
        # can fall between the fitted and the true flag point (the EGPI steps there)
        assert eg["holdout_metrics"]["rmse_deg"] <= 2 * NOISE
        assert eg["v_f"] is not None and d["models"]["gpi"]["v_f"] is None
    assert doc["provenance"]["inputs"]


def test_predictions_csv(fitted):
    _, out, df = fitted
    pred = pd.read_csv(out / "predictions.csv")
    assert list(pred.columns) == [
        "dataset", "time_s", "v", "theta_deg", "gpi_deg", "egpi_deg", "egpi_c_deg", "split",
        "gpi_sd_deg", "egpi_sd_deg", "egpi_c_sd_deg",
    ]  # fmt: skip
    # the 1-sd band of the model curve: positive and small against the data's noise
    # (3000+ samples pin the curve far better than one sample)
    sd = pred.loc[pred["split"] != "other", "egpi_sd_deg"]
    assert (sd.dropna() >= 0).all() and 0 < sd.median() < NOISE
    assert set(pred["split"]) == {"fit", "holdout", "other"}
    for name in ("yaw+", "yaw-"):  # the whole recording, in time order, in every dataset
        np.testing.assert_allclose(
            pred.loc[pred["dataset"] == name, "time_s"], df["time_s"], rtol=1e-9
        )
    neg = pred[pred["dataset"] == "yaw-"]
    np.testing.assert_allclose(neg["v"], np.maximum(-df["enc_yaw"], 0), rtol=1e-9)  # max(-enc, 0)
    own = neg["split"] != "other"
    assert (
        neg.loc[own, "theta_deg"].max() > 20
        and (neg.loc[own & (neg["v"] > 50), "theta_deg"] > 0).all()
    )
    # angles of rows not 'measured' and NaN angles are NaN
    pos = pred[pred["dataset"] == "yaw+"]
    expected = ((df["status"] != "measured") | df["yaw_deg"].isna()).sum()
    assert expected >= 10 and pos["theta_deg"].isna().sum() == expected
    ok = pred["theta_deg"].notna() & (pred["split"] != "other")
    err = (pred.loc[ok, "egpi_deg"] - pred.loc[ok, "theta_deg"]).to_numpy()
    assert np.sqrt(np.mean(err**2)) <= 1.2 * NOISE


def test_single_dataset_top_level(tmp_path):
    df = synced_frame(("pitch+",), n=1200)
    df.to_csv(tmp_path / "p.csv", index=False)
    assert (
        main(
            [
                "fit",
                str(tmp_path / "p.csv"),
                "--axis",
                "pitch",
                "--model",
                "egpi",
                "--out",
                str(tmp_path / "o"),
            ]
        )
        == 0
    )
    doc = json.loads((tmp_path / "o" / "fit.json").read_text())
    assert doc["direction"] == "+" and set(doc["models"]) == {"egpi"}
    pred = pd.read_csv(tmp_path / "o" / "predictions.csv")
    assert pred["gpi_deg"].isna().all() and pred["egpi_deg"].notna().all()


def _run_bad(tmp_path, capsys, df, *extra):
    p = tmp_path / "bad.csv"
    df.to_csv(p, index=False)
    rc = main(["fit", str(p), "--axis", "yaw", "--out", str(tmp_path / "o"), *extra])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert (
        err.startswith("error: ") and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    )
    assert not (tmp_path / "o" / "fit.json").exists()
    return err


def test_missing_columns(tmp_path, capsys):
    err = _run_bad(tmp_path, capsys, synced_frame(("yaw+",), n=300).drop(columns=["yaw_deg"]))
    assert "yaw_deg" in err


def test_nan_rows(tmp_path, capsys):
    df = synced_frame(("yaw+",), n=300)
    df.loc[10, "enc_yaw"] = np.nan
    assert "NaN" in _run_bad(tmp_path, capsys, df)


@pytest.mark.parametrize("kind", ["duplicate", "decreasing"])
def test_bad_time(tmp_path, capsys, kind):
    df = synced_frame(("yaw+",), n=300)
    df.loc[20, "time_s"] = df.loc[19, "time_s"] if kind == "duplicate" else df.loc[19, "time_s"] - 1
    assert kind in _run_bad(tmp_path, capsys, df)


def test_constant_input_and_no_motion(tmp_path, capsys):
    df = synced_frame(("yaw+",), n=300)
    df["enc_yaw"] = 0.0
    assert "no yaw motion" in _run_bad(tmp_path, capsys, df)
    df["enc_yaw"] = 500.0
    assert "constant" in _run_bad(tmp_path, capsys, df)


def test_too_few_samples(tmp_path, capsys):
    df = synced_frame(("yaw+",), n=300)
    df.loc[df.index[8:], "yaw_deg"] = np.nan
    assert "usable samples" in _run_bad(
        tmp_path, capsys, df, "--config", str(_cfg(tmp_path, "min_block_samples = 5"))
    )


def test_bad_model_option(tmp_path, capsys):
    assert "--model" in _run_bad(
        tmp_path, capsys, synced_frame(("yaw+",), n=300), "--model", "prandtl"
    )


def _cfg(tmp_path, line):
    p = tmp_path / "c.toml"
    p.write_text(f"[fit]\n{line}\n")
    return p


def test_outputs_checked_before_fitting(tmp_path, capsys):
    """Bad --out is refused at once (one line, exit 2), not after the fit."""
    synced_frame(directions=("yaw+",), n=600).to_csv(tmp_path / "s.csv", index=False)
    (tmp_path / "afile").write_text("x")
    (tmp_path / "o2" / "fit.json").mkdir(parents=True)
    for out, match in (
        (tmp_path / "afile", "is a file"),
        (tmp_path / "afile" / "sub", "is a file"),
        (tmp_path / "o2", "fit.json is a folder"),
    ):
        capsys.readouterr()
        rc = main(["fit", str(tmp_path / "s.csv"), "--axis", "yaw", "--out", str(out)])
        err = capsys.readouterr().err
        assert rc == 2 and match in err and err.count("\n") == 1, err
    assert not (tmp_path / "o2" / "predictions.csv").exists()


def test_angle_that_does_not_follow_its_input_is_flagged(tmp_path, capsys):
    """A yaw_deg column of noise fits with a small RMSE; fit.json and the terminal say
    the model explains nothing."""
    df = synced_frame(directions=("yaw+",), n=800)
    df["yaw_deg"] = np.random.default_rng(1).normal(0, 0.05, len(df))
    df.to_csv(tmp_path / "s.csv", index=False)
    rc = main(
        [
            "fit",
            str(tmp_path / "s.csv"),
            "--axis",
            "yaw",
            "--model",
            "gpi",
            "--out",
            str(tmp_path / "o"),
        ]
    )
    assert rc == 0
    rec = json.loads((tmp_path / "o" / "fit.json").read_text())["models"]["gpi"]
    assert rec["metrics"]["explained_variance"] < 0.9
    assert any("explains only" in w for w in rec["warnings"])
    assert "warning: yaw+ gpi: the model explains only" in capsys.readouterr().err
    assert any("check the axis, the columns" in w for w in rec["warnings"])


@pytest.mark.slow  # ~14 s (keeps the default run under 5 minutes)
def test_low_variance_warning_names_the_model_that_explains_the_angle(tmp_path, capsys):
    """Pitch following the yaw motor (a lab's two-motor recording, 5 Hz, 250 samples):
    the uncoupled models explain little of it, the coupled one nearly all; their
    warnings say so instead of sending the user to check the columns."""
    from i2ris_calib.simulation.two_motor import simulate_two_motor

    r = simulate_two_motor(7, n_samples=250, rate_hz=5.0, noise_deg=0.3, coupling=0.6)
    pd.DataFrame(
        {"time_s": r.t_s, "enc_yaw": np.round(r.enc_yaw), "enc_pitch": np.round(r.enc_pitch),
         "yaw_deg": r.yaw_deg, "pitch_deg": r.pitch_deg}
    ).to_csv(tmp_path / "s.csv", index=False)  # fmt: skip
    assert main(["fit", str(tmp_path / "s.csv"), "--axis", "pitch", "--out",
                 str(tmp_path / "o")]) == 0  # fmt: skip
    models = json.loads((tmp_path / "o" / "fit.json").read_text())["models"]
    ev = {k: m["metrics"]["explained_variance"] for k, m in models.items()}
    assert ev["agpi_coupled"] > 0.95 and ev["gpi"] < 0.9
    (w,) = [w for w in models["gpi"]["warnings"] if "explains only" in w]
    assert "check the axis" not in w
    assert f"agpi_coupled explains {100 * ev['agpi_coupled']:.0f} % of it" in w
    assert not any("explains only" in w for w in models["agpi_coupled"]["warnings"])
    assert "lacks what agpi_coupled models" in capsys.readouterr().err


@pytest.mark.parametrize("unit_per_count", [150.0 / 6000.0, 1e8])
def test_same_fit_whatever_the_input_unit(tmp_path, unit_per_count):
    """Volts or 1e12-scale inputs: same datasets, same held-out RMSE as counts."""
    df = synced_frame(directions=("yaw+",), n=800)
    scaled = df.copy()
    scaled["enc_yaw"] = df["enc_yaw"] * unit_per_count
    df.to_csv(tmp_path / "a.csv", index=False)
    scaled.to_csv(tmp_path / "b.csv", index=False)
    docs = []
    for name in ("a", "b"):
        out = tmp_path / f"o{name}"
        assert (
            main(
                [
                    "fit",
                    str(tmp_path / f"{name}.csv"),
                    "--axis",
                    "yaw",
                    "--model",
                    "egpi",
                    "--out",
                    str(out),
                ]
            )
            == 0
        )
        docs.append(json.loads((out / "fit.json").read_text()))
    ra, rb = (d["datasets"][0] for d in docs)
    assert ra["rows"] == rb["rows"]
    ha, hb = (d["models"]["egpi"]["holdout_metrics"]["rmse_deg"] for d in (ra, rb))
    # the same optimum up to the optimiser's tolerance (ftol 1e-7 on the cost)
    assert hb == pytest.approx(ha, rel=0.02) and hb < 1.2 * NOISE


def test_source_labels_are_the_shortest_distinguishing_paths():
    from i2ris_calib.commands.fit import source_labels

    runs = ["/r/s1/sync/synced.csv", "/r/s2/sync/synced.csv", "/r/s1/sync/synced.csv"]
    assert source_labels(runs) == {
        "/r/s1/sync/synced.csv": "s1/sync/synced.csv",
        "/r/s2/sync/synced.csv": "s2/sync/synced.csv",
    }
    assert source_labels(["/r/a.csv", "/r/b.csv"]) == {"/r/a.csv": "a.csv", "/r/b.csv": "b.csv"}
    assert source_labels(["/r/x.csv"]) == {"/r/x.csv": "x.csv"}


def test_same_file_name_in_two_folders_gets_one_table_per_file(tmp_path, capsys, monkeypatch):
    # was: one table with four "yaw+"/"yaw+ (synced)" column groups, squeezed into 80
    # columns until some columns were empty, and no way to tell which file was which
    monkeypatch.setenv("COLUMNS", "80")
    df = synced_frame(n=600)
    for folder in ("A", "B"):
        (tmp_path / folder).mkdir()
        df.to_csv(tmp_path / folder / "synced.csv", index=False)
    rc = main(["fit", str(tmp_path / "A" / "synced.csv"), str(tmp_path / "B" / "synced.csv"),
               "--axis", "yaw", "--model", "gpi", "--out", str(tmp_path / "o")])  # fmt: skip
    out = capsys.readouterr()
    assert rc == 0, out.err
    tables = out.out.split("yaw motor:")[1:]
    assert len(tables) == 2
    for folder, table in zip(("A", "B"), tables, strict=True):
        assert f"{folder}/synced.csv" in table
        # every column whole: yaw+ and yaw-, RMSE / NRMSE / max |error| each, two rows
        heads = [line.split("┃")[2:-1] for line in table.splitlines() if line.startswith("┃")]
        assert [[c.strip() for c in h] for h in heads] == [
            ["yaw+"] * 3 + ["yaw-"] * 3, ["RMSE", "NRMSE", "max |error|"] * 2
        ]  # fmt: skip
        assert len(re.findall(r"\b\d+\.\d\d\b", table)) == 12
    err = " ".join(out.err.split())
    assert "yaw+ [A/synced.csv]: " in err and "yaw- (synced) [B/synced.csv]: " in err


def test_table_title_names_the_models_fitted(tmp_path, capsys, monkeypatch):
    """A signed two-tendon fit is not titled "GPI and EGPI"; max |error|, not "MAE"."""
    monkeypatch.setenv("COLUMNS", "120")
    t = np.arange(0, 40, 0.05)
    enc = np.round(3000 * np.sin(2 * np.pi * t / 8))
    csv = tmp_path / "signed.csv"
    pd.DataFrame({"time_s": t, "enc_yaw": enc, "yaw_deg": enc / 200 + 0.3 * np.sign(np.cos(
        2 * np.pi * t / 8))}).to_csv(csv, index=False)  # fmt: skip
    rc = main(["fit", str(csv), "--axis", "yaw", "--model", "agpi", "--out", str(tmp_path / "o")])
    out = capsys.readouterr()
    assert rc == 0, out.err
    title = " ".join(out.out.split("yaw motor:")[0].split())
    assert title.endswith("two-tendon GPI,") and "EGPI" not in title, title
    assert "max |error|" in out.out and "MAE" not in out.out


def test_messages_print_brackets_verbatim(tmp_path, capsys):
    """The terminal's lines are plain text: "[fit] max_nfev" in a hint is printed as
    written (rich markup once ate "[fit]", leaving "--config  max_nfev")."""
    synced_frame(directions=("yaw+",), n=300).to_csv(tmp_path / "s.csv", index=False)
    cfg = _cfg(tmp_path, "max_nfev = 10\nmax_restarts = 0")
    code = main(["fit", str(tmp_path / "s.csv"), "--axis", "yaw", "--model", "gpi",
                 "--out", str(tmp_path / "o"), "--config", str(cfg)])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 0, err
    assert "try more starts or --config [fit] max_nfev" in err
