"""Eq25-27 and the held-out split by loading cycles."""

from __future__ import annotations

import math

import numpy as np
import pytest

from i2ris_calib.data.cycles import cycle_index, holdout_mask
from i2ris_calib.fitting.metrics import information_criteria, metrics
from i2ris_calib.hysteresis.presets import loading_trajectory


def test_metrics_by_hand():
    theta = np.array([0.0, 10.0, 20.0, 40.0])
    pred = np.array([1.0, 9.0, 23.0, 40.0])
    m = metrics(theta, pred)
    rmse = math.sqrt((1 + 1 + 9 + 0) / 4)
    assert m.rmse_deg == pytest.approx(rmse)
    assert m.nrmse_pct == pytest.approx(rmse / 40 * 100)
    assert m.max_abs_err_deg == pytest.approx(3.0)  # MAXIMUM, not mean (Eq27)
    assert m.n_samples == 4


def test_metrics_nan_and_mask():
    theta = np.array([0.0, np.nan, 2.0, 4.0])
    pred = np.array([0.5, 100.0, 2.0, 3.0])
    m = metrics(theta, pred, mask=np.array([True, True, True, False]))
    assert m.n_samples == 2 and m.max_abs_err_deg == pytest.approx(0.5)
    assert m.nrmse_pct == pytest.approx(math.sqrt(0.125) / 2 * 100)
    # one sample's error beside the RMSE (issue 32): errors 0.5 and 0
    assert m.p99_abs_err_deg == pytest.approx(0.495) and m.rmse_without_worst_deg == 0.0
    empty = metrics(theta, pred, mask=np.zeros(4, bool))
    assert empty.n_samples == 0 and math.isnan(empty.rmse_deg)
    assert set(m.as_dict()) == {
        "rmse_deg",
        "nrmse_pct",
        "max_abs_err_deg",
        "explained_variance",
        "p99_abs_err_deg",
        "rmse_without_worst_deg",
    }


@pytest.mark.parametrize("n_cycles", [1, 3, 6])
def test_cycle_index_counts_cycles(rng, n_cycles):
    _, v = loading_trajectory(rng, n_cycles=n_cycles, rate_hz=15.0)
    cyc = cycle_index(v)
    assert cyc.max() + 1 == n_cycles
    assert np.all(np.diff(cyc) >= 0)
    # each cycle starts at a minimum of the input
    starts = np.flatnonzero(np.diff(cyc)) + 1
    assert np.all(v[starts] == 0)


def test_holdout_whole_cycles_never_first(rng):
    _, v = loading_trajectory(rng, n_cycles=8, rate_hz=10.0)
    cyc = cycle_index(v)
    hold = holdout_mask(cyc, 0.25)
    held = np.unique(cyc[hold])
    assert held.size == 2 and 0 not in held
    for c in held:  # whole cycles
        assert hold[cyc == c].all()
    assert not holdout_mask(np.zeros(50, int), 0.25).any()
    assert not holdout_mask(cyc, 0.0).any()


def test_holdout_never_extrapolates():
    """A cycle reaching beyond the input range of the other cycles is not held out."""
    v = np.r_[0, 100, 0, 50, 0, 200, 0, 80, 0].astype(float)
    cyc = np.r_[0, 0, 1, 1, 2, 2, 3, 3, 3]
    held = np.unique(cyc[holdout_mask(cyc, 0.5, v)])
    assert 2 not in held and 0 not in held and held.size >= 1
    # two cycles, the second the larger one: nothing can be held out
    assert not holdout_mask(np.r_[0, 0, 1, 1], 0.5, np.r_[0, 50, 0, 90.0]).any()


def test_holdout_holds_out_as_many_cycles_as_asked():
    """Evenly spread picks that round to one cycle still give k distinct cycles."""
    cycles = np.repeat(np.arange(4), 10)
    held = np.unique(cycles[holdout_mask(cycles, 0.5)])
    assert held.size == 2 and 0 not in held


def test_information_criteria_gaussian_formulas():
    rss, n, k = 12.5, 400, 7
    aic, bic = information_criteria(rss, n, k)
    assert aic == pytest.approx(n * math.log(rss / n) + 2 * k, rel=1e-12)
    assert bic == pytest.approx(n * math.log(rss / n) + k * math.log(n), rel=1e-12)
    # one more parameter that does not lower the RSS costs 2 (AIC) and ln n (BIC)
    aic2, bic2 = information_criteria(rss, n, k + 1)
    assert aic2 - aic == pytest.approx(2.0) and bic2 - bic == pytest.approx(math.log(n))
    # an exact fit stays finite
    assert all(math.isfinite(x) for x in information_criteria(0.0, n, k))
