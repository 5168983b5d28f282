"""Model classes: equivalences between code paths, the parameter contract, presets."""

from __future__ import annotations

import numpy as np
import pytest
from hyst_reference import triangle

from i2ris_calib.errors import CalibError
from i2ris_calib.hysteresis.models import (
    ContinuousEGPIModel,
    GPIModel,
    I2RISEGPIModel,
    egpi_model,
    gpi_model,
    i2ris_egpi_model,
)
from i2ris_calib.hysteresis.presets import (
    DATASETS,
    GPI_NAMES,
    V_MAX_COUNTS,
    loading_trajectory,
    paper_like_params,
    random_i2ris_egpi_params,
)
from i2ris_calib.hysteresis.registry import MODEL_KINDS, model_for_kind
from i2ris_calib.model import Model, Parameter, Signals

V = triangle([0, 6000, 1500, 5000, 0, 3500, 200, 6000, 0])


@pytest.fixture
def truth(rng):
    return random_i2ris_egpi_params(rng)


def test_models_follow_protocol():
    for m in (gpi_model(), i2ris_egpi_model()):
        assert isinstance(m, Model)
        assert len({p.name for p in m.parameters}) == len(m.parameters)
        assert all(p.unit for p in m.parameters) and all(p.doc for p in m.parameters)
    assert gpi_model().names == GPI_NAMES
    assert i2ris_egpi_model().names[-1] == "v_f" and len(i2ris_egpi_model().names) == 12


def test_egpi_reduces_to_gpi(truth):
    """v_f below every input -> y = y1, which is the GPI with (a1..a4, lam, sigma, r1, rn)."""
    gpi = gpi_model().evaluate_dict(V, {k: truth[k] for k in GPI_NAMES})
    egpi = i2ris_egpi_model().evaluate_dict(V, truth | {"v_f": -1.0})
    np.testing.assert_allclose(egpi, gpi, atol=1e-9)
    # identical second family (kappa 1, same envelope) -> EGPI == GPI for any v_f
    same = truth | {"a5": truth["a3"], "a6": truth["a4"], "kappa": 1.0}
    np.testing.assert_allclose(i2ris_egpi_model().evaluate_dict(V, same), gpi, atol=1e-9)


def test_flag_point_matters(truth):
    y = i2ris_egpi_model().evaluate_dict(V, truth)
    gpi = gpi_model().evaluate_dict(V, {k: truth[k] for k in GPI_NAMES})
    assert np.max(np.abs(y - gpi)) > 1.0  # the second stage changes the output visibly


def test_general_egpi_equals_i2ris_form(truth):
    """N-stage EGPI with linear envelopes, a never-reached rising flag, a shared
    loading envelope and kappa_l = 1 is exactly the I2RIS EGPI (Eq16-23 from Eq4-8)."""
    vals = {
        "l1_slope": truth["a1"], "l1_offset": truth["a2"], "r1_slope": truth["a3"], "r1_offset": truth["a4"],
        "l2_slope": truth["a1"], "l2_offset": truth["a2"], "r2_slope": truth["a5"], "r2_offset": truth["a6"],
        "kappa_l2": 1.0, "kappa_r2": truth["kappa"], "vf_rise1": 1e12, "vf_fall1": truth["v_f"],
        "lam": truth["lam"], "sigma": truth["sigma"], "r1": truth["r1"], "rn": truth["rn"],
    }  # fmt: skip
    general = egpi_model([("linear", "linear"), ("linear", "linear")], vals)
    np.testing.assert_allclose(general(V), i2ris_egpi_model(**truth)(V), atol=1e-9)


def test_three_stage_egpi_switches_at_each_flag():
    """A 3-stage model whose stages are constant offsets shows which stage is active."""
    vals = {"lam": 1.0, "sigma": 0.0, "r1": 0.0, "rn": 0.0}
    for s in (1, 2, 3):
        vals |= {
            f"l{s}_slope": 0.0,
            f"l{s}_offset": 10.0 * s,
            f"r{s}_slope": 0.0,
            f"r{s}_offset": 10.0 * s,
        }
        if s > 1:
            vals |= {f"kappa_l{s}": 1.0, f"kappa_r{s}": 1.0}
    vals |= {"vf_rise1": 2.0, "vf_rise2": 4.0, "vf_fall1": 3.0, "vf_fall2": 1.0}
    m = egpi_model([("linear", "linear")] * 3, vals, n=1)
    v = np.array([0, 1, 2, 3, 4, 5, 4, 3, 2, 1, 0], dtype=float)
    stage = m(v) / m.families(v, m.values)[0, 0]  # family s outputs s times family 1
    np.testing.assert_allclose(stage, [1, 1, 2, 2, 3, 3, 1, 2, 2, 3, 3])


def test_scale_gauge_of_lam():
    """(a, r) / c, lam * c, sigma * c leave the output unchanged: lam is redundant,
    which is why fits hold it fixed by default (docs/models.md)."""
    t = paper_like_params("yaw+")
    c = 3.7
    scaled = {
        k: x / c for k, x in t.items() if k in ("a1", "a2", "a3", "a4", "a5", "a6", "r1", "rn")
    }
    scaled |= {"lam": t["lam"] * c, "sigma": t["sigma"] * c}
    m = i2ris_egpi_model()
    np.testing.assert_allclose(m.evaluate_dict(V, t | scaled), m.evaluate_dict(V, t), atol=1e-9)


def test_with_values_returns_new_model():
    m = gpi_model()
    m2 = m.with_values({"a1": 0.01})
    assert m.value_dict()["a1"] == 7.0e-3 and m2.value_dict()["a1"] == 0.01
    assert m.with_fixed(fixed=("sigma",)).parameters[5].fixed
    with pytest.raises(KeyError):
        m.with_values({"nope": 1.0})
    with pytest.raises(ValueError):
        m.with_values(np.zeros(3))
    with pytest.raises(ValueError):
        m.evaluate(Signals(v=V), np.zeros(3))


def test_random_params_are_plausible():
    for seed in range(10):
        t = random_i2ris_egpi_params(np.random.default_rng(seed))
        y = i2ris_egpi_model(**t)(triangle([0, V_MAX_COUNTS, 0]))
        assert 28.0 <= np.ptp(y) <= 47.0  # bending range 30-45 deg (+ backlash shape)
        assert 0 < t["v_f"] < V_MAX_COUNTS and t["kappa"] > 1
        assert all(t[k] > 0 for k in ("a1", "a3", "a5", "lam", "sigma", "r1", "rn"))


def test_paper_like_presets_fixed_and_distinct():
    sets = [paper_like_params(d) for d in DATASETS]
    assert sets[0] == paper_like_params("yaw+")
    assert len({round(s["a1"], 12) for s in sets}) == 4
    with pytest.raises(KeyError):
        paper_like_params("roll+")


def test_loading_trajectory(rng):
    t, v = loading_trajectory(rng, n_cycles=4, rate_hz=20.0, speed_counts_s=500.0)
    assert np.allclose(np.diff(t), 1 / 20.0)
    assert v.min() == 0 and v.max() == V_MAX_COUNTS and np.all(v == np.round(v))
    holds = np.sum(np.diff(v) == 0)
    assert holds >= 4 * 2 * 15  # pauses of 1 s at top and bottom, 20 Hz
    _, v2 = loading_trajectory(rng, n_samples=1234)
    assert v2.size == 1234


def test_registry_builds_every_kind_with_the_same_defaults():
    classes = {"gpi": GPIModel, "egpi": I2RISEGPIModel, "egpi_c": ContinuousEGPIModel}
    assert set(MODEL_KINDS) == set(classes)
    for kind in MODEL_KINDS:
        m = model_for_kind(kind, n=12, a1=0.01)
        assert type(m) is classes[kind] and m.name == kind and m.n == 12
        assert m.value_dict()["a1"] == 0.01
        if kind != "gpi":
            assert m.deadband_counts == i2ris_egpi_model().deadband_counts
    with pytest.raises(CalibError, match="unknown model 'pgi'"):
        model_for_kind("pgi")
    with pytest.raises(CalibError, match="model 'gpi'"):
        model_for_kind("gpi", kappa=3.0)


def test_only_the_paper_egpi_steps_at_its_flag_point():
    """Registry ``output_steps`` (the report prefers EGPI_C over such a kind, compensate
    says its output steps at v_f): the paper's EGPI alone, not its continuous form."""
    from i2ris_calib.hysteresis.registry import KINDS

    assert [k.kind for k in KINDS if k.output_steps] == ["egpi"]


def test_parameter_fields_after_the_name_are_keyword_only():
    """``Parameter("a1", 0.5)`` is refused: a positional 0.5 could be a value or a bound."""
    with pytest.raises(TypeError):
        Parameter("a1", 0.5)  # type: ignore[misc]
    p = Parameter("a1", value=0.5, lower=0.0, upper=1.0)
    assert (p.name, p.value, p.lower, p.upper, p.fixed) == ("a1", 0.5, 0.0, 1.0, False)
