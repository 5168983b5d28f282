"""The held-out evidence: the z-test's false-positive rate, cycles, residual location."""

from __future__ import annotations

import numpy as np
import pytest

from i2ris_calib.data.cycles import cycle_index
from i2ris_calib.data.dataset import make_dataset
from i2ris_calib.diagnosis.cycles import dataset_cycles, holdout_units, loading_mask
from i2ris_calib.diagnosis.locate import concentration_sentences, residual_analysis
from i2ris_calib.diagnosis.report import diagnosis_markdown, not_excluded_sentence, step_verdict
from i2ris_calib.diagnosis.results import SEPARATING_FROM_BASE, Alternative, separating_experiment
from i2ris_calib.diagnosis.stats import autocovariance, sse_reduction_z
from i2ris_calib.model import Signals


def _ar1(rng, n, phi, sigma):
    e = rng.normal(0, sigma, n)
    out = np.empty(n)
    out[0] = e[0]
    for k in range(1, n):
        out[k] = phi * out[k - 1] + e[k]
    return out


@pytest.mark.parametrize("phi", [0.0, 0.7])
def test_z_test_false_positive_rate_is_at_most_alpha(phi):
    """Under H0 (residual before = noise, possibly autocorrelated) a smooth
    prediction change is 'significant' at alpha = 5 % in at most ~5 % of draws."""
    rng = np.random.default_rng(5)
    n, hits, trials = 600, 0, 400
    t = np.linspace(0, 1, n)
    for _ in range(trials):
        noise = _ar1(rng, n, phi, 0.2)
        delta = 0.02 * np.sin(2 * np.pi * rng.uniform(1, 5) * t + rng.uniform(0, 6))
        gamma = autocovariance(_ar1(rng, n, phi, 0.2), max_lag=50)
        _, p = sse_reduction_z(noise, delta, gamma)
        hits += p < 0.05
    assert hits / trials <= 0.08  # 5 % nominal; binomial sd over 400 draws ~1.1 %


def test_z_test_detects_a_real_improvement():
    rng = np.random.default_rng(6)
    n = 600
    misfit = 0.1 * np.sin(np.linspace(0, 20, n))
    r_before = misfit + rng.normal(0, 0.2, n)
    gamma = autocovariance(rng.normal(0, 0.2, n), 50)
    z, p = sse_reduction_z(r_before, misfit, gamma)
    assert z > 3 and p < 1e-3


def test_units_are_the_held_out_cycles_of_the_one_segmentation():
    """Units come from data.cycles (the cycles the held-out mask was drawn from):
    2 held-out cycles of 6 are 2 units, halved until there are at least 6."""
    t = np.arange(0, 60, 0.05)
    v = np.round(3000 * (1 - np.cos(2 * np.pi * t / 10)))
    data = make_dataset("yaw", "+", t, v, 0.005 * v, holdout_fraction=0.34)
    cyc = dataset_cycles(data.v)
    np.testing.assert_array_equal(cyc, cycle_index(data.v))
    assert cyc.max() == 5
    held = np.unique(cyc[data.holdout])
    assert held.size == 2 and 0 not in held
    assert np.unique(holdout_units(cyc, data.holdout, min_units=2)).tolist() == [-1, *held]
    units = holdout_units(cyc, data.holdout, min_units=6)
    assert np.unique(units[units >= 0]).size == 8
    assert (units >= 0).sum() == data.holdout.sum()  # every held-out sample in a unit
    for u in np.unique(units[units >= 0]):  # a unit never spans two cycles
        assert np.unique(cyc[units == u]).size == 1


def test_loading_mask_is_the_models_v_prime():
    v = np.concatenate([np.linspace(0, 10, 11), np.linspace(9, 2, 8), np.linspace(3, 12, 10)])
    up = loading_mask(v, 0.5)
    assert up[:11].all() and not up[11:19].any() and up[19:].all()


def test_residual_analysis_locates_branch_rate_and_lag():
    t = np.arange(0, 60, 0.02)
    v = 1000 * (1 - np.cos(2 * np.pi * t / 10))
    rate = np.gradient(v, t)
    loading = loading_mask(v, 1.0)
    # residual only on the unloading branch, proportional to the rate 0.5 s earlier
    lagged = np.interp(t - 0.5, t, rate)
    res = np.where(rate < 0, 1e-3 * lagged, 0.0)
    sig = Signals(v=v, t_s=t, v_other=np.zeros_like(t), theta_other_deg=np.sin(t))
    a = residual_analysis(res, sig, loading, max_lag_s=1.0)
    assert a["by_branch"]["unloading"]["sse_share"] > 0.9
    assert abs(a["xcorr_input"]["peak_rate_lag_s"] - 0.5) <= 0.1
    text = " ".join(concentration_sentences(a))
    assert "unloading branch" in text and "lag +0.5" in text


@pytest.mark.parametrize("n", [1, 2, 40])
def test_residual_analysis_of_a_series_shorter_than_the_largest_lag(n):
    """1 kHz for ``n`` samples with a 1 s largest lag: the lags stay inside the series
    (a lag of the whole series was a shape error), no correlation on one sample."""
    t = np.arange(n) * 1e-3
    v = np.sin(40 * t) * 100
    res = np.random.default_rng(n).normal(0, 0.1, n)
    a = residual_analysis(res, Signals(v=v, t_s=t), loading_mask(v, 1.0), max_lag_s=1.0)
    lags = [row["lag_s"] for row in a["xcorr_input"]["lags"]]
    assert all(abs(lag) < n * 1e-3 for lag in lags)
    assert 0.0 in lags
    if n == 1:
        assert np.isnan(a["xcorr_input"]["peak_rate_corr"])
    assert concentration_sentences(a)


def test_time_windows_cover_only_the_counted_samples():
    # a pre-history (or burn-in) before the recording: NaN residual, times before 0
    t = np.linspace(-5.0, 10.0, 1501)
    v = 100.0 * np.sin(t)
    res = np.where(t < 0.0, np.nan, 0.1 * np.sin(3.0 * t))
    a = residual_analysis(res, Signals(v=v, t_s=t), loading_mask(v, 1.0))
    windows = a["by_time"]
    assert windows[0]["t_lo_s"] == pytest.approx(0.0, abs=0.01)
    assert windows[-1]["t_hi_s"] == pytest.approx(10.0)
    assert all(w["n"] > 0 for w in windows)


def test_markdown_section_from_a_record():
    m = {"fit_rmse_deg": 0.2, "holdout_rmse_deg": 0.21, "bic": -10.0, "n_free": 12}
    ev = {
        "rel_improvement": 0.5,
        "z": 9.0,
        "p_value": 1e-9,
        "units_improved": 5,
        "n_units": 6,
        "delta_bic": -50.0,
        "significant": True,
    }
    rec = {
        "axis": "pitch",
        "start": "egpi",
        "baseline": m | {"holdout_rmse_deg": 0.42},
        "final": m,
        "named_effects": ["creep"],
        "figures": ["a.png", "b.png"],
        "notes": [],
        "steps": [
            {
                "effect": "creep",
                "meaning": "slow",
                "params": {"gain": 0.2, "tau_s": 1.0},
                "location_before": ["x"],
                "holdout_rmse_before_deg": 0.42,
                "holdout_rmse_after_deg": 0.21,
                "delta_bic": -50.0,
                "evidence": ev,
                "candidates": [
                    {"effect": "creep", "fit": "global", "metrics": m, "evidence": ev},
                    {"effect": "axis_coupling", "skipped": "no other axis"},
                ],
                "figures": {"before": "a.png", "after": "b.png"},
            }
        ],
        "location_final": ["y"],
        "last_candidates": [],
    }
    md = diagnosis_markdown(rec)
    assert md.startswith("## Model diagnosis (pitch)")
    assert "**creep**" in md and "0.42 -> 0.21 deg (50% lower)" in md
    assert "![residual after creep](b.png)" in md
    rows = [
        r for r in md.splitlines() if r.startswith("| creep |") or r.startswith("| axis_coupling |")
    ]
    assert len({r.count("|") for r in rows}) == 1  # skipped rows keep the table's columns


def test_verdict_names_the_open_alternatives_with_z_and_experiment():
    open_ = Alternative("backlash", 0.21, 0.8, 0.21, False, {"width_counts": 90.0})
    shut = Alternative("creep", 0.35, 6.0, 1e-9, True, {"gain": 0.1, "tau_s": 1.0})
    text = step_verdict("dead_zone", (open_, shut))
    assert text.startswith("dead_zone; backlash not excluded, z = 0.8")
    assert "creep" not in text
    assert step_verdict("dead_zone", (shut,)).endswith("left open by the held-out cycles")
    exp = separating_experiment("time_delay", "rate_dependent_thresholds")
    assert exp and exp == separating_experiment("rate_dependent_thresholds", "time_delay")
    with_exp = step_verdict(
        "time_delay", (Alternative("rate_dependent_thresholds", 0.2, 1.1, 0.14, False, {}, exp),)
    )
    assert "to separate rate_dependent_thresholds: a slow and a fast ramp" in with_exp


def test_summary_lists_what_the_data_cannot_tell_from_the_final_model():
    """Nothing named, a backlash absorbed by the base: the one-line answer says so with
    its fitted width, its size, z and why no recording of the angle separates it."""
    bl = Alternative(
        "backlash",
        0.085,
        -1.2,
        0.88,
        False,
        {"width_counts": 151.3},
        SEPARATING_FROM_BASE["backlash"],
        effect_rms_deg=0.37,
    )
    assert not_excluded_sentence(()) == ""
    text = not_excluded_sentence((bl,))
    assert text.startswith("backlash not excluded (width_counts = 151 moves the angle by 0.37 deg")
    assert "z = -1.2" in text and "envelope offsets" in text
    assert bl.as_dict()["effect_rms_deg"] == 0.37
