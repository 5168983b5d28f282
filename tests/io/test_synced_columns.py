"""A lab's own export read as a synced CSV: ``[columns]`` / ``--columns`` (issue 20, item 5).

The lab file has its own headers (``Img TS, Enc TS, Encoder counts 0, Encoder counts
1, yaws, pitches``), an epoch clock and 5 Hz samples; ``fit`` reads it through the
column mapping, at full time precision, and fits it down to the noise.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from i2ris_calib.cli import main
from i2ris_calib.errors import CalibError
from i2ris_calib.hysteresis.models import gpi_model
from i2ris_calib.hysteresis.presets import gpi_values, loading_trajectory, paper_like_params
from i2ris_calib.io.config_io import load_config
from i2ris_calib.io.synced import read_synced

NOISE_DEG = 0.3
RATE_HZ = 5.0
EPOCH_S = 1_700_000_000.0
MAPPING = (
    "time_s=Img TS,enc_yaw=Encoder counts 0,enc_pitch=Encoder counts 1,"
    "yaw_deg=yaws,pitch_deg=pitches"
)


def lab_frame(seed: int = 7, n_cycles: int = 5, speed_counts_s: float = 1350.0) -> pd.DataFrame:
    """A lab-style export at 5 Hz (~250 rows for 5 cycles): yaw out and back five times
    (the paper's yaw+ GPI, tracker noise NOISE_DEG), the pitch motor moving meanwhile
    (pitch- GPI), times in seconds since 1970, an unused encoder-clock column."""
    rng = np.random.default_rng(seed)
    t, yaw_enc = loading_trajectory(
        rng, n_cycles=n_cycles, rate_hz=RATE_HZ, speed_counts_s=speed_counts_s
    )
    _, pitch_v = loading_trajectory(
        rng, n_cycles=n_cycles + 2, rate_hz=RATE_HZ, speed_counts_s=1.7 * speed_counts_s
    )
    pitch_v = np.resize(pitch_v, t.size)
    yaw = gpi_model().evaluate_dict(yaw_enc, gpi_values(paper_like_params("yaw+")))
    pitch = -gpi_model().evaluate_dict(pitch_v, gpi_values(paper_like_params("pitch-")))
    return pd.DataFrame(
        {
            "Img TS": EPOCH_S + t,
            "Enc TS": EPOCH_S + t - 0.013,
            "Encoder counts 0": yaw_enc.astype(int),
            "Encoder counts 1": (-pitch_v).astype(int),
            "yaws": yaw + rng.normal(0.0, NOISE_DEG, t.size),
            "pitches": pitch + rng.normal(0.0, NOISE_DEG, t.size),
        }
    )


@pytest.fixture(scope="module")
def lab_csv(tmp_path_factory):
    path = tmp_path_factory.mktemp("lab") / "lab export.csv"
    lab_frame().to_csv(path, index=False, float_format="%.6f")
    return path


def _error(capsys, args: list[str]) -> str:
    """The one error line of a failing command (exit status 2)."""
    capsys.readouterr()
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error:") and "\n" not in err, err
    return err


def test_fit_reads_a_lab_export_through_columns(lab_csv, tmp_path, capsys):
    """5 Hz, ~250 rows, epoch seconds, the lab's headers: fit at the noise, times exact."""
    out = tmp_path / "fit"
    assert (
        main(["fit", str(lab_csv), "--axis", "yaw", "--columns", MAPPING, "--out", str(out)]) == 0
    )
    capsys.readouterr()
    doc = json.loads((out / "fit.json").read_text())
    (yaw,) = doc["datasets"]
    n = len(pd.read_csv(lab_csv))
    assert 240 <= n <= 260 and yaw["name"] == "yaw+" and yaw["rows"]["total"] == n
    assert yaw["rows"]["holdout"] > 0
    gpi = yaw["models"]["gpi"]
    assert 0.7 * NOISE_DEG <= gpi["metrics"]["rmse_deg"] <= 1.3 * NOISE_DEG
    assert gpi["holdout_metrics"]["rmse_deg"] <= 1.5 * NOISE_DEG
    for rec in yaw["models"].values():
        assert rec["holdout_metrics"]["rmse_deg"] <= 2.0 * NOISE_DEG
    # the mapping used is the effective configuration the outputs record
    assert doc["provenance"]["config"]["columns"]["enc_yaw"] == "Encoder counts 0"
    # epoch times counted from the first sample without rounding: 0.2 s steps, exactly
    pred = pd.read_csv(out / "predictions.csv")
    t = pred.loc[pred["dataset"] == "yaw+", "time_s"].to_numpy()
    assert t[0] == 0.0 and np.abs(np.diff(t) - 1.0 / RATE_HZ).max() < 1e-9


def test_config_columns_section_with_ms_and_radians(tmp_path):
    """[columns] in the config TOML: integer epoch ms (time_unit_s) and radians."""
    lab = lab_frame()
    lab["Img TS"] = np.round(lab["Img TS"] * 1000).astype(np.int64)
    lab["yaws"] = np.deg2rad(lab["yaws"])
    lab["pitches"] = np.deg2rad(lab["pitches"])
    csv = tmp_path / "lab_ms_rad.csv"
    lab.to_csv(csv, index=False, float_format="%.12g")
    toml = tmp_path / "lab.toml"
    toml.write_text(
        '[columns]\ntime_s = "Img TS"\nenc_yaw = "Encoder counts 0"\n'
        'enc_pitch = "Encoder counts 1"\nyaw_deg = "yaws"\npitch_deg = "pitches"\n'
        'time_unit_s = 0.001\nangle_unit = "rad"\n'
    )
    cfg = load_config(toml)
    df = read_synced(csv, "yaw", cfg.columns)
    assert list(df.columns) == ["time_s", "enc_yaw", "enc_pitch", "yaw_deg", "pitch_deg"]
    assert df["time_s"].dtype == np.float64
    assert np.abs(np.diff(df["time_s"].to_numpy()) - 0.2).max() < 1e-12
    assert df.attrs["time_origin_s"] == pytest.approx(EPOCH_S, abs=1e-3)
    np.testing.assert_allclose(df["yaw_deg"], np.rad2deg(lab["yaws"]), rtol=1e-9)
    np.testing.assert_array_equal(df["enc_pitch"], lab["Encoder counts 1"])


def test_epoch_nanoseconds_keep_full_precision(tmp_path):
    """Integer ns stamps: the first is subtracted in integers before any float."""
    t_ns = 1_700_000_000_123_456_789 + np.arange(300) * 200_000_001
    df = pd.DataFrame(
        {"stamp": t_ns, "enc_yaw": np.round(3000 * np.sin(np.arange(300) / 9.0)), "yaw_deg": 0.0}
    )
    csv = tmp_path / "ns.csv"
    df.to_csv(csv, index=False)
    from i2ris_calib.io.columns import ColumnsConfig

    got = read_synced(csv, "yaw", ColumnsConfig(time_s="stamp", time_unit_s=1e-9))
    # 1 ns resolved (float64 seconds since 1970 would be off by up to 1.2e-7 s)
    np.testing.assert_allclose(np.diff(got["time_s"].to_numpy()), 0.200000001, rtol=0, atol=1e-12)
    assert got["time_s"].iloc[0] == 0.0


def test_epoch_ms_without_time_unit_names_the_setting(tmp_path):
    lab = lab_frame()
    lab["Img TS"] = np.round(lab["Img TS"] * 1000).astype(np.int64)
    csv = tmp_path / "ms.csv"
    lab.to_csv(csv, index=False)
    from i2ris_calib.io.columns import parse_columns_option

    with pytest.raises(CalibError, match=r"look like ms; set time_unit_s = 0\.001") as exc:
        read_synced(csv, "yaw", parse_columns_option(MAPPING))
    assert "'Img TS'" in str(exc.value) and "\n" not in str(exc.value)


@pytest.mark.parametrize(
    "columns, needles",
    [
        # an unknown key: the closest valid one suggested (the config loader's did-you-mean)
        (
            MAPPING.replace("enc_yaw=", "enc_yw="),
            ["--columns", "'enc_yw'", "did you mean 'enc_yaw'"],
        ),
        (MAPPING + ",time_unit=0.001", ["'time_unit'", "did you mean 'time_unit_s'"]),
        # a mapped column the file does not have: the file, the column, its columns
        (
            MAPPING.replace("Encoder counts 0", "Encoder count 0"),
            [
                "lab export.csv",
                "no column 'Encoder count 0'",
                "enc_yaw",
                "'Img TS', 'Enc TS', 'Encoder counts 0', 'Encoder counts 1', 'yaws', 'pitches'",
                "did you mean 'Encoder counts 0'?",
            ],
        ),
        (MAPPING + ",status=Track OK", ["lab export.csv", "no column 'Track OK'", "status"]),
        ("time_s=Img TS,yaws", ["'yaws' is not KEY=VALUE"]),
        (MAPPING + ",time_unit_s=ms", ["time_unit_s=ms is not a number"]),
        (MAPPING + ",angle_unit=radians", ["angle_unit = 'radians'", '"deg" or "rad"']),
        (
            MAPPING.replace("Encoder counts 1", "Encoder counts 0"),
            ["enc_yaw and enc_pitch both read column 'Encoder counts 0'"],
        ),
    ],
    ids=[
        "unknown-key",
        "unknown-unit-key",
        "column-not-in-file",
        "status-not-in-file",
        "not-key-value",
        "time-unit-not-number",
        "angle-unit",
        "one-column-twice",
    ],
)
def test_bad_mapping_is_one_line(lab_csv, tmp_path, capsys, columns, needles):
    out = tmp_path / "out"
    err = _error(
        capsys, ["fit", str(lab_csv), "--axis", "yaw", "--columns", columns, "--out", str(out)]
    )
    for needle in needles:
        assert needle in err, (needle, err)
    assert not out.exists()


def test_diagnose_takes_columns(lab_csv, tmp_path, capsys):
    """diagnose reads through the same mapping (a wrong name fails before any work)."""
    bad = MAPPING.replace("=yaws", "=yaw")
    out = tmp_path / "diag"
    err = _error(
        capsys, ["diagnose", str(lab_csv), "--axis", "yaw", "--columns", bad, "--out", str(out)]
    )
    assert "no column 'yaw'" in err and "did you mean 'yaws'?" in err
    assert not out.exists()


def test_config_unknown_columns_key_suggests_closest(tmp_path):
    toml = tmp_path / "bad.toml"
    toml.write_text('[columns]\nyaw_degs = "yaws"\n')
    with pytest.raises(CalibError, match=r"unknown key 'yaw_degs'; did you mean 'yaw_deg'\?"):
        load_config(toml)


def test_option_overrides_config_key_by_key(lab_csv, tmp_path):
    from dataclasses import replace

    from i2ris_calib.io.columns import ColumnsConfig
    from i2ris_calib.io.synced import with_columns

    cfg = load_config()
    cfg = replace(cfg, columns=ColumnsConfig(time_s="Img TS", yaw_deg="yaws"))
    eff = with_columns(cfg, "enc_yaw=Encoder counts 0,enc_pitch=Encoder counts 1")
    assert eff.columns.time_s == "Img TS" and eff.columns.enc_yaw == "Encoder counts 0"
    assert read_synced(lab_csv, "yaw", eff.columns)["enc_yaw"].iloc[-1] == 0.0
    with pytest.raises(CalibError, match="missing column"):  # the standard names
        read_synced(lab_csv, "yaw")


@pytest.mark.parametrize(
    "status, needles",
    [
        ("Enc TS", ["'Enc TS' (status)", "not tracking statuses", "map status"]),
        ("flag", ["'flag' (status)", "'ok' x", "not tracking statuses"]),
    ],
)
def test_status_mapped_to_a_column_without_measured_says_why(lab_csv, tmp_path, capsys,
                                                              status, needles):  # fmt: skip
    """A status column with no row 'measured' leaves no angle: say so, not '0 usable
    samples for 7 free parameters'."""
    csv = tmp_path / "flagged.csv"
    pd.read_csv(lab_csv).assign(flag="ok").to_csv(csv, index=False, float_format="%.6f")
    out = tmp_path / "o"
    err = _error(capsys, ["fit", str(csv), "--axis", "yaw", "--columns",
                          f"{MAPPING},status={status}", "--out", str(out)])  # fmt: skip
    assert "no row of" in err and "reads 'measured'" in err and "usable samples" not in err
    for needle in needles:
        assert needle in err, err
    assert not out.exists()


def test_status_never_measured_names_the_tracking(tmp_path):
    t = np.arange(0, 20, 0.05)
    enc = np.round(3000 * (1 - np.cos(t)))
    csv = tmp_path / "s.csv"
    pd.DataFrame({"time_s": t, "enc_yaw": enc, "yaw_deg": enc / 200, "status": "not_found"}).to_csv(
        csv, index=False
    )
    with pytest.raises(CalibError, match="'not_found' x400.*tracking measured no frame"):
        read_synced(csv, "yaw")


def test_too_little_motion_states_the_minimum(tmp_path, capsys):
    """Fewer than [fit] min_block_samples per direction: the counts, the minimum, and
    the minimum in seconds at the file's own rate."""
    short = lab_frame(n_cycles=2, speed_counts_s=6000.0)
    csv = tmp_path / "short.csv"
    short.to_csv(csv, index=False, float_format="%.6f")
    err = _error(capsys, ["fit", str(csv), "--axis", "yaw", "--columns", MAPPING])
    assert "fewer than 50 samples leave the zero band of enc_yaw" in err
    assert "needs at least 50 ([fit] min_block_samples, 10 s of motion at 5 Hz)" in err


def test_sample_lab_export_reads_with_its_config():
    """sample_data/datasets/lab_export.csv (a lab's two-motor export: its own column
    names, epoch times, 5 Hz) through configs/columns.lab.toml: standard columns, time
    from the first sample, the angles as exported (its truth file beside it)."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    cfg = load_config(root / "configs" / "columns.lab.toml")
    path = root / "sample_data" / "datasets" / "lab_export.csv"
    df = read_synced(path, "pitch", cfg.columns)
    raw = pd.read_csv(path)
    truth = pd.read_csv(root / "sample_data" / "datasets" / "lab_export_truth.csv")
    assert len(df) == len(raw) == len(truth) == 250
    assert df.attrs["time_origin_s"] == raw["Img TS"].iloc[0]
    np.testing.assert_allclose(df["time_s"], np.arange(250) * 0.2, atol=1e-9)
    np.testing.assert_array_equal(df["enc_yaw"], raw["Encoder counts 0"])
    np.testing.assert_array_equal(df["pitch_deg"], raw["pitches"])
    noise = (df["pitch_deg"] - truth["pitch_true_deg"]).std()
    assert 0.25 < noise < 0.35  # the export's 0.3 deg tracker noise


# ---------------------------------------------------------------- issue 33: units checked


def test_epoch_seconds_read_as_ms_refused_with_both_readings(lab_csv, tmp_path, capsys):
    """time_unit_s=0.001 on epoch seconds at 5 Hz made them 5 kHz (fit.json's rate x1000,
    compensate's default safety limit with it): refused naming both readings."""
    out = tmp_path / "fit"
    err = _error(capsys, ["fit", str(lab_csv), "--axis", "yaw", "--columns",
                          MAPPING + ",time_unit_s=0.001", "--out", str(out)])  # fmt: skip
    for needle in ("lab export.csv", "'Img TS'", "1970-01-20 at 5000 Hz", "2023-11-14 at 5 Hz",
                   "the unit is 1 s", "set time_unit_s"):  # fmt: skip
        assert needle in err, (needle, err)
    assert not out.exists()


def test_epoch_units_that_fit_are_accepted(tmp_path):
    """Epoch ms / ns given their unit, and a clock that is no epoch clock, still read."""
    from i2ris_calib.io.columns import ColumnsConfig
    from i2ris_calib.io.epoch import epoch_unit_problem

    assert epoch_unit_problem(1.7e12, 200.0, 1e-3) is None
    assert epoch_unit_problem(1.7e18, 2e8, 1e-9) is None
    assert epoch_unit_problem(1.7e9, 0.2, 1.0) is None
    assert epoch_unit_problem(5e5, 0.2, 1.0) is None  # seconds since boot: not an epoch
    assert "as epoch ms" in epoch_unit_problem(1.7e12, 200.0, 1.0)
    lab = lab_frame()
    lab["Img TS"] = np.round(lab["Img TS"] * 1e6).astype(np.int64)
    lab.to_csv(tmp_path / "us.csv", index=False)
    cols = ColumnsConfig(time_s="Img TS", enc_yaw="Encoder counts 0", yaw_deg="yaws",
                         time_unit_s=1e-6)  # fmt: skip
    df = read_synced(tmp_path / "us.csv", "yaw", cols)
    np.testing.assert_allclose(np.diff(df["time_s"]), 0.2, atol=1e-9)


def test_degrees_read_as_radians_refused(lab_csv, tmp_path, capsys):
    """angle_unit = "rad" on degree data: angles x57, fitted without a word before."""
    out = tmp_path / "fit"
    err = _error(capsys, ["fit", str(lab_csv), "--axis", "yaw", "--columns",
                          MAPPING + ",angle_unit=rad", "--out", str(out)])  # fmt: skip
    for needle in ("lab export.csv", "'yaws' (yaw_deg)", 'angle_unit = "rad"',
                   "beyond +-180 deg", 'set angle_unit = "deg"'):  # fmt: skip
        assert needle in err, (needle, err)
    assert not out.exists()
    yaws = pd.read_csv(lab_csv)["yaws"]
    k = int(yaws.abs().argmax())
    assert f"= {yaws[k]:.6g} at line {k + 2} is {np.rad2deg(yaws[k]):.5g} deg with" in err


def test_radians_of_unmeasured_rows_are_not_checked(tmp_path):
    """Only measured angles count: a tracker's placeholder on a lost row is no reason."""
    from i2ris_calib.io.columns import ColumnsConfig

    lab = lab_frame()
    lab["yaws"] = np.deg2rad(lab["yaws"])
    lab["status"] = "measured"
    lab.loc[3, ["yaws", "status"]] = [999.0, "lost"]
    lab.to_csv(tmp_path / "rad.csv", index=False)
    cols = ColumnsConfig(time_s="Img TS", enc_yaw="Encoder counts 0", yaw_deg="yaws",
                         angle_unit="rad")  # fmt: skip
    df = read_synced(tmp_path / "rad.csv", "yaw", cols)
    assert np.isnan(df["yaw_deg"].iloc[3]) and np.nanmax(np.abs(df["yaw_deg"])) < 180


@pytest.mark.parametrize("command", ["fit", "diagnose"])
@pytest.mark.parametrize("mapped", [False, True], ids=["standard", "columns"])
def test_header_only_synced_csv_is_one_line(tmp_path, capsys, command, mapped):
    """A synced CSV with its header and no row: an internal IndexError before."""
    csv = tmp_path / "empty.csv"
    if mapped:
        csv.write_text("Img TS,Enc TS,Encoder counts 0,Encoder counts 1,yaws,pitches\n")
        extra = ["--columns", MAPPING]
    else:
        csv.write_text("time_s,enc_yaw,enc_pitch,yaw_deg,pitch_deg,status\n")
        extra = []
    out = tmp_path / "out"
    err = _error(capsys, [command, str(csv), "--axis", "yaw", *extra, "--out", str(out)])
    assert "empty.csv" in err and "no samples" in err and "internal" not in err
    assert not out.exists()
