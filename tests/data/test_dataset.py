"""The data layer: whole input history, direction inputs, loss masks, bands."""

from __future__ import annotations

import numpy as np
import pytest

from i2ris_calib.data.dataset import (
    direction_datasets,
    direction_input,
    direction_of_samples,
    input_bands,
    make_dataset,
)
from i2ris_calib.fitting.config import FitConfig
from i2ris_calib.fitting.pipeline import fit_dataset_all
from i2ris_calib.hysteresis.models import i2ris_egpi_model
from i2ris_calib.hysteresis.presets import paper_like_params


def _excursions(levels, n_ramp=150, n_hold=40):
    """Signed input: 0 -> level -> 0 ramps (counts), a hold at 0 between them."""
    parts = [np.zeros(n_hold)]
    for lv in levels:
        up = np.linspace(0, lv, n_ramp)
        parts += [up, up[::-1], np.zeros(n_hold)]
    return np.round(np.concatenate(parts))


def test_direction_attribution_keeps_every_sample():
    enc = np.r_[np.zeros(10), np.arange(1, 101), np.zeros(30), -np.arange(1, 81), np.zeros(5)]
    d = direction_of_samples(enc, zero_band=0.0)
    assert d.size == enc.size and set(np.unique(d)) == {-1, 1}
    assert np.all(d[:10] == 1)  # before the first excursion: the first excursion's
    assert np.all(d[110:140] == 1)  # rest after "+": belongs to "+" (its residual angle)
    assert np.all(d[140:220] == -1) and np.all(d[220:] == -1)
    assert np.all(direction_of_samples(np.zeros(5), 0.0) == 0)


def test_direction_input_never_splices():
    enc = np.r_[0, 50, 100, 50, 0, -40, -80, -40, 0, 60, 0]
    plus, minus = direction_input(enc, "+"), direction_input(enc, "-")
    assert plus.size == minus.size == enc.size  # whole history
    np.testing.assert_array_equal(plus, np.maximum(enc, 0))
    np.testing.assert_array_equal(minus, np.maximum(-enc, 0))
    # consecutive inputs of a direction never jump by more than the signal itself did
    assert np.max(np.abs(np.diff(plus))) <= np.max(np.abs(np.diff(enc)))
    np.testing.assert_array_equal(direction_input(enc, "±"), enc)
    with pytest.raises(ValueError):
        direction_input(enc, "x")


def test_bands_do_not_depend_on_the_unit():
    enc = _excursions([6000, -5000, 5500])
    b_counts = input_bands(enc)
    b_volts = input_bands(enc * 150.0 / 6000.0)  # the same motion in volts
    assert b_volts.zero_band == pytest.approx(b_counts.zero_band * 150 / 6000)
    assert b_volts.deadband == pytest.approx(b_counts.deadband * 150 / 6000)
    assert 1.0 <= b_counts.deadband <= 3.0  # ~2 counts on a 6000-count range


def test_dataset_masks_and_sign_convention(rng):
    enc = _excursions([6000, -5000, 5500, -6000, 4000, -4500])
    theta = np.sign(enc) * np.abs(enc) * 0.006 + rng.normal(0, 0.05, enc.size)
    theta[7] = np.nan  # not measured
    t = np.arange(enc.size) * 0.01
    minus = make_dataset("yaw", "-", t, enc, theta, holdout_fraction=0.0)
    assert minus.n_samples == enc.size and minus.name == "yaw-"
    mine = minus.in_direction
    assert np.all(np.isnan(minus.theta_deg[~mine]))  # other direction: out of the loss
    np.testing.assert_allclose(minus.theta_deg[mine & (enc < 0)], -theta[mine & (enc < 0)])
    assert np.all(minus.theta_deg[enc < -50] > 0)  # |angle|, the paper's convention
    assert minus.rows["total"] == enc.size and minus.rows["holdout"] == 0
    assert minus.rows["fitted"] == int(np.isfinite(minus.theta_deg).sum())
    plus = make_dataset("yaw", "+", t, enc, theta, holdout_fraction=0.25)
    assert plus.holdout.any() and not (plus.holdout & ~plus.in_direction).any()
    # the two directions share no sample and together cover every one
    assert not (plus.in_direction & minus.in_direction).any()
    assert (plus.in_direction | minus.in_direction).all()


def test_min_samples_and_signed():
    enc = _excursions([6000, 5000])
    theta = enc * 0.006
    t = np.arange(enc.size) * 0.01
    ds = direction_datasets("pitch", t, enc, theta)
    assert [d.name for d in ds] == ["pitch+"]
    signed = direction_datasets("pitch", t, enc, theta, signed=True)
    assert [d.name for d in signed] == ["pitch±"] and signed[0].in_direction.all()
    assert direction_datasets("pitch", t, enc, theta, min_samples=10**6) == []


def test_whole_history_fit_reaches_the_noise_floor(rng):
    """Truth EGPI per direction with holds at zero between excursions of both signs:
    fitted on the whole history (no splice), the held-out RMSE is at the noise."""
    sigma = 0.1
    enc = _excursions([6000, -5500, 5000, -6000, 5800, -4800, 6000, -5600, 5400, -5900])
    tp, tm = paper_like_params("yaw+"), paper_like_params("yaw-")
    model = i2ris_egpi_model(deadband_counts=2.0)
    y = model.evaluate_dict(np.maximum(enc, 0), tp) - model.evaluate_dict(np.maximum(-enc, 0), tm)
    # the robot's angle: each direction's own model on its own samples
    d = direction_of_samples(enc, input_bands(enc).zero_band)
    y = np.where(
        d > 0,
        model.evaluate_dict(np.maximum(enc, 0), tp),
        -model.evaluate_dict(np.maximum(-enc, 0), tm),
    )
    theta = y + rng.normal(0, sigma, enc.size)
    t = np.arange(enc.size) * 0.01
    for data in direction_datasets("yaw", t, enc, theta):
        res = fit_dataset_all(data, FitConfig(), kinds=("gpi", "egpi"))["egpi"]
        # tolerance: 1.2 sigma (fitted parameters absorb a little noise; held-out cycles
        # of ~1000 samples scatter by ~3 % around sigma)
        assert res.holdout_metrics.rmse_deg <= 1.2 * sigma, data.name
        assert res.holdout_metrics.max_abs_err_deg <= 6 * sigma, data.name
