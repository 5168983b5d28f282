"""The compiled kernels against independent references (tolerance 1e-9 deg)."""

from __future__ import annotations

import numpy as np
import pytest
from hyst_reference import gpi_reference, play_reference, triangle

from i2ris_calib.hysteresis.kernel import (
    density,
    motion_direction,
    play_numpy,
    play_operators,
    play_switched,
    select_stage,
    thresholds,
)
from i2ris_calib.hysteresis.models import (
    continuous_egpi_model,
    continuous_egpi_output,
    egpi_output,
    gpi_model,
    gpi_output,
    i2ris_egpi_model,
)
from i2ris_calib.hysteresis.presets import paper_like_params


def test_thresholds_eq14_and_density_eq15():
    """Eq14: r_0 = 0, r_i = r1 + (i - 1)(rn - r1)/(n - 1); Eq15: p = lam exp(-sigma r)."""
    r = thresholds(0.3, 3.0, 10)
    expected = [0.0] + [0.3 + (i - 1) * (3.0 - 0.3) / 9 for i in range(1, 11)]
    np.testing.assert_allclose(r, expected, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(thresholds(0.5, 9.0, 1), [0.0, 0.5])
    np.testing.assert_allclose(density(r, 0.06, 0.2), 0.06 * np.exp(-0.2 * np.array(expected)))
    with pytest.raises(ValueError, match="n must be >= 1"):
        thresholds(0.3, 3.0, 0)


def test_single_operator_matches_eq1_2(rng):
    v = np.round(rng.uniform(-50, 50, 400).cumsum() / 5)
    gl = lambda x: 0.3 * x + 1.0  # noqa: E731
    gr = lambda x: 0.25 * x - 2.0  # noqa: E731
    for r in (0.0, 0.7, 5.0):
        ref = play_reference(v, gl, gr, r, ml=1.0, mr=2.5)
        rl, rr = np.array([r]), np.array([2.5 * r])
        got = play_operators(v, 0.3, 1.0, rl, 0.25, -2.0, rr, np.ones(1))
        np.testing.assert_allclose(got, ref, atol=1e-9)
        np.testing.assert_allclose(play_numpy(v, gl(v), rl, gr(v), rr, np.ones(1)), ref, atol=1e-9)


def test_numba_equals_numpy_reference(rng):
    v = rng.normal(0, 30, 600).cumsum()
    v[100:120] = v[100]  # a hold
    r = np.linspace(0, 4, 31)
    p = 0.05 * np.exp(-0.2 * r)
    for a_l, b_l, a_r, b_r, rl, rr in (
        (0.02, 1.0, 0.03, -1.0, 2 * r, r),
        (0.1, 0, 0.1, 0, r, 3 * r),
    ):
        np.testing.assert_allclose(
            play_operators(v, a_l, b_l, rl, a_r, b_r, rr, p),
            play_numpy(v, a_l * v + b_l, rl, a_r * v + b_r, rr, p),
            atol=1e-9,
        )


def test_switched_play_reduces_to_play(rng):
    """With the same boundary on both sides of v_f (kappa = 1) the switched loop is the
    plain one, wherever v_f lies."""
    v = np.round(rng.normal(0, 40, 500).cumsum())
    r = np.linspace(0, 3, 11)
    p = np.exp(-0.3 * r)
    plain = play_operators(v, 0.01, 1.0, r, 0.011, -1.0, r, p)
    for v_f in (-np.inf, float(np.median(v)), float(v.max()) + 1):
        got = play_switched(v, 0.01, 1.0, 0.011, -1.0, 0.011, -1.0, r, 1.0, v_f, p)
        np.testing.assert_allclose(got, plain, atol=1e-12)


def test_egpi_output_is_eq20_of_the_two_families():
    """Eq20: y1 while loading, and while unloading above v_f; y2 unloading at v <= v_f,
    with y1, y2 the families of Eq16-19 on the envelopes of Eq21-23."""
    t = paper_like_params("yaw+")
    v = triangle([0, 5000, 1000, 4000, 0]).astype(float)
    r = thresholds(t["r1"], t["rn"], 30)
    p = density(r, t["lam"], t["sigma"])
    gl = t["a1"] * v + t["a2"]  # the families written independently (numpy loop)
    y1 = play_numpy(v, gl, r, t["a3"] * v + t["a4"], r, p)
    y2 = play_numpy(v, gl, r, t["a5"] * v + t["a6"], t["kappa"] * r, p)
    d = motion_direction(v, 2.0)
    expected = np.where((d < 0) & (v <= t["v_f"]), y2, y1)
    got = i2ris_egpi_model(deadband_counts=2.0, **t)(v)
    np.testing.assert_allclose(got, expected, atol=1e-9)
    assert np.any((d < 0) & (v <= t["v_f"])) and np.any(y1 != y2)


def test_gpi_sum_of_operators_matches_reference():
    v = triangle([0, 3000, 800, 2500, 0, 3000])
    pars = (0.007, 0.5, 0.0075, -0.5, 0.05, 0.2, 0.3, 3.0)
    n = 7
    got = gpi_model(n=n).evaluate(np.asarray(v), np.array(pars))
    np.testing.assert_allclose(got, gpi_reference(v, *pars, n), atol=1e-9)


def test_motion_direction_holds_and_deadband():
    v = np.array([0, 1, 2, 2, 2, 1.5, 1, 1, 3, 2.9], dtype=float)
    np.testing.assert_array_equal(motion_direction(v, 0.0), [1, 1, 1, 1, 1, -1, -1, -1, 1, -1])
    # a 0.6 dead band ignores the 0.5 dip, then turns at 1.0 below the maximum 2
    np.testing.assert_array_equal(motion_direction(v, 0.6), [1, 1, 1, 1, 1, 1, -1, -1, 1, 1])


def test_select_stage_paper_rule():
    """Eq8: rising z1 if v < v_f1 else z2; falling z1 if v > v_f2 else z2."""
    z = np.vstack((np.zeros(4), np.ones(4)))
    v = np.array([1.0, 2.0, 0.0, -1.0])
    d = np.array([1, 1, -1, -1], np.int8)
    got = select_stage(z, v, d, np.array([1.5]), np.array([-0.3]))
    np.testing.assert_array_equal(got, [0, 1, 0, 1])


def test_holds_are_evaluated_once_per_run(rng):
    """Models evaluate a run of equal inputs once (exact for rate-independent models):
    same output as the compiled output function on every sample."""
    v = np.repeat(np.round(rng.uniform(0, 6000, 300)), rng.integers(1, 6, 300)).astype(float)
    v[50:400] = 0.0  # a long rest at zero (the other direction's stretch)
    for model, output, extra in (
        (gpi_model(), gpi_output, {}),
        (i2ris_egpi_model(deadband_counts=2.0), egpi_output, {"deadband": 2.0}),
        (continuous_egpi_model(), continuous_egpi_output, {}),
    ):
        np.testing.assert_array_equal(model(v), output(v, n=30, **extra, **model.value_dict()))


def test_gather_rows_is_the_fancy_indexed_assignment():
    """``jac[:, first:first + q] = sign * cols[at]`` into a column-ordered array, the
    other columns untouched (the two-tendon and coupled Jacobians' assembly)."""
    from i2ris_calib.hysteresis.kernel import gather_rows

    rng = np.random.default_rng(0)
    cols = rng.normal(size=(200, 8))
    at = rng.integers(0, 200, 150)
    for sign in (1.0, -1.0, -0.5):
        jac = np.full((20, 150), 7.0).T  # column-ordered, as LM takes it
        gather_rows(jac, 3, sign, cols, at)
        np.testing.assert_array_equal(jac[:, 3:11], sign * cols[at])
        assert np.all(jac[:, :3] == 7.0) and np.all(jac[:, 11:] == 7.0)


def test_run_index_is_the_runs_of_equal_samples():
    """First value of every run of equal consecutive samples and the run index of each
    sample, as ``v[new]`` and ``cumsum(new) - 1`` (NaN never equal)."""
    from i2ris_calib.hysteresis.kernel import run_index

    rng = np.random.default_rng(1)
    for n in (0, 1, 2, 50, 500):
        v = np.round(rng.normal(size=n)).cumsum() * (rng.random(n) < 0.6)
        if n > 10:
            v[[3, 4]] = np.nan
        new = np.ones(n, bool)
        new[1:] = v[1:] != v[:-1]
        vals, idx = run_index(v)
        np.testing.assert_array_equal(vals, v[new])
        np.testing.assert_array_equal(idx, np.cumsum(new) - 1)
