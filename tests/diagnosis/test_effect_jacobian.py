"""EffectModel's exact Jacobian: columns against central differences of ``evaluate``,
rows and columns subsets, and None over a base model without a Jacobian."""

from __future__ import annotations

import numpy as np
import pytest

from i2ris_calib.diagnosis.refit import refit
from i2ris_calib.fitting.fit import _analytic_jacobian
from i2ris_calib.hysteresis.effect_kernels import first_order_lag, lag_sum
from i2ris_calib.hysteresis.effects import CATALOGUE, EffectModel, add_effect, model_values
from i2ris_calib.hysteresis.models import gpi_model
from i2ris_calib.hysteresis.registry import model_for_kind
from i2ris_calib.hysteresis.two_tendon import two_tendon_gpi_model
from i2ris_calib.model import Signals

#: The play operators make the output piecewise linear in the parameters, with kinks
#: and, where a branch switches, jumps: a difference that straddles one is no
#: derivative. The base model's columns (exact) are compared with central differences
#: of relative step BASE_STEP, too small to straddle a kink but on a few rows; at least
#: MIN_ROWS of the rows must agree within RTOL x the column's largest |entry| (an
#: output lag spreads a straddled kink over the rows after it, so not all rows).
BASE_STEP = 1e-8
MIN_ROWS = 0.99
RTOL = 1e-5
#: The effect's columns (central differences of relative step eps^(1/3) themselves)
#: are compared on the rows where differences of relative steps SMOOTH_STEPS agree
#: within SMOOTH_RTOL (no kink within the steps); at least MIN_SMOOTH of the rows.
SMOOTH_STEPS = (1e-5, 1e-7)
SMOOTH_RTOL = 1e-6
MIN_SMOOTH = 0.9

BASES = {"gpi": gpi_model(), "agpi": two_tendon_gpi_model()}
STACKS = {
    "backlash+creep": ("backlash", "creep"),
    "time_delay+saturation": ("time_delay", "saturation"),
    "dead_zone+rate_dependent_weights": ("dead_zone", "rate_dependent_weights"),
}


def _signals(signed: bool) -> Signals:
    """2000 samples at 50 Hz of a modulated sine without holds (unsigned input in
    [100, 4900] counts for the GPI, through zero for the two-tendon GPI)."""
    t = np.arange(2000) / 50.0
    v = 2400 * np.sin(2 * np.pi * t / 6.0) * (0.7 + 0.3 * np.cos(2 * np.pi * t / 17))
    return Signals(
        v=v if signed else v + 2500.0,
        t_s=t,
        v_other=1500 + 1000 * np.sin(2 * np.pi * t / 9),
        theta_other_deg=10 * np.cos(2 * np.pi * t / 11),
    )


def _at_grid_point(model: EffectModel, sig: Signals) -> np.ndarray:
    """The model's values with its effect at the middle start of its grid (non-neutral)."""
    x = model_values(model)
    y = model.inner.evaluate(sig, x[: model.n_inner])
    grid = model.effect.start_grid(sig, y)
    x[model.n_inner :] = grid[len(grid) // 2]
    return x


def _central(model, sig, x, j, rel):
    h = rel * max(1.0, abs(x[j]))
    up, down = x.copy(), x.copy()
    up[j] += h
    down[j] -= h
    return (model.evaluate(sig, up) - model.evaluate(sig, down)) / (2 * h)


def _check_against_differences(model: EffectModel, sig: Signals, x: np.ndarray) -> None:
    jac = model.jacobian(sig, x)
    assert jac.shape == (sig.v.size, x.size)
    for j in range(x.size):
        name = model.parameters[j].name
        if j < model.n_inner:
            c = _central(model, sig, x, j, BASE_STEP)
            scale = max(float(np.max(np.abs(c))), 1e-12)
            ok = np.abs(jac[:, j] - c) <= RTOL * scale
            assert ok.mean() >= MIN_ROWS, f"{name}: {ok.mean():.4f} of the rows agree"
            continue
        c1, c2 = (_central(model, sig, x, j, rel) for rel in SMOOTH_STEPS)
        scale = max(float(np.max(np.abs(c2))), 1e-12)
        smooth = np.abs(c1 - c2) <= SMOOTH_RTOL * scale
        assert smooth.mean() >= MIN_SMOOTH, f"{name}: {smooth.mean():.3f} smooth rows"
        err = np.abs(jac[smooth, j] - c2[smooth]) / scale
        assert err.max() <= RTOL, f"{name}: relative error {err.max():.2e}"


def _check_subsets(model: EffectModel, sig: Signals, x: np.ndarray) -> None:
    full = model.jacobian(sig, x)
    rows = np.arange(3, sig.v.size, 7)
    np.testing.assert_allclose(model.jacobian(sig, x, rows=rows), full[rows], rtol=1e-12, atol=0)
    cols = np.array([x.size - 1, 0, 2])
    np.testing.assert_allclose(
        model.exact_jacobian(sig, x, rows=rows, cols=cols), full[np.ix_(rows, cols)], rtol=1e-12
    )


@pytest.mark.parametrize("base", list(BASES))
@pytest.mark.parametrize("name", list(CATALOGUE))
def test_effect_jacobian_matches_central_differences(base, name):
    sig = _signals(signed=base == "agpi")
    model = add_effect(BASES[base], name)
    x = _at_grid_point(model, sig)
    _check_against_differences(model, sig, x)
    _check_subsets(model, sig, x)


@pytest.mark.parametrize("stack", list(STACKS))
def test_stacked_effects_jacobian(stack):
    sig = _signals(signed=False)
    first, second = STACKS[stack]
    inner = add_effect(BASES["gpi"], first)
    inner = inner.with_values(_at_grid_point(inner, sig))
    model = add_effect(inner, second)
    x = _at_grid_point(model, sig)
    _check_against_differences(model, sig, x)
    _check_subsets(model, sig, x)


def test_no_jacobian_over_a_base_without_one(linear):
    model = add_effect(linear, "time_delay")
    assert model.jacobian is None
    assert _analytic_jacobian(model) is None
    assert _analytic_jacobian(add_effect(model, "creep")) is None
    assert _analytic_jacobian(add_effect(gpi_model(), "creep")) is not None
    assert add_effect(model_for_kind("bouc_wen"), "creep").jacobian is None
    assert add_effect(model_for_kind("maxwell_slip"), "creep").jacobian is not None


def test_refit_with_the_exact_jacobian_recovers_a_delay():
    sig = _signals(signed=False)
    truth = add_effect(gpi_model(), "time_delay", {"tau_s": 0.2})
    theta = truth.evaluate(sig, model_values(truth))
    mask = np.ones(sig.v.size, bool)
    x0 = model_values(truth)
    x0[-1] = 0.1
    free = np.zeros(x0.size, bool)
    free[-1] = True
    r = refit(truth, sig, theta, mask, x0, free=free)
    assert abs(r.values[-1] - 0.2) < 1e-6
    assert r.sse_deg2 < 1e-10


def test_lag_sum_equals_the_sum_of_lags_to_the_last_bit():
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.01, 0.05, 3000))
    y = rng.normal(size=(3000, 3)).cumsum(axis=0)
    taus = CATALOGUE["creep_log"].taus(0.3)
    out = lag_sum(np.asfortranarray(y), t, taus)
    for c in range(3):
        ref = sum(first_order_lag(np.ascontiguousarray(y[:, c]), t, float(tau)) for tau in taus)
        np.testing.assert_array_equal(out[:, c], ref)
