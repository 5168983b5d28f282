"""``i2ris-calib fit``: synced CSV in, fit.json + predictions.csv out, one-line errors."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from i2ris_calib.cli import main
from i2ris_calib.hysteresis.models import i2ris_egpi_model
from i2ris_calib.hysteresis.presets import loading_trajectory, paper_like_params

NOISE = 0.1


def synced_frame(directions=("yaw+", "yaw-"), n=1500, seed=3) -> pd.DataFrame:
    """A session with yaw+ then yaw- blocks (pitch at rest), EGPI truth + noise."""
    rng = np.random.default_rng(seed)
    parts, t0 = [], 0.0
    for ds in directions:
        t, v = loading_trajectory(rng, n_cycles=4, n_samples=n, start_s=t0)
        y = i2ris_egpi_model(deadband_counts=2.0).evaluate_dict(v, paper_like_params(ds))
        y = y + rng.normal(0, NOISE, v.size)
        s = -1.0 if ds.endswith("-") else 1.0
        axis = ds[:-1]
        other = "pitch" if axis == "yaw" else "yaw"
        parts.append(
            pd.DataFrame(
                {
                    "time_s": t,
                    f"enc_{axis}": s * v,
                    f"enc_{other}": 0.0,
                    f"{axis}_deg": s * y,
                    f"{other}_deg": rng.normal(0, 0.05, v.size),
                    "status": "measured",
                    "frame": np.arange(v.size),
                }
            )
        )
        t0 = t[-1] + 1.0
    return pd.concat(parts, ignore_index=True)


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
        assert set(d["models"]) == {"gpi", "egpi"}
        for kind, m in d["models"].items():
            for key in ("params", "stderr", "metrics", "holdout_metrics", "aic", "bic", "converged",
                        "message", "nfev", "n_samples", "v_f"):  # fmt: skip
                assert key in m, (kind, key)
            assert set(m["metrics"]) == {"rmse_deg", "nrmse_pct", "max_abs_err_deg"}
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
        "dataset",
        "time_s",
        "v",
        "theta_deg",
        "gpi_deg",
        "egpi_deg",
        "split",
    ]
    assert set(pred["split"]) == {"fit", "holdout"}
    neg = pred[pred["dataset"] == "yaw-"]
    assert (neg["v"] > 0).all() and neg["theta_deg"].max() > 20  # |counts| -> |deg|
    # angles of rows not 'measured' and NaN angles are NaN in the yaw+ dataset
    in_pos = df["enc_yaw"] > 5
    expected = ((df["status"] != "measured") | df["yaw_deg"].isna())[in_pos].sum()
    assert (
        expected >= 10 and pred.loc[pred["dataset"] == "yaw+", "theta_deg"].isna().sum() == expected
    )
    ok = pred["theta_deg"].notna()
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
