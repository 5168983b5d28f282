"""Operator invariants (hypothesis): band, rate independence, wiping-out, monotonicity."""

from __future__ import annotations

import numpy as np
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hyst_reference import refine

from i2ris_calib.hysteresis.kernel import play_operators
from i2ris_calib.hysteresis.models import (
    continuous_egpi_model,
    density,
    gpi_model,
    i2ris_egpi_model,
    thresholds,
)
from i2ris_calib.hysteresis.presets import random_i2ris_egpi_params

inputs = st.lists(st.integers(0, 6000), min_size=2, max_size=60).map(
    lambda x: np.array(x, dtype=float)
)
seeds = st.integers(0, 2**31 - 1)
SETTINGS = settings(max_examples=60, deadline=None)


def _egpi(seed):
    vals = random_i2ris_egpi_params(np.random.default_rng(seed))
    return i2ris_egpi_model(deadband_counts=0.0, **vals)


@SETTINGS
@given(v=inputs, r=st.floats(0, 10), slope=st.floats(1e-3, 0.02), gap=st.floats(0, 5))
def test_operator_stays_in_envelope_band(v, r, slope, gap):
    """gamma_l(v) - r <= w <= gamma_r(v) + r at every sample when gamma_l <= gamma_r + 2r."""
    gl, gr = slope * v, slope * v + gap
    w = play_operators(v, slope, 0.0, np.array([r]), slope, gap, np.array([r]), np.ones(1))
    assert np.all(w >= gl - r - 1e-9)
    assert np.all(w <= gr + r + 1e-9)


@SETTINGS
@given(v=inputs, seed=seeds)
def test_rate_independence(v, seed):
    """Holding the input or adding monotone intermediate samples does not change the
    GPI/EGPI output at the original samples."""
    rng = np.random.default_rng(seed)
    fine, kept = refine(v, rng)
    for model in (gpi_model(), _egpi(seed)):
        np.testing.assert_allclose(model(fine)[kept], model(v), atol=1e-9)


@SETTINGS
@given(h1=inputs, h2=inputs, tail=inputs, seed=seeds)
def test_wiping_out(h1, h2, tail, seed):
    """After a new maximum far above and then a new minimum far below every earlier
    input, the output no longer depends on the earlier history (memory is wiped)."""
    sweep = np.array([20000.0, -14000.0])
    model = _egpi(seed)
    y1 = model(np.concatenate((h1, sweep, tail)))[h1.size + 2 :]
    y2 = model(np.concatenate((h2, sweep, tail)))[h2.size + 2 :]
    np.testing.assert_allclose(y1, y2, atol=1e-9)


@SETTINGS
@given(v=inputs, seed=seeds)
def test_monotone_on_a_monotone_branch(v, seed):
    """With increasing envelopes and positive weights, a rising input never lowers
    the GPI output and a falling one never raises it."""
    model = gpi_model().with_values(
        {
            k: x
            for k, x in random_i2ris_egpi_params(np.random.default_rng(seed)).items()
            if k in gpi_model().names
        }
    )
    up = np.concatenate((v, np.sort(np.random.default_rng(seed).uniform(v[-1], 6500, 30))))
    y = model(up)[v.size - 1 :]
    assert np.all(np.diff(y) >= -1e-9)
    down = np.concatenate((v, -np.sort(-np.random.default_rng(seed).uniform(-500, v[-1], 30))))
    y = model(down)[v.size - 1 :]
    assert np.all(np.diff(y) <= 1e-9)


def _egpi_c(seed):
    vals = random_i2ris_egpi_params(np.random.default_rng(seed))
    return continuous_egpi_model(**vals)


@SETTINGS
@given(v=inputs, seed=seeds)
def test_continuous_egpi_is_rate_independent(v, seed):
    """Holds and monotone intermediate samples (also ones landing near the flag point)
    leave the continuous EGPI's output at the original samples unchanged."""
    rng = np.random.default_rng(seed)
    fine, kept = refine(v, rng)
    model = _egpi_c(seed)
    np.testing.assert_allclose(model(fine)[kept], model(v), atol=1e-9)


@SETTINGS
@given(v=inputs, seed=seeds)
def test_continuous_egpi_nests_gpi(v, seed):
    """a5 = a3, a6 = a4, kappa = 1: one unloading boundary on both sides of v_f -> GPI."""
    vals = random_i2ris_egpi_params(np.random.default_rng(seed))
    vals |= {"a5": vals["a3"], "a6": vals["a4"], "kappa": 1.0}
    gpi = gpi_model(**{k: vals[k] for k in ("a1", "a2", "a3", "a4", "lam", "sigma", "r1", "rn")})
    np.testing.assert_allclose(continuous_egpi_model(**vals)(v), gpi(v), atol=1e-9)


@SETTINGS
@given(seed=seeds)
def test_continuous_egpi_has_no_step_at_the_flag_point(seed):
    """A finely sampled unloading ramp through v_f: the paper's EGPI may step by
    |y2 - y1| there; the continuous EGPI moves by at most what the boundaries allow for
    one input step (sum of weights x steepest boundary slope x 2 counts).

    Only where the stage-2 boundary starts at or above the stage-1 boundary at v_f
    (``gamma_r2(v_f) + kappa r >= gamma_r1(v_f) + r`` for every threshold): below it,
    operators in contact with the stage-1 boundary drop to the stage-2 one at v_f, a
    step of the output (e.g. seed 591: gap -0.95 deg at r = 0, step 0.041 deg)."""
    vals = random_i2ris_egpi_params(np.random.default_rng(seed))
    r = thresholds(vals["r1"], vals["rn"], 30)
    vf = vals["v_f"]
    gap = vals["a5"] * vf + vals["a6"] + vals["kappa"] * r - (vals["a3"] * vf + vals["a4"] + r)
    assume(gap.min() >= 0)
    v = np.r_[np.linspace(0, 6000, 3001), np.linspace(6000, 0, 3001)]
    y = continuous_egpi_model(**vals)(v)
    k = int(np.flatnonzero((v[:-1] > vals["v_f"]) & (v[1:] <= vals["v_f"]))[-1]) + 1
    p = density(thresholds(vals["r1"], vals["rn"], 30), vals["lam"], vals["sigma"])
    bound = p.sum() * max(vals["a1"], vals["a3"], vals["a5"]) * 2.0
    assert abs(y[k] - y[k - 1]) <= bound * (1 + 1e-9) + 1e-12
