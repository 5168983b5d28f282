"""The single-loop kinds over the signed input: Bouc-Wen (``bouc_wen``) and the
Prandtl-Ishlinskii / Maxwell-slip model with a free density (``maxwell_slip``)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hyst_reference import refine

from i2ris_calib.fitting.config import FitConfig
from i2ris_calib.fitting.pipeline import unfitted_model
from i2ris_calib.hysteresis.bouc_wen import BoucWenModel, bouc_wen_state
from i2ris_calib.hysteresis.registry import (
    DIAGNOSIS_STARTS,
    INVERSE_KINDS,
    MODEL_KINDS,
    SIGNED_DEFAULT,
    SIGNED_KINDS,
    SLIP_THRESHOLDS,
    kind_info,
    kind_of,
    model_for_kind,
)
from i2ris_calib.hysteresis.slip import SlipModel
from i2ris_calib.model import Signals

SETTINGS = settings(max_examples=40, deadline=None)
signed_inputs = st.lists(st.integers(-6000, 6000), min_size=2, max_size=50).map(
    lambda x: np.array(x, dtype=float)
)
seeds = st.integers(0, 2**31 - 1)


def _bw(seed, exact=True):
    """A random Bouc-Wen model; exponent 1 (solved exactly) or random (Runge-Kutta)."""
    rng = np.random.default_rng(seed)
    return model_for_kind("bouc_wen").with_values({
        "theta0": rng.uniform(-5, 5), "d": rng.uniform(1e-3, 1e-2), "hs": rng.uniform(0.5, 5),
        "k": rng.uniform(2e-4, 5e-3), "phi": rng.uniform(-0.9, 1.0),
        "n_bw": 1.0 if exact else rng.uniform(0.5, 4.0),
    })  # fmt: skip


def _pi(seed, n=12):
    rng = np.random.default_rng(seed)
    vals = {f"w{j}": rng.uniform(0, 2e-3) for j in range(1, n + 1)}
    vals |= {"theta0": rng.uniform(-5, 5), "w0": rng.uniform(-2e-3, 5e-3), "r_max": 3000.0}
    return model_for_kind("maxwell_slip", n=n).with_values(vals)


def test_registry_rows_of_the_single_loop_kinds():
    for kind, cls in (("bouc_wen", BoucWenModel), ("maxwell_slip", SlipModel)):
        info = kind_info(kind)
        assert info.signed and info.on_signed and kind in SIGNED_KINDS
        assert kind not in MODEL_KINDS  # the paper's split is unchanged
        assert kind in DIAGNOSIS_STARTS  # picked on a signed input: a start of diagnose
        assert kind not in INVERSE_KINDS  # no inverse in the compensation stage
        m = model_for_kind(kind, n=7)
        assert isinstance(m, cls) and kind_of(m) is info and m.n == 7
    assert SIGNED_DEFAULT == "agpi"  # the default known before fitting is unchanged
    # its own number of thresholds by default ([fit] n_operators is GPI's)
    assert model_for_kind("maxwell_slip").n == SLIP_THRESHOLDS == 15
    assert model_for_kind("gpi").n == 30
    v = np.linspace(-100.0, 100.0, 50)
    assert unfitted_model("maxwell_slip", v, FitConfig(n_operators=40)).n == SLIP_THRESHOLDS
    assert len(model_for_kind("maxwell_slip", n=7).parameters) == 7 + 3


def test_bouc_wen_is_the_classic_equation():
    """theta0 + d v - h with dh = A dv - beta |dv| h - gamma dv |h| (n = 1), A = k hs,
    beta = k (1 + phi) / 2, gamma = k (1 - phi) / 2: a fine Euler integration agrees."""
    rng = np.random.default_rng(3)
    v = np.concatenate([np.linspace(0, 4000, 300), np.linspace(4000, -3000, 400),
                        rng.uniform(-4000, 4000, 20).repeat(15)])  # fmt: skip
    theta0, d, hs, k, phi = 1.5, 6e-3, 2.0, 1.5e-3, 0.3
    m = model_for_kind("bouc_wen").with_values(
        {"theta0": theta0, "d": d, "hs": hs, "k": k, "phi": phi, "n_bw": 1.0}
    )
    a, beta, gamma = k * hs, k * (1 + phi) / 2, k * (1 - phi) / 2
    h, want, sub = 0.0, [], 2000
    for i in range(v.size):
        if i:
            du = (v[i] - v[i - 1]) / sub
            for _ in range(sub):
                h += a * du - beta * abs(du) * h - gamma * du * abs(h)
        want.append(theta0 + d * v[i] - h)
    np.testing.assert_allclose(m(v), want, atol=2e-3)


@SETTINGS
@given(v=signed_inputs, seed=seeds, exact=st.booleans())
def test_bouc_wen_rate_independence_and_bounded_state(v, seed, exact):
    """Holds and intermediate samples on the straight input between samples leave the
    output at the original samples unchanged (exactly for n = 1; to the Runge-Kutta
    error, < 1e-3 hs, for another exponent); |h| <= hs."""
    m = _bw(seed, exact)
    fine, kept = refine(v, np.random.default_rng(seed))
    hs = abs(m.value_dict()["hs"])
    np.testing.assert_allclose(m(fine)[kept], m(v), atol=(1e-9 if exact else 1e-3) * hs)
    val = m.value_dict()
    z = bouc_wen_state(fine, val["k"], val["phi"], val["n_bw"])
    assert np.all(np.abs(z) <= 1.0 + 1e-9)


def test_exact_and_runge_kutta_agree():
    """The exact n = 1 solution and the Runge-Kutta integration of the same equation."""
    rng = np.random.default_rng(8)
    v = np.cumsum(rng.normal(0, 300, 500))
    for phi in (-0.8, 0.0, 0.6, 1.0):
        exact = bouc_wen_state(v, 1e-3, phi, 1.0)
        rk = bouc_wen_state(v, 1e-3, phi, 1.0 + 1e-12)
        np.testing.assert_allclose(exact, rk, atol=1e-6)


def test_bouc_wen_has_no_wiping_out_but_pi_has():
    """After the same large excursion the PI state forgets a smaller earlier loop
    (wiping-out); a Bouc-Wen element remembers it (its minor loops do not close)."""
    a = np.array([0.0, 1500.0, -1500.0, 1500.0, -4000.0, 4000.0, 1000.0])
    b = np.array([0.0, 500.0, -200.0, 500.0, -4000.0, 4000.0, 1000.0])
    pi = _pi(1)
    assert pi(a)[-1] == pytest.approx(pi(b)[-1], abs=1e-12)
    bw = model_for_kind("bouc_wen").with_values({"k": 3e-4, "hs": 2.0, "phi": 0.5})
    assert abs(bw(a)[-1] - bw(b)[-1]) > 1e-6


@SETTINGS
@given(v=signed_inputs, seed=seeds)
def test_pi_rate_independent_continuous_and_wipes_out(v, seed):
    m = _pi(seed)
    fine, kept = refine(v, np.random.default_rng(seed))
    np.testing.assert_allclose(m(fine)[kept], m(v), atol=1e-9)
    # no output jump: |dy| <= sum |w| |dv| (every operator is 1-Lipschitz in the input)
    w = np.abs(m.values[1:-1]).sum()
    assert np.all(np.abs(np.diff(m(fine))) <= w * np.abs(np.diff(fine)) + 1e-9)
    # wiping-out: a reversal beyond every earlier extreme erases the history
    big = np.concatenate([v, [7000.0, -7000.0, 100.0]])
    other = np.array([0.0, 7000.0, -7000.0, 100.0])
    assert m(big)[-1] == pytest.approx(m(other)[-1], abs=1e-9)


def test_pi_jacobian_matches_finite_differences():
    """The exact Jacobian (operator outputs; the r_max column from the boundary each
    operator last sat on) equals central differences."""
    rng = np.random.default_rng(5)
    v = np.cumsum(rng.normal(0, 150, 400))
    m = _pi(2)
    x = m.values
    j = m.jacobian(Signals(v=v), x)
    for i in range(x.size):
        h = 1e-6 * max(1.0, abs(x[i]))
        up, dn = x.copy(), x.copy()
        up[i] += h
        dn[i] -= h
        fd = (m.evaluate(Signals(v=v), up) - m.evaluate(Signals(v=v), dn)) / (2 * h)
        np.testing.assert_allclose(j[:, i], fd, atol=1e-5 * max(1.0, np.abs(fd).max()))
    np.testing.assert_array_equal(m.jacobian(Signals(v=v), x, rows=np.array([3, 7])), j[[3, 7]])
