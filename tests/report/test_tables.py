"""Report tables against the truth written into synthetic run folders."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from runfolder import FLAGGED, N_FRAMES, write_fit

from i2ris_calib.report import tables


@pytest.fixture
def yaw_fit(tmp_path):
    return write_fit(tmp_path, "yaw")


def test_metrics_table_is_paper_shaped_and_shows_fit_json_numbers(yaw_fit):
    ds = tables.fit_datasets(yaw_fit)
    t = tables.metrics_table("yaw", ds)
    # Rows: EGPI_C, then the paper's order (EGPI before GPI), fitted then held-out.
    order = [
        ("egpi_c", "metrics"),
        ("egpi_c", "holdout_metrics"),
        ("egpi", "metrics"),
        ("egpi", "holdout_metrics"),
        ("gpi", "metrics"),
        ("gpi", "holdout_metrics"),
    ]
    assert [r[:2] for r in t.rows] == [
        (
            {"egpi_c": "EGPI_C", "egpi": "EGPI", "gpi": "GPI"}[m],
            "fitted" if k == "metrics" else "held-out",
        )
        for m, k in order
    ]
    assert sum(n for _, n in t.group_header) == len(t.header) == 2 + 3 * len(ds)
    assert [g for g, _ in t.group_header][1:] == ["yaw+", "yaw-"]
    assert "yaw-: input max(-enc, 0), angle -theta" in t.caption
    assert "*" not in t.caption and not any("*" in c for r in t.rows for c in r)
    for row, (model, split) in zip(t.rows, order, strict=True):
        for j, d in enumerate(ds):
            m = d["models"][model][split]
            cells = row[2 + 3 * j : 5 + 3 * j]
            assert cells == (
                f"{m['rmse_deg']:.3f}",
                f"{m['nrmse_pct']:.2f}",
                f"{m['max_abs_err_deg']:.3f}",
            )
    # Known construction: errors 0.4 / 0.2 / 1.2 sin(.) -> max abs 0.4 / 0.2 / 1.2 deg (+-2e-3),
    # RMS amplitude / sqrt(2) (whole periods on every split).
    for i, amp in ((0, 0.4), (2, 0.2), (4, 1.2)):
        for j in range(2):
            assert abs(float(t.rows[i][4 + 3 * j]) - amp) < 2e-3
            assert abs(float(t.rows[i + 1][2 + 3 * j]) - amp / np.sqrt(2)) < 2e-3


def test_not_converged_star_is_per_model_and_dataset_cell(yaw_fit):
    ds = tables.fit_datasets(yaw_fit)
    ds[0]["models"]["gpi"]["converged"] = False  # GPI yaw+ failed
    ds[1]["models"]["egpi"]["converged"] = False  # EGPI yaw- failed
    ds[1]["models"]["egpi_c"].pop("converged")  # unknown: not a failure
    t = tables.metrics_table("yaw", ds)
    starred = {
        (row[0], ds[j]["name"])
        for row in t.rows
        for j in range(2)
        if all(c.endswith("*") for c in row[2 + 3 * j : 5 + 3 * j])
    }
    assert starred == {("GPI", "yaw+"), ("EGPI", "yaw-")}
    # every other cell carries no star at all
    n_star = sum(c.endswith("*") for row in t.rows for c in row[2:])
    assert n_star == 2 * 2 * 3  # 2 cell groups x (fitted, held-out) x 3 metrics
    assert "* = that model's fit of that dataset did not converge" in t.caption
    # a star keeps the column right-aligned (numeric)
    from i2ris_calib.report.render import column_alignment

    assert column_alignment(t)[2:] == [True] * 6


def test_samples_table_from_fit_json_rows(yaw_fit):
    ds = tables.fit_datasets(yaw_fit)
    t = tables.samples_table("yaw", ds)
    assert t.header[:7] == (
        "dataset",
        "samples in recording",
        "own samples",
        "fitted",
        "held out",
        "not measured",
        "other direction",
    )
    for row, d in zip(t.rows, ds, strict=True):
        r = d["rows"]
        assert row[:7] == (
            d["name"],
            str(r["total"]),
            str(r["in_direction"]),
            str(r["fitted"]),
            str(r["holdout"]),
            str(r["angle_missing"]),
            str(r["total"] - r["in_direction"]),
        )
        assert row[7:] == ("5.000", "1.800 (derived)")
    # yaw+ lost 0.3 s of angles at 50 Hz (tests/report/runfolder.py): 15 samples
    assert t.rows[0][5] == "15" and t.rows[1][5] == "0"


def test_samples_table_falls_back_to_predictions(yaw_fit, tmp_path):
    ds = tables.fit_datasets(yaw_fit)
    truth = [dict(d["rows"]) for d in ds]
    for d in ds:
        del d["rows"], d["bands"]
    assert tables.samples_table("yaw", ds) is None
    pred = pd.read_csv(tmp_path / "fit" / "yaw" / "predictions.csv")
    by_name = {n: g for n, g in pred.groupby("dataset")}
    t = tables.samples_table("yaw", ds, by_name)
    for row, r in zip(t.rows, truth, strict=True):
        assert row[1:7] == tuple(
            str(x)
            for x in (
                r["total"],
                r["in_direction"],
                r["fitted"],
                r["holdout"],
                r["angle_missing"],
                r["total"] - r["in_direction"],
            )
        )
        assert row[7:] == (tables.DASH, tables.DASH)


class _Predicts:
    """A stand-in fit result: the model output is a known function of the input."""

    def __init__(self, gain: float) -> None:
        self.gain = gain

    def predict(self, signals):
        return self.gain * signals.v

    def eval_uncertainty(self, signals, sigma=1.0):  # predictions.csv's <model>_sd_deg
        return np.full(np.shape(signals.v), 0.01 * sigma)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rows_from_predictions_match_the_fit_stage_accounting(seed):
    """The report reads predictions.csv exactly as the fit stage counts its rows."""
    from i2ris_calib.data.dataset import direction_datasets
    from i2ris_calib.io.fit import predictions_frame

    rng = np.random.default_rng(seed)
    t = np.arange(0, 60, 0.02)
    enc = 3000 * np.sin(2 * np.pi * t / 12) + 5 * rng.standard_normal(t.size)
    enc[(t > 20) & (t < 22)] = 0.0  # a rest at zero (belongs to the excursion before it)
    angle = 0.01 * enc + 0.2 * rng.standard_normal(t.size)
    angle[rng.random(t.size) < 0.05] = np.nan  # unmeasured frames
    datasets = direction_datasets("yaw", t, enc, angle)
    assert [d.name for d in datasets] == ["yaw+", "yaw-"]
    fitted = [(d, {"gpi": _Predicts(0.01), "egpi": _Predicts(0.011)}) for d in datasets]
    pred = predictions_frame(fitted)
    for d in datasets:
        got = tables.rows_from_predictions(pred[pred["dataset"] == d.name])
        assert got == {**d.rows, "other": d.rows["total"] - d.rows["in_direction"]}
        assert got["angle_missing"] > 0 and got["holdout"] > 0 and got["other"] > 0
    # the "-" dataset's angle is -angle: |angle| on its own samples, up to the noise
    neg = pred[(pred["dataset"] == "yaw-") & (pred["split"] != "other")]
    big = np.abs(neg["v"]) > 500
    assert (neg["theta_deg"][big].dropna() > 0).all()


def test_metrics_table_with_one_model_and_null_metrics(yaw_fit):
    ds = tables.fit_datasets(yaw_fit)
    del ds[0]["models"]["egpi"], ds[1]["models"]["egpi"]
    ds[0]["models"]["gpi"]["holdout_metrics"] = {"rmse_deg": None, "nrmse_pct": None}
    del ds[0]["models"]["egpi_c"], ds[1]["models"]["egpi_c"]
    t = tables.metrics_table("yaw", ds)
    assert [r[0] for r in t.rows] == ["GPI", "GPI"]
    assert t.rows[1][2:5] == (tables.DASH,) * 3


def test_single_dataset_top_level_form():
    fit = {"axis": "pitch", "direction": "+", "models": {"gpi": {"metrics": {"rmse_deg": 1.0}}}}
    ds = tables.fit_datasets(fit)
    assert ds[0]["name"] == "pitch+" and ds[0]["models"] is fit["models"]
    assert tables.fit_datasets({"axis": "yaw"}) == []


def test_gpi_egpi_ratio(yaw_fit):
    d = tables.fit_datasets(yaw_fit)[0]
    g = d["models"]["gpi"]["holdout_metrics"]["rmse_deg"]
    e = d["models"]["egpi"]["holdout_metrics"]["rmse_deg"]
    assert tables.gpi_egpi_ratio(d) == pytest.approx(g / e, rel=1e-12)
    # 1.2 sin vs 0.2 sin over whole periods: ratio 6 within 1 %.
    assert tables.gpi_egpi_ratio(d) == pytest.approx(6.0, rel=0.01)
    d["models"]["egpi"]["holdout_metrics"]["rmse_deg"] = None
    assert tables.gpi_egpi_ratio(d) is None


def test_params_table_value_pm_stderr_in_words(yaw_fit):
    d = tables.fit_datasets(yaw_fit)[0]
    long_doc = "flag point: unloading switches to y2 at v <= v_f (fitted by profile search)"
    t = tables.params_table(d, {"a1": ("deg/count", "loading slope"), "v_f": ("count", long_doc)})
    labels = ("EGPI_C", "EGPI", "GPI")
    assert t.header == (
        "parameter",
        "unit",
        *(f"{m} (value ± stderr)" for m in labels),
        "meaning",
    )
    rows = {r[0]: r for r in t.rows}
    assert set(rows) == set(d["models"]["egpi"]["params"]) | set(d["models"]["gpi"]["params"])
    assert rows["a1"][1] == "deg/count" and rows["a1"][-1] == "loading slope"
    assert rows["a2"][1] == "" and rows["a2"][-1] == ""
    # stderr was written as 1 % of the value: value and stderr to the stderr's 2nd digit
    for j, key in enumerate(("egpi_c", "egpi", "gpi")):
        val = d["models"][key]["params"]["a1"]
        assert rows["a1"][2 + j] == tables.fmt_pm(val, 0.01 * val)
        v_txt, s_txt = rows["a1"][2 + j].split(" ± ")
        assert abs(float(v_txt) - val) <= 0.0051 * val and float(s_txt) == pytest.approx(
            0.01 * val, rel=0.05
        )
    # each model's last parameter has a null stderr: the profiled v_f says so, GPI's rn
    # is not identified; GPI has no kappa
    assert rows["v_f"][2].endswith("(profiled)") and rows["v_f"][3].endswith("(profiled)")
    assert rows["rn"][4].endswith("(not identified)")
    assert rows["kappa"][4] == tables.DASH
    # the long meaning is cut to its head and given whole in a footnote
    assert rows["v_f"][-1] == "flag point [1]"
    assert t.footnotes == (f"[1] v_f: {long_doc}",)


def test_params_table_fixed_and_unidentified(yaw_fit):
    d = tables.fit_datasets(yaw_fit)[0]
    rec = d["models"]["egpi"]
    rec["params"]["lam"], rec["stderr"]["lam"] = 0.0364, 0.0
    rec["params"]["a5"], rec["stderr"]["a5"] = 3.49926e-05, 0.163169
    rec["free"] = [n for n in rec["params"] if n != "lam"]
    rows = {r[0]: r for r in tables.params_table(d).rows}
    assert rows["lam"][3] == "0.0364 (fixed)"
    assert rows["a5"][3] == "0.00003 ± 0.16 (not identified)"
    assert tables.unidentified(d, "egpi") == ["a5"]
    # without a "free" list a zero stderr still means fixed
    del rec["free"]
    assert {r[0]: r for r in tables.params_table(d).rows}["lam"][3] == "0.0364 (fixed)"


def test_fit_info_table(yaw_fit):
    d = tables.fit_datasets(yaw_fit)[0]
    d["models"]["gpi"]["converged"] = False
    t = tables.fit_info_table(d)
    assert [r[0] for r in t.rows] == ["EGPI_C", "EGPI", "GPI"]
    assert [r[1] for r in t.rows] == ["yes", "yes", "no"]
    assert t.rows[1][2] == str(d["models"]["egpi"]["nfev"])


def _angles(status: list[str], err: list[float]) -> pd.DataFrame:
    n = len(status)
    return pd.DataFrame({"time_s": np.arange(n) * 0.1, "status": status, "reproj_err_px": err})


def test_tracking_summary_known_counts_and_error_stats():
    status = ["measured"] * N_FRAMES
    for s, idx in FLAGGED.items():
        for i in idx:
            status[i] = s
    n_meas = status.count("measured")
    err = np.full(N_FRAMES, np.nan)
    err[np.array(status) == "measured"] = np.linspace(0.1, 1.1, n_meas)
    # A huge error on a flagged frame must not count (measured frames only).
    err[FLAGGED["rejected"][0]] = 99.0
    s = tables.tracking_summary(_angles(status, list(err)))
    assert s["counts"] == {"measured": 555, "not_found": 30, "ambiguous": 10, "rejected": 5}
    assert s["detection_rate"] == pytest.approx(555 / 600, abs=1e-12)
    assert s["reproj_median_px"] == pytest.approx(0.6, abs=1e-9)
    assert s["reproj_p95_px"] == pytest.approx(1.05, abs=1e-9)
    assert s["reproj_max_px"] == pytest.approx(1.1, abs=1e-12)
    assert s["duration_s"] == pytest.approx(59.9, abs=1e-9)
    rows = dict(tables.tracking_table(s).rows)
    assert rows["detection rate (%)"] == "92.5"
    assert rows["frames not_found"] == "30 (5.0 %)"


def test_tracking_summary_unknown_status_and_no_error_column():
    a = pd.DataFrame({"time_s": [0.0, 1.0, 2.0], "status": ["measured", "occluded", "measured"]})
    s = tables.tracking_summary(a)
    assert s["counts"]["occluded"] == 1 and s["detection_rate"] == pytest.approx(2 / 3)
    assert math.isnan(s["reproj_median_px"])


@pytest.mark.parametrize(
    "record",
    [
        {"offset_s": 0.25, "offset_stderr_s": 4e-4},
        {"offset_s": 0.25, "offset_s_stderr": 4e-4},
        {"offset_s": 0.25, "stderr": {"offset_s": 4e-4}},
        {"offset_s": 0.25, "offset_std_s": 4e-4},
    ],
)
def test_find_stderr_naming_variants(record):
    assert tables.find_stderr(record, "offset_s") == 4e-4
    assert tables.find_stderr(record, "drift_ppm") is None


def test_sync_table():
    t = tables.sync_table(
        {
            "offset_s": 0.25,
            "drift_ppm": 15.0,
            "offset_stderr_s": 4e-4,
            "drift_stderr_ppm": 2.5,
            "method": "event",
        }
    )
    assert t.rows == (
        ("offset (s)", "0.250000", "0.000400"),
        ("drift (ppm)", "15.000", "2.500"),
        ("method", "event", ""),
    )


def test_fmt_and_flatten():
    assert tables.fmt(None) == tables.fmt(float("nan")) == tables.DASH
    assert tables.fmt(True) == "yes" and tables.fmt(np.int64(3)) == "3"
    assert tables.fmt(0.123456789) == "0.123457" and tables.fmt(2.0, 2) == "2.00"
    flat = tables.flatten(
        {"a": {"b": 1, "provenance": {"x": 1}}, "steps": [{"e": "x"}, {"e": "y"}], "l": [1, 2]}
    )
    assert flat == [("a.b", 1), ("steps.0.e", "x"), ("steps.1.e", "y"), ("l", [1, 2])]


def test_provenance_table_lists_every_input_hash():
    prov = {
        "version": "0.1.0",
        "python": "3.11",
        "inputs": {"a.csv": "ab" * 32, "b.mkv": "cd" * 32},
        "config": {"x": 1},
        "git": "abc",
    }
    rows = dict(tables.provenance_table("fit.json", prov).rows)
    assert (
        rows["input a.csv"] == "sha256 " + "ab" * 32
        and rows["input b.mkv"] == "sha256 " + "cd" * 32
    )
    assert rows["package version"] == "0.1.0" and rows["git"] == "abc"


def test_paper_table_mirrors_model_md():
    t = tables.paper_table("yaw")
    assert [g for g, _ in t.group_header] == ["", "yaw+ (paper)", "yaw- (paper)"]
    assert t.rows == (
        ("EGPI", "paper", "0.36", "0.98", "1.07", "0.35", "1.12", "1.15"),
        ("GPI", "paper", "2.23", "6.07", "4.88", "2.38", "7.50", "5.37"),
    )
    assert tables.paper_table("pitch").rows[1][2:] == (
        "2.51",
        "7.16",
        "6.73",
        "2.64",
        "8.38",
        "5.53",
    )
