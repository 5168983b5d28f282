"""The recording's own limits (issue 32 items 3-4): noise, repeatability, model-free
baselines, the worst sample and cross-validation, against known synthetic truth."""

from __future__ import annotations

import math

import numpy as np
import pytest

from i2ris_calib.fitting.limits import (
    RecordingLimits,
    cv_folds,
    cycle_phase,
    is_periodic,
    line_baseline,
    noise_sd,
    phase_baseline,
    repeatability,
    verdict,
)


def test_noise_from_the_residuals_high_frequency_part():
    rng = np.random.default_rng(0)
    t = np.linspace(0, 50, 5000)
    smooth_misfit = 0.5 * np.sin(0.3 * t)  # a slow model error does not count
    r = smooth_misfit + rng.normal(0, 0.05, t.size)
    r[::7] = np.nan  # unmeasured samples break pairs, not the estimate
    assert noise_sd(r) == pytest.approx(0.05, rel=0.08)
    assert math.isnan(noise_sd(np.full(5, 0.1)))


def loops(n_cycles: int, jitter: float, noise: float, seed: int = 1, amp=None):
    """Input loops 0 -> 1000 -> 0 (one cycle each), angle = 0.01 v + per-cycle offset
    of sd ``jitter`` + noise; ``amp``: per-cycle amplitudes."""
    rng = np.random.default_rng(seed)
    amp = [1000.0] * n_cycles if amp is None else amp
    v = np.concatenate([a * np.r_[np.linspace(0, 1, 100), np.linspace(1, 0, 100)[1:]] for a in amp])
    cyc = np.repeat(np.arange(n_cycles), 199)
    offs = rng.normal(0, jitter, n_cycles)
    theta = 0.01 * v + offs[cyc] + rng.normal(0, noise, v.size)
    return v, theta, cyc


def test_repeatability_measures_the_spread_between_alike_cycles():
    v, theta, cyc = loops(6, jitter=0.2, noise=0.01)
    rep, n = repeatability(v, theta, cyc)
    assert n == 6 and 0.1 < rep < 0.35  # sd 0.2 of 6 draws
    v, theta, cyc = loops(6, jitter=0.0, noise=0.01)
    assert repeatability(v, theta, cyc)[0] < 0.01
    # loops of different amplitude are not compared (their branches differ by memory)
    v, theta, cyc = loops(3, jitter=0.2, noise=0.01, amp=[1000.0, 600.0, 300.0])
    rep, n = repeatability(v, theta, cyc)
    assert math.isnan(rep) and n == 1


def test_baselines_line_and_phase():
    rng = np.random.default_rng(2)
    v, _, cyc = loops(8, 0.0, 0.0)
    t = np.arange(v.size) * 0.01
    theta = 3.0 + 0.02 * v + rng.normal(0, 0.05, v.size)
    hold = cyc == 4
    fit = ~hold
    assert line_baseline(v, theta, fit, hold) == pytest.approx(0.05, rel=0.2)
    assert is_periodic(v, t, cyc)
    phase = cycle_phase(cyc, t)
    assert phase.min() == 0.0 and phase.max() < 1.0
    # a loop (hysteresis: the angle depends on the direction): no line can follow it,
    # a function of the phase can
    theta = 0.01 * v + 1.0 * np.sin(2 * np.pi * phase) + rng.normal(0, 0.05, v.size)
    rmse, k = phase_baseline(phase, theta, fit, hold)
    assert rmse < 0.08 and k >= 2
    assert line_baseline(v, theta, fit, hold) > 0.3
    assert not is_periodic(*loops(4, 0, 0, amp=[1000.0, 500.0, 900.0, 300.0])[::2], cyc[: 4 * 199])


def test_cross_validation_folds_are_inside_cycles_and_only_short_recordings():
    v, theta, cyc = loops(5, 0.0, 0.0)
    own = np.ones(v.size, bool)
    assert cv_folds(cyc, v, own) == [1, 2, 3, 4]  # never cycle 0 (it carries the start)
    v, theta, cyc = loops(12, 0.0, 0.0)
    assert cv_folds(cyc, v, np.ones(v.size, bool)) == []


def test_verdict_words_match_the_numbers():
    base = dict(model="egpi", noise_sd_deg=0.01, repeatability_deg=0.02, n_cycles_compared=3,
                line_rmse_deg=2.0, phase_rmse_deg=float("nan"), phase_harmonics=0)  # fmt: skip
    at = verdict(RecordingLimits(model_rmse_deg=0.025, **base))
    assert "at the limit of this recording" in at and "1.2x its floor" in at
    off = verdict(RecordingLimits(model_rmse_deg=0.2, **base))
    assert "leaves about 0.2 deg beyond" in off and "10x its floor" in off
    one = RecordingLimits(model_rmse_deg=0.19, worst_sample={"time_s": 20.0, "error_deg": -1.93},
                          without_worst_deg=0.0077, **base)  # fmt: skip
    assert "one sample carries much of it (t = 20 s, -1.9 deg" in verdict(one)
    assert "nan" not in (at + off + verdict(one)).lower()


def test_a_rest_off_the_loop_is_named_with_its_numbers():
    """Issue 32 item 5 (the piezo file): a 3 s rest at input 0 whose angle sits far
    from the loop's centre there is warned; a rest on the loop is not."""
    from i2ris_calib.fitting.limits import rest_anomalies

    rng = np.random.default_rng(3)
    v, _, cyc = loops(4, 0.0, 0.0)
    v = v - 500.0  # loops through 0
    theta = 0.01 * v + 0.3 * np.sign(np.gradient(v)) + rng.normal(0, 0.01, v.size)
    t = np.arange(v.size) * 0.01
    rest_v, rest_t = np.zeros(300), t[-1] + 0.01 * np.arange(1, 301)
    on = np.r_[theta, 0.3 + rng.normal(0, 0.01, 300)]  # on the falling branch
    off = np.r_[theta, -1.68 + rng.normal(0, 0.01, 300)]
    vv, tt = np.r_[v, rest_v], np.r_[t, rest_t]
    assert rest_anomalies(vv, on, tt, 0.01) == []
    (w,) = rest_anomalies(vv, off, tt, 0.01)
    assert w.startswith("a rest of 2.99 s at input 0 (t = ") and "sits at -1.68 deg, 1." in w
    lo = float(w.split("the loop's angles there (")[1].split(" to ")[0])
    assert -0.55 <= lo <= -0.25  # the falling branch near 0: -0.3 deg, slope and noise
    # the other motor moving during the "rest": coupling may move the angle, no warning
    other = np.r_[np.zeros(v.size), np.linspace(0, 2000, 300)]
    assert rest_anomalies(vv, off, tt, 0.01, other) == []
