"""The normal-equations Levenberg-Marquardt (fitting/lm.py) against scipy's MINPACK LM
on problems with known solutions."""

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import least_squares

from i2ris_calib.fitting.lm import ScaledSystem, _norm, least_squares_lm, lm_parameter
from i2ris_calib.hysteresis.models import gpi_model
from i2ris_calib.hysteresis.presets import gpi_values, loading_trajectory, paper_like_params


def _tanh_problem(seed, m=3000, n=6):
    """r(x) = A tanh(x) - b with b made from a known x (plus noise)."""
    rng = np.random.default_rng(seed)
    a = rng.standard_normal((m, n))
    x_true = 0.8 * np.tanh(rng.standard_normal(n))
    b = a @ np.tanh(x_true) + 0.01 * rng.standard_normal(m)

    def fun(x):
        return a @ np.tanh(x) - b

    def jac(x):
        return a * (1.0 - np.tanh(x) ** 2)[None, :]

    return fun, jac, rng.uniform(-1.5, 1.5, n)


def _exp_decay_problem(seed, m=2000):
    """y = c0 exp(-c1 t) + c2 with scales far apart (the LM scaling matters)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 10.0, m)
    truth = np.array([250.0, 0.7, -3.0])
    y = truth[0] * np.exp(-truth[1] * t) + truth[2] + 0.1 * rng.standard_normal(m)

    def fun(c):
        return c[0] * np.exp(-c[1] * t) + c[2] - y

    def jac(c):
        e = np.exp(-c[1] * t)
        return np.column_stack([e, -c[0] * t * e, np.ones_like(t)])

    return fun, jac, np.array([100.0, 0.2, 0.0])


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("problem", [_tanh_problem, _exp_decay_problem])
def test_ends_where_minpack_ends(problem, seed):
    fun, jac, x0 = problem(seed)
    ours = least_squares_lm(fun, jac, x0, ftol=1e-10, xtol=1e-10)
    ref = least_squares(fun, x0, jac=jac, method="lm", x_scale="jac", ftol=1e-10, xtol=1e-10)
    assert ours.success and ref.success
    np.testing.assert_allclose(ours.x, ref.x, rtol=1e-6, atol=1e-8)
    assert ours.cost == pytest.approx(ref.cost, rel=1e-10)
    # the same algorithm: about as many evaluations as MINPACK
    assert abs(ours.nfev - ref.nfev) <= max(3, ref.nfev // 4)
    np.testing.assert_allclose(ours.jac, jac(ours.x))
    np.testing.assert_allclose(ours.fun, fun(ours.x))


def test_linear_problem_is_its_least_squares_solution():
    rng = np.random.default_rng(3)
    a, b = rng.standard_normal((500, 4)), rng.standard_normal(500)
    res = least_squares_lm(lambda x: a @ x - b, lambda x: a, np.zeros(4))
    np.testing.assert_allclose(res.x, np.linalg.lstsq(a, b, rcond=None)[0], rtol=1e-9)


def test_rank_deficient_jacobian_still_descends():
    """Two identical columns: the Gauss-Newton system is singular; LM must still reach
    the minimal cost (any split of the duplicated coefficient), with finite values."""
    rng = np.random.default_rng(4)
    base = rng.standard_normal((400, 2))
    a = np.column_stack([base, base[:, 0]])
    b = base @ np.array([1.5, -2.0]) + 0.01 * rng.standard_normal(400)
    res = least_squares_lm(lambda x: a @ x - b, lambda x: a, np.zeros(3))
    floor = 0.5 * np.sum((base @ np.linalg.lstsq(base, b, rcond=None)[0] - b) ** 2)
    assert np.isfinite(res.x).all()
    assert res.cost == pytest.approx(floor, rel=1e-9)
    assert res.x[0] + res.x[2] == pytest.approx(1.5, abs=0.01)


def test_max_nfev_stops_with_status_0():
    fun, jac, x0 = _exp_decay_problem(0)
    res = least_squares_lm(fun, jac, x0, max_nfev=3)
    assert res.status == 0 and not res.success and res.nfev <= 3


def test_norm_does_not_overflow():
    big = np.array([3e200, 4e200])
    assert _norm(big) == pytest.approx(5e200, rel=1e-15)
    assert _norm(np.array([np.inf, 1.0])) == np.inf


def test_overflowing_normal_equations_hand_over_to_minpack():
    """Jacobian entries of 1e160 (residuals of order 1): J^T J overflows, MINPACK's QR
    finishes the run (the same end as scipy's LM from the start)."""
    t = np.linspace(0.0, 1.0, 100)
    a = np.column_stack([1e160 * t, np.ones_like(t)])
    b = a @ np.array([2.0, 1.0])

    def fun(c):
        return a @ c - b

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = least_squares_lm(fun, lambda c: a, np.array([2.0, 0.0]))
    ref = least_squares(fun, np.array([2.0, 0.0]), jac=lambda c: a, method="lm", x_scale="jac")
    np.testing.assert_array_equal(res.x, ref.x)
    assert res.nfev == ref.nfev + 1  # the start's evaluation before the hand-over


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    n=st.integers(1, 8),
    delta_scale=st.floats(1e-3, 10.0),
)
def test_lm_parameter_meets_the_trust_radius(seed, n, delta_scale):
    """par = 0 only when the Gauss-Newton step is within 1.1 delta; else the damped
    step's scaled length is within 10 % of delta (MINPACK lmpar's contract)."""
    rng = np.random.default_rng(seed)
    j = rng.standard_normal((3 * n + 2, n)) * rng.uniform(0.1, 10.0, n)
    f = rng.standard_normal(3 * n + 2)
    diag = np.linalg.norm(j, axis=0)
    system = ScaledSystem.of(j.T @ j, j.T @ f, diag)
    gn = system.step_norm(0.0)
    delta = delta_scale * gn
    par = lm_parameter(system, delta, 0.0)
    if par == 0.0:
        assert gn <= 1.1 * delta * (1 + 1e-12)
    else:
        assert abs(system.step_norm(par) - delta) <= 0.1 * delta * (1 + 1e-9)
    # the step solves (J^T J + par D^2) p = -J^T f
    p = system.step(par) / diag
    np.testing.assert_allclose(
        (j.T @ j + par * np.diag(diag**2)) @ p,
        -(j.T @ f),
        rtol=1e-6,
        atol=1e-8 * np.abs(j.T @ f).max(),
    )


def test_qr_system_is_the_normal_system_when_well_conditioned():
    rng = np.random.default_rng(6)
    j = rng.standard_normal((300, 5)) * np.array([1.0, 10.0, 0.1, 3.0, 1e3])
    f = rng.standard_normal(300)
    diag = np.linalg.norm(j, axis=0)
    normal = ScaledSystem.of(j.T @ j, j.T @ f, diag)
    qr = ScaledSystem.of_qr(j, f, diag)
    np.testing.assert_allclose(normal.eigenvalues, qr.eigenvalues, rtol=1e-10)
    for par in (0.0, 0.3, 10.0):
        np.testing.assert_allclose(normal.step(par), qr.step(par), rtol=1e-8)
        assert normal.newton_slope(par) == pytest.approx(qr.newton_slope(par), rel=1e-8)


def test_ill_conditioned_system_goes_to_qr():
    """Scaled condition number 1e7 (beyond the normal equations' 1e5): ``of`` refuses,
    and the QR system's Gauss-Newton step solves the least-squares problem."""
    rng = np.random.default_rng(7)
    base = rng.standard_normal((400, 3))
    j = np.column_stack([base, base[:, 0] + 1e-7 * rng.standard_normal(400)])
    f = rng.standard_normal(400)
    diag = np.linalg.norm(j, axis=0)
    assert ScaledSystem.of(j.T @ j, j.T @ f, diag) is None
    qr = ScaledSystem.of_qr(j, f, diag)
    p = qr.step(0.0) / diag
    np.testing.assert_allclose(p, -np.linalg.lstsq(j, f, rcond=None)[0], rtol=1e-6)


def test_forward_jacobian_matches_the_exact_one():
    """A model without an exact Jacobian gets forward differences (scipy's 2-point
    steps) for the project's LM: on a GPI they agree with the model's exact Jacobian."""
    from i2ris_calib.fitting.fit import _forward_jacobian

    rng = np.random.default_rng(8)
    _, v = loading_trajectory(rng, n_cycles=3, n_samples=400)
    model = gpi_model()
    x0 = model.vector(gpi_values(paper_like_params("yaw+")))
    fd = _forward_jacobian(lambda x: model.evaluate(v, x))(x0)
    exact = model.jacobian(v, x0)
    scale = np.abs(exact).max(axis=0) + 1e-12
    np.testing.assert_allclose(fd / scale, exact / scale, atol=1e-5)
