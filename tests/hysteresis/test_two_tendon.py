"""The two-tendon GPI (model kind ``agpi``): each tendon a GPI on its side of zero."""

from __future__ import annotations

import numpy as np
import pytest

from i2ris_calib.data.dataset import input_bands
from i2ris_calib.data.excursions import excursions
from i2ris_calib.hysteresis.models import gpi_model
from i2ris_calib.hysteresis.presets import (
    loading_trajectory,
    random_two_tendon_params,
    through_zero_trajectory,
)
from i2ris_calib.hysteresis.registry import (
    KINDS,
    MODEL_KINDS,
    SIGNED_KINDS,
    kind_info,
    kind_of,
    model_for_kind,
    table_order,
)
from i2ris_calib.hysteresis.two_tendon import TwoTendonGPIModel


def _through_zero(seed=0, n=3000, rate=30.0):
    rng = np.random.default_rng(seed)
    truth = random_two_tendon_params(rng, offset_deg=-9.0)
    t, v, start = through_zero_trajectory(rng, n, rate)
    return truth, t, v, start


def test_registry_is_the_one_table_of_kinds():
    assert MODEL_KINDS == ("gpi", "egpi", "egpi_c")  # the paper's per-direction kinds
    assert "agpi" in SIGNED_KINDS and kind_info("agpi").signed
    assert table_order(["gpi", "agpi", "diagnosed"]) == ["diagnosed", "agpi", "gpi"]
    for k in KINDS:
        if k.factory is not None:
            m = model_for_kind(k.kind, n=5)
            assert kind_of(m) is k and m.name == k.kind and m.n == 5
    assert kind_of(object()) is None


def test_the_names_tables_roles_are_the_paper_and_the_simulations_kinds():
    """The role names of hysteresis/kinds.py the other layers read instead of literals."""
    from i2ris_calib.hysteresis import kinds
    from i2ris_calib.hysteresis.models import GPIModel, I2RISEGPIModel

    assert kinds.PAPER_KINDS == ("egpi", "gpi")  # its Tables 1-2's row order
    assert kind_info(kinds.PAPER_MODEL).model_class is I2RISEGPIModel
    assert kind_info(kinds.PAPER_BASELINE).model_class is GPIModel
    assert kinds.SESSION_TRUTH == "egpi"  # simulation/truth.py: i2ris_egpi_model
    assert kind_info(kinds.LAB_TRUTH).model_class is TwoTendonGPIModel


def test_output_is_offset_plus_one_gpi_per_side():
    """theta = theta0 + GPI_p[max(v, 0)] - GPI_n[max(-v, 0)], over the whole history."""
    truth, _, v, _ = _through_zero()
    m = model_for_kind("agpi").with_values(truth)
    assert isinstance(m, TwoTendonGPIModel) and len(m.parameters) == 17
    g = gpi_model()
    side = {s: {k[:-2]: x for k, x in truth.items() if k.endswith(f"_{s}")} for s in "pn"}
    want = (
        truth["theta0"]
        + g.evaluate_dict(np.maximum(v, 0), side["p"])
        - g.evaluate_dict(np.maximum(-v, 0), side["n"])
    )
    np.testing.assert_allclose(m(v), want, atol=1e-12)
    assert m(np.zeros(10))[0] == pytest.approx(truth["theta0"], abs=2.0)


def test_jacobian_matches_finite_differences():
    truth, _, v, _ = _through_zero(n=1500)
    m = model_for_kind("agpi").with_values(truth)
    x = m.values
    jac = m.jacobian(v, x)
    for i in range(x.size):
        h = 1e-6 * max(abs(x[i]), 1e-3)
        xp, xm = x.copy(), x.copy()
        xp[i] += h
        xm[i] -= h
        fd = (m.evaluate(v, xp) - m.evaluate(v, xm)) / (2 * h)
        # kinks: a few samples may see a one-sided derivative
        close = np.isclose(jac[:, i], fd, rtol=1e-4, atol=1e-6 * (np.abs(fd).max() + 1e-9))
        assert close.mean() > 0.99, m.names[i]
    rows = np.arange(0, v.size, 7)
    np.testing.assert_array_equal(m.jacobian(v, x, rows=rows), jac[rows])


def test_gauge_holds_a2_and_lam_and_guess_keeps_them():
    m = model_for_kind("agpi")
    fixed = {p.name for p in m.parameters if p.fixed}
    assert fixed == {"a2_p", "a2_n", "lam_p", "lam_n"}
    truth, _, v, _ = _through_zero(n=2000)
    theta = m.with_values(truth)(v)
    g = m.guess(v, theta)
    assert g.value_dict()["a2_p"] == 0.0 and g.value_dict()["lam_n"] == m.value_dict()["lam_n"]
    assert np.sqrt(np.mean((g(v) - theta) ** 2)) < 0.5 * np.std(theta)


def test_excursions_tell_the_lab_recording_from_the_paper_protocol():
    _, t, v, start = _through_zero(n=3000)
    lab = excursions(v[start:], input_bands(v[start:]).zero_band, t[start:])
    assert lab.signed and lab.n_crossings > 5
    assert lab.reason.startswith("the input crosses zero")
    rng = np.random.default_rng(1)
    t1, v1 = loading_trajectory(rng, 4, n_samples=1500)
    t2, v2 = loading_trajectory(rng, 4, n_samples=1500, start_s=t1[-1] + 1.0)
    enc, t = np.concatenate([v1, -v2]), np.concatenate([t1, t2])
    paper = excursions(enc, input_bands(enc).zero_band, t)
    assert not paper.signed and paper.n_from_rest == paper.n_excursions == 8
    one_side = excursions(v1, input_bands(v1).zero_band, t1)
    assert not one_side.signed and one_side.reason == "the input stays on one side of zero"


def test_joint_coupling_starts_come_from_the_angle_not_the_base():
    """The coupled kind's joint starts (issue 31, agpi_coupled:112): the coupling's
    straight-line part fitted with this axis's at once, and the coupling signs from it,
    whatever the base (the fit's regression case: tests/fitting/test_optimum.py)."""
    from i2ris_calib.hysteresis.coupled import coupled_starts, joint_coupling
    from i2ris_calib.model import Signals

    k = np.arange(400)
    v = 4000.0 * np.sin(2 * np.pi * k / 80)
    vo = 4500.0 * np.cos(2 * np.pi * k / 80)
    # straight lines on each side of both inputs: the joint fit reads them exactly
    own = 3.0 + 0.009 * np.maximum(v, 0) - 0.008 * np.maximum(-v, 0)
    coupling = -0.006 * np.maximum(vo, 0) + 0.004 * np.maximum(-vo, 0)
    theta = own + coupling
    np.testing.assert_allclose(joint_coupling(v, vo, theta), coupling, atol=1e-9)
    model = model_for_kind("agpi_coupled")
    base = model_for_kind("agpi").value_dict()  # a poor base: the defaults
    s = Signals(v=v, v_other=vo)
    _, plain = coupled_starts(model, s, theta, base, 4, np.random.default_rng(0), 2.0, joint=False)
    signed, both = coupled_starts(model, s, theta, base, 4, np.random.default_rng(0), 2.0)
    assert len(plain) == 4 + 2 and len(both) == len(plain) + 4
    # the other motor's positive side lowers the angle, its negative side raises it
    # (sign_cn -1: -(-1) C_n), as the joint fit reads
    assert signed.value_dict()["sign_cp"] == -1.0
    assert signed.value_dict()["sign_cn"] == -1.0
