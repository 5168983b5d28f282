"""Fitting against synthetic truth: recovery, masking, bad input, convergence flags."""

from __future__ import annotations

import math

import numpy as np
import pytest

from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.config import FitConfig
from i2ris_calib.fitting.fit import _Counter, _refine_profiled, fit_model
from i2ris_calib.fitting.pipeline import (
    fit_all,
    fit_kind,
    model_from_params,
    split_masks,
    unfitted_model,
)
from i2ris_calib.hysteresis.kernel import motion_direction
from i2ris_calib.hysteresis.models import as_signals, gpi_model, i2ris_egpi_model
from i2ris_calib.hysteresis.presets import GPI_NAMES, loading_trajectory, paper_like_params
from i2ris_calib.hysteresis.start import (
    FLAG_CANDIDATE_GAP,
    _flat_after_moving,
    flag_point,
    flag_point_candidates,
    start_values,
)

NOISE = 0.1  # deg, the noise of the egpi_data fixture (conftest.py)


@pytest.mark.parametrize("seed", [5, 6, 7])
def test_egpi_recovers_truth_to_noise_floor(seed):
    """Tolerances from the noise, over several seeds (robust across CPUs and BLAS builds):

    * fitted samples: the fit's RMSE is at most 1 % above the TRUE model's on the same
      samples (the optimiser reaches the truth's cost; it has more freedom, so usually
      ends below it);
    * held-out cycles: RMSE within 10 % of the noise sd, except samples whose error
      exceeds 5 sd: the paper's EGPI steps at v_f, and fitted data locate v_f only
      between two unloading samples, so a held-out sample in that gap gets the whole
      step (at most 1 % of the held-out samples).
    Measured (seeds 5-10): fit/truth RMSE 0.986-0.998; held-out 0.0997-0.1224 with
    0-2 gap samples of 0.8-1.4 deg.
    """
    rng = np.random.default_rng(seed)
    truth = paper_like_params("yaw+")
    _, v = loading_trajectory(rng, n_cycles=5, n_samples=3000)
    y = i2ris_egpi_model(deadband_counts=2.0).evaluate_dict(v, truth)
    theta = y + rng.normal(0, NOISE, v.size)
    res = fit_kind("egpi", v, theta)
    assert res.converged
    assert res.holdout_metrics.n_samples > 300
    err = res.predict(v) - theta
    truth_rmse = float(np.sqrt(np.mean((y - theta) ** 2)))
    assert res.metrics.rmse_deg <= 1.01 * truth_rmse
    h = holdout_of(res, v)
    e_h = np.abs(err[h])
    gap = e_h > 5 * NOISE
    assert gap.sum() <= 0.01 * h.sum()
    assert np.sqrt(np.mean(e_h[~gap] ** 2)) <= 1.1 * NOISE
    assert abs(res.params["v_f"] - truth["v_f"]) < 0.005 * 6000
    # invariants of the lam scale gauge are recovered (kappa is scale free)
    assert res.params["kappa"] == pytest.approx(truth["kappa"], rel=0.1)
    assert res.params["a5"] / res.params["a1"] == pytest.approx(truth["a5"] / truth["a1"], rel=0.05)
    # prediction on unseen input: the fitted model tracks the true model
    _, v2 = loading_trajectory(np.random.default_rng(99), n_cycles=3, n_samples=2000)
    err2 = res.predict(v2) - i2ris_egpi_model(deadband_counts=2.0).evaluate_dict(v2, truth)
    assert np.median(np.abs(err2)) < 0.5 * NOISE


def holdout_of(res, v):
    """The held-out mask the fit used (the one rule: fitting.pipeline.split_masks)."""
    return split_masks(v)[1]


def test_gpi_is_worse_on_two_stage_data(egpi_data):
    _, v, theta = egpi_data
    res = fit_all(v, theta)
    assert res["gpi"].holdout_metrics.rmse_deg > 2 * res["egpi"].holdout_metrics.rmse_deg
    assert res["gpi"].free == ("a1", "a2", "a3", "a4", "sigma", "r1", "rn")  # lam held (gauge)
    assert res["gpi"].stderr["lam"] == 0.0
    for k in res["gpi"].free:  # finite, or NaN when LM left the bounds and k was held there
        se = res["gpi"].stderr[k]
        assert (math.isfinite(se) and se > 0) or (math.isnan(se) and k in res["gpi"].message)
    assert res["egpi"].aic < res["gpi"].aic and res["egpi"].bic < res["gpi"].bic


def test_gpi_recovers_gpi_data(rng):
    t = paper_like_params("pitch+")
    _, v = loading_trajectory(rng, n_cycles=4, n_samples=1500)
    theta = gpi_model().evaluate_dict(v, {k: t[k] for k in GPI_NAMES}) + rng.normal(0, 0.05, v.size)
    res = fit_kind("gpi", v, theta)
    assert res.converged and res.metrics.rmse_deg <= 1.1 * 0.05
    cov = res.covariance
    assert cov.shape == (8, 8) and np.allclose(cov, cov.T) and np.all(cov[4] == 0)


def test_nan_angles_masked_not_dropped(egpi_data):
    truth, v, theta = egpi_data
    th = theta.copy()
    th[200:260] = np.nan  # a tracking gap: the input sequence stays intact
    model = i2ris_egpi_model(deadband_counts=2.0).with_fixed(fixed=("lam",))
    res = fit_model(model, v, th, starts=[model.vector(truth)])
    assert res.n_samples == v.size - 60
    assert np.isnan(res.residuals[200:260]).all()
    assert res.metrics.rmse_deg <= 1.1 * NOISE
    assert model.value_dict() == i2ris_egpi_model(deadband_counts=2.0).value_dict()  # not mutated


def test_bounded_trf_respects_bounds(egpi_data):
    _, v, theta = egpi_data
    model = gpi_model().with_fixed(fixed=("lam",)).with_bounds(r1=(0.0, 1.0), rn=(0.0, 6.0))
    res = fit_model(model, v[:1500], theta[:1500], method="trf", max_nfev=50)
    for p in res.model.parameters:
        assert p.lower <= p.value <= p.upper


def test_flag_point_from_data(egpi_data):
    truth, v, theta = egpi_data
    vf = flag_point(v, theta, motion_direction(v, 2.0))
    assert vf is not None and abs(vf - truth["v_f"]) < 0.03 * 6000


@pytest.mark.parametrize("seed", range(4))
def test_flag_point_from_the_stretches_that_come_down_from_the_top(seed):
    # sparse, noisy unloading stretches that turned below the flag point give spurious
    # estimates (egpi:153 of bench_optimum); only those from full scale cross it
    truth, top = paper_like_params("yaw+"), 6000.0
    peaks = [top, 0.6 * top, 0.55 * top, 0.5 * top, top]
    v = np.concatenate([np.r_[np.linspace(0, p, 50), np.linspace(p, 0, 50)] for p in peaks])
    v = v.round()
    y = i2ris_egpi_model(deadband_counts=2.0).evaluate_dict(v, truth)
    theta = y + np.random.default_rng(seed).normal(0, 0.4, v.size)
    vf = flag_point(v, theta, motion_direction(v, 2.0))
    assert truth["v_f"] > 0.6 * top and vf > 0.6 * top


def noisy_full_scale_cycles(seed: int):
    """(truth, top, v, clean angle, noisy angle): three full-scale EGPI cycles of a
    paper-like truth, 0.45 deg noise (egpi_c:4 of bench_optimum), dead band 2 counts."""
    truth, top = paper_like_params("yaw+"), 6000.0
    v = np.concatenate([np.r_[np.linspace(0, top, 500), np.linspace(top, 0, 500)]] * 3)
    v = v.round()
    y = i2ris_egpi_model(deadband_counts=2.0).evaluate_dict(v, truth)
    return truth, top, v, y, y + np.random.default_rng(seed).normal(0, 0.45, v.size)


@pytest.mark.parametrize("seed", range(4))
def test_flag_point_is_not_tripped_by_one_noisy_bin(seed):
    # full-scale cycles at 0.45 deg noise (egpi_c:4 of bench_optimum): the slope between
    # neighbouring 2 % bins dipped below 0.2 x the loading slope on one noisy bin above
    # the flag point (+0.11 to +0.15 of the range off on these seeds); the slope over
    # three bins reads the flat stretch below the flag point (-0.011)
    truth, top, v, _, theta = noisy_full_scale_cycles(seed)
    vf = flag_point(v, theta, motion_direction(v, 2.0))
    assert vf is not None and abs(vf - truth["v_f"]) < 0.03 * top


@pytest.mark.parametrize("seed", range(4))
def test_flag_point_candidates_are_both_readings(seed):
    # the same noisy full-scale cycles: the neighbouring-bin reading first (tripped by a
    # noisy bin: the start every earlier fit had), then the secant's (near the truth's)
    # as one more start; on clean data the two agree and one candidate is left
    truth, top, v, y, theta = noisy_full_scale_cycles(seed)
    d = motion_direction(v, 2.0)
    got = flag_point_candidates(v, theta, 2.0)
    assert len(got) == 2
    assert got[0] == flag_point(v, theta, d, runs=(1,))
    assert got[1] == flag_point(v, theta, d) and abs(got[1] - truth["v_f"]) < 0.03 * top
    assert abs(got[1] - got[0]) > FLAG_CANDIDATE_GAP * top
    assert len(flag_point_candidates(v, y, 2.0)) == 1


def test_egpi_starts_hold_both_flag_point_readings():
    """start_values: the data-driven start and the shape spread at the first reading,
    one more data-driven start at the second, last."""
    _, _, v, _, theta = noisy_full_scale_cycles(0)
    model = i2ris_egpi_model(deadband_counts=2.0)
    first, second = flag_point_candidates(v, theta, 2.0)
    starts = start_values(model, v, theta, 5, np.random.default_rng(1), 2.0)
    i = model.names.index("v_f")
    assert len(starts) == 6
    assert [x[i] for x in starts] == [first] * 5 + [second]


def test_flag_point_reads_a_flat_stretch_not_a_flat_bin():
    # bin means walking down (slopes x the loading slope between neighbouring bins):
    # slow after the reversal, moving, ONE flat bin (noise), moving, then flat from c=12
    step = np.r_[0.3, 0.3, 1.0, 0.1, 1.0, 1.0, 1.0, 1.0, 0, 0, 0, 0, 0, 1.0, 1.0, 1.0, 1.0]
    c = np.arange(step.size + 1, dtype=float)[::-1] + 3.0
    m = np.r_[0.0, -np.cumsum(step)]
    assert _flat_after_moving(c, m, 1.0) == 12.0  # neighbouring bins alone: 17.0
    # a flat part shorter than three bins is still found (secant over 2 bins)
    step = np.r_[0.3, 1.0, 1.0, 1.0, 0, 0, 1.0, 1.0, 1.0, 1.0]
    c = np.arange(step.size + 1, dtype=float)[::-1]
    m = np.r_[0.0, -np.cumsum(step)]
    assert _flat_after_moving(c, m, 1.0) == 6.0


@pytest.mark.parametrize(
    ("v", "theta", "match"),
    [
        (np.full(100, 5.0), np.linspace(0, 1, 100), "constant"),
        (np.linspace(0, 100, 100), np.linspace(0, 1, 99), "angle has"),
        (np.r_[np.linspace(0, 100, 99), np.nan], np.linspace(0, 1, 100), "NaN"),
        (np.linspace(0, 100, 100), np.r_[np.full(95, np.nan), np.ones(5)], "usable samples"),
    ],
)
def test_bad_input_one_line_errors(v, theta, match):
    with pytest.raises(CalibError, match=match) as exc:
        fit_model(gpi_model(), v, theta)
    assert "\n" not in str(exc.value)


def test_not_converged_is_flagged(egpi_data):
    _, v, theta = egpi_data
    res = fit_model(gpi_model().with_fixed(fixed=("lam",)), v, theta, max_nfev=2)
    assert not res.converged and res.message


def test_config_fixes_parameters(egpi_data):
    _, v, theta = egpi_data
    cfg = FitConfig(fixed_egpi=("lam", "kappa"), fit_flag_point=False, n_starts=1)
    m = unfitted_model("egpi", v, cfg)
    assert {p.name for p in m.parameters if p.fixed} == {"lam", "kappa", "v_f"}
    res = fit_kind("egpi", v, theta, cfg)
    assert res.params["kappa"] == m.value_dict()["kappa"]
    rebuilt = model_from_params("egpi", res.params, deadband_counts=res.model.deadband_counts)
    np.testing.assert_allclose(rebuilt(v), res.predict(v))
    with pytest.raises(ValueError, match="unknown"):
        FitConfig(fixed_gpi=("kappa",)).validate()


def test_lm_out_of_bounds_is_refitted_bounded(rng):
    """LM is unbounded: an end point outside the bounds is refitted bounded (trf) from inside."""
    t = paper_like_params("yaw+")
    _, v = loading_trajectory(rng, n_cycles=3, n_samples=1500)
    theta = gpi_model().evaluate_dict(v, {k: t[k] for k in GPI_NAMES}) + rng.normal(0, 0.05, v.size)
    lo = 2.0 * t["r1"]  # the truth lies below the lower bound
    model = gpi_model().with_fixed(fixed=("lam",)).with_bounds(r1=(lo, 10.0))
    res = fit_model(
        model, v, theta, starts=[model.vector({k: t[k] for k in GPI_NAMES} | {"r1": lo * 1.5})]
    )
    assert res.params["r1"] == pytest.approx(lo)
    assert "r1" in res.message and math.isnan(res.stderr["r1"]) and res.converged
    assert all(p.lower <= p.value <= p.upper for p in res.model.parameters)


def test_unidentified_parameters_get_nan_stderr(rng):
    """Loading only: the stage-2 envelope never acts, its stderr is NaN, the rest finite."""
    v = np.r_[np.zeros(20), np.linspace(0, 6000, 600)]
    t = paper_like_params("yaw+")
    theta = i2ris_egpi_model().evaluate_dict(v, t) + rng.normal(0, 0.1, v.size)
    model = i2ris_egpi_model().with_fixed(fixed=("lam", "r1", "rn", "sigma"))
    res = fit_model(model, v, theta, starts=[model.vector(t)])
    assert math.isnan(res.stderr["a5"]) and math.isnan(res.stderr["kappa"])
    assert math.isfinite(res.stderr["a1"]) and res.stderr["a1"] > 0


@pytest.mark.parametrize("seed", [11, 12, 13])
def test_robust_loss_resists_outliers(egpi_data, seed):
    """Tracking outliers (5 % of samples, +-8 deg = 80 noise sd) pull plain LS; soft_l1
    (trf) resists. Tolerance from the noise: the robust model stays within one noise sd
    (RMS over the whole input) of the true model, and closer to it than plain LS.
    Measured (seeds 11-16): robust 0.006-0.067 deg, plain 0.073-0.127 deg."""
    truth, v, theta = egpi_data
    rng = np.random.default_rng(seed)
    bad = theta.copy()
    idx = rng.choice(v.size, v.size // 20, replace=False)
    bad[idx] += rng.choice([-8.0, 8.0], idx.size)
    y_true = i2ris_egpi_model(deadband_counts=2.0).evaluate_dict(v, truth)

    def model_err(cfg):
        res = fit_kind("egpi", v, bad, cfg)
        return float(np.sqrt(np.mean((res.predict(v) - y_true) ** 2)))

    plain = model_err(FitConfig(n_starts=1))
    robust = model_err(FitConfig(n_starts=1, method="trf", loss="soft_l1", f_scale_deg=0.3))
    assert robust < NOISE and robust < plain
    with pytest.raises(ValueError, match="trf"):
        FitConfig(loss="huber").validate()


@pytest.mark.parametrize("shift", [-0.026, -0.005, 0.0, 0.006, 0.027])
def test_flag_point_profile_never_makes_the_fit_worse(shift):
    """The fine v_f profile tries the interval holding the current value and the ones
    just beyond its +-1 % window, and never returns a worse point (regression: it could
    step from the right interval to a neighbour, 0.14 -> 127 deg^2 on a rendered session).
    Coarse sampling (125 counts per sample, two phases 40 counts apart) makes intervals
    that reach beyond the window; shifts -0.026, -0.005, 0.006, 0.027 failed before."""
    rng = np.random.default_rng(3)
    truth = paper_like_params("yaw+")
    up = np.linspace(0, 6000, 49)
    up2 = np.clip(up + 40, 0, 6000)
    v = np.concatenate([up, up[::-1][1:], up2[1:], up2[::-1][1:]])
    model = i2ris_egpi_model(deadband_counts=2.0)
    theta = model.evaluate_dict(v, truth) + rng.normal(0, NOISE, v.size)
    counter = _Counter(model, as_signals(v), theta, np.isfinite(theta))
    x = model.vector(truth | {"v_f": truth["v_f"] + shift * 6000})
    lower = np.array([p.lower for p in model.parameters])
    upper = np.array([p.upper for p in model.parameters])
    pidx = [model.names.index("v_f")]
    before = counter.cost(x)
    after = counter.cost(_refine_profiled(counter, x, pidx, v, lower, upper, wide=False))
    assert after <= before * (1 + 1e-12)


def test_an_infinite_bound_is_never_reached():
    """``at its bound`` is for a finite bound the fit sits on: a parameter bounded only
    by +-inf is never "at its bound" (it used to be: inf - x <= 1e-6 * inf)."""
    from i2ris_calib.fitting.fit import _on_bound

    assert not _on_bound(5.0, -np.inf, np.inf)
    assert not _on_bound(5.0, 0.0, np.inf)
    assert _on_bound(6.67482e-10, 0.0, np.inf) and _on_bound(-1e-9, -np.inf, 0.0)
