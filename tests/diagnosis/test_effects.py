"""Effect catalogue: neutral values, hand-checked transforms, build_model errors."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from i2ris_calib.compensation.inverse import SUPPORTED_EFFECTS
from i2ris_calib.diagnosis.results import (
    SEPARATING_FROM_BASE,
    separating_experiment,
)
from i2ris_calib.diagnosis.stats import RATE_EFFECTS
from i2ris_calib.diagnosis.synthetic import STRENGTHS, excitation
from i2ris_calib.errors import CalibError
from i2ris_calib.hysteresis.codec import model_from_dict, model_to_dict
from i2ris_calib.hysteresis.effect_kernels import first_order_lag, play_varying, staged_backlash
from i2ris_calib.hysteresis.effects import (
    CATALOGUE,
    add_effect,
    base_of,
    build_model,
    effects_of,
    model_values,
    other_axis_moves,
)
from i2ris_calib.hysteresis.models import gpi_model
from i2ris_calib.hysteresis.registry import MODEL_KINDS, model_for_kind
from i2ris_calib.model import Model, Parameter, Signals


def _signals(seed: int = 0) -> Signals:
    rng = np.random.default_rng(seed)
    t, v = excitation(rng, n_cycles=3, rate_hz=20.0)
    return Signals(
        v=v, t_s=t, v_other=np.linspace(0, 3000, t.size), theta_other_deg=np.linspace(0, 20, t.size)
    )


@pytest.mark.parametrize("name", list(CATALOGUE))
def test_neutral_effect_leaves_the_model_unchanged(name, egpi):
    sig = _signals()
    ext = add_effect(egpi, name)
    assert isinstance(ext, Model)
    y0 = egpi.evaluate(sig, model_values(egpi))
    y1 = ext.evaluate(sig, model_values(ext))
    np.testing.assert_allclose(y1, y0, atol=1e-12)


@pytest.mark.parametrize("name", list(CATALOGUE))
def test_parameters_are_declared_and_prefixed(name, egpi):
    ext = add_effect(egpi, name)
    own = ext.parameters[len(egpi.parameters) :]
    assert [p.name for p in own] == [f"{name}.{p.name}" for p in CATALOGUE[name].params]
    for p in own:
        assert p.lower <= p.value <= p.upper and p.unit and p.doc
    assert CATALOGUE[name].meaning


@pytest.mark.parametrize("name", list(CATALOGUE))
def test_metadata_lives_on_the_effect_and_is_consistent(name, egpi):
    """Each effect's strengths are three non-neutral sets inside its bounds (add_effect
    accepts them); its ``separating`` names earlier catalogue effects, so each pair is
    written once; the diagnosis and compensation tables are read from the effects."""
    e = CATALOGUE[name]
    assert len(e.strengths) == 3
    for values in e.strengths:
        ext = add_effect(egpi, name, values)  # CalibError outside the declared bounds
        assert not np.array_equal(ext.effect_values, e.neutral())
    earlier = list(CATALOGUE)[: list(CATALOGUE).index(name)]
    assert set(e.separating) <= set(earlier) and all(e.separating.values())
    assert STRENGTHS[name] == tuple(dict(p) for p in e.strengths)
    assert (name in RATE_EFFECTS) == e.rate and (name in SUPPORTED_EFFECTS) == e.compensated
    assert SEPARATING_FROM_BASE.get(name, "") == e.separating_from_base
    for other, text in e.separating.items():
        assert separating_experiment(other, name) == text


def test_the_diagnosis_re_exports_the_model_layers_effects_and_codec():
    """docs/diagnosis.md documents diagnosis.effects and diagnosis.serialize: the same
    objects as in the model layer."""
    import i2ris_calib.diagnosis.effects as old_effects
    import i2ris_calib.diagnosis.serialize as old_serialize
    import i2ris_calib.hysteresis.codec as codec
    import i2ris_calib.hysteresis.effects as effects

    assert all(getattr(old_effects, n) is getattr(effects, n) for n in old_effects.__all__)
    assert old_serialize.model_from_dict is codec.model_from_dict
    assert old_serialize.SCHEMA == codec.MODEL_SCHEMA == "i2ris-calib.model/1"


def test_with_values_round_trip_and_stacking(egpi):
    m = build_model(egpi, {"time_delay": {"tau_s": 0.1}, "creep": {"gain": 0.2, "tau_s": 1.0}})
    assert [e[0] for e in effects_of(m)] == ["time_delay", "creep"]
    assert base_of(m) is egpi
    x = model_values(m)
    x[-1] = 2.0
    m2 = m.with_values(x)
    assert effects_of(m2)[-1][2] == {"gain": 0.2, "tau_s": 2.0}
    assert effects_of(m)[-1][2]["tau_s"] == 1.0  # original unchanged
    twice = add_effect(add_effect(egpi, "backlash", {"width_counts": 10.0}), "backlash")
    assert twice.parameters[-1].name == "backlash_2.width_counts"


def test_extended_model_is_callable_and_values_mean_what_they_mean_for_the_base(egpi):
    """``values`` is the whole current vector (base first), as for a ParametricModel,
    and calling the model evaluates it there."""
    m = build_model(egpi, {"time_delay": {"tau_s": 0.1}, "creep": {"gain": 0.2, "tau_s": 1.0}})
    assert m.values.shape == (len(egpi.parameters) + 3,)
    np.testing.assert_array_equal(m.values[: len(egpi.parameters)], egpi.values)
    np.testing.assert_array_equal(m.values[-3:], [0.1, 0.2, 1.0])
    assert m.value_dict()["creep.tau_s"] == 1.0
    t = np.arange(0.0, 20.0, 1 / 30)
    v = 3000.0 * (1 - np.cos(2 * np.pi * t / 10.0))
    sig = Signals(v=v, t_s=t)
    np.testing.assert_array_equal(m(sig), m.evaluate(sig, model_values(m)))
    assert not np.allclose(m(sig), egpi(sig))  # the effects act
    # the effect's declared parameters are the models' one Parameter type
    assert all(isinstance(p, Parameter) for p in CATALOGUE["creep"].params)


def test_build_model_rejects_bad_names_and_values(egpi):
    with pytest.raises(CalibError, match="did you mean 'time_delay'"):
        build_model(egpi, {"time_delya": {}})
    with pytest.raises(CalibError, match="did you mean 'tau_s'"):
        build_model(egpi, {"time_delay": {"tau": 0.1}})
    with pytest.raises(CalibError, match="outside"):
        build_model(egpi, {"time_delay": {"tau_s": -1.0}})
    assert build_model(egpi, {}) is egpi


def test_play_operator_by_hand():
    v = np.array([0.0, 1, 2, 3, 2, 1, 0])
    u = play_varying(v, np.ones(7))
    np.testing.assert_array_equal(u, [0, 0, 1, 2, 2, 2, 1])


def test_staged_backlash_by_hand():
    # falls from 10 to 0 then rises back; stage flag at 6, slack 2
    v = np.array([10.0, 8, 6, 5, 4, 3, 2, 0, 1, 2, 3, 5])
    u = staged_backlash(v, 6.0, 2.0)
    # above the flag u = v; the first 2 counts below it are slack (u holds at 6);
    # then u = v + 2; the rise pays the slack back first (u holds at 2)
    np.testing.assert_array_equal(u, [10, 8, 6, 6, 6, 5, 4, 2, 2, 2, 3, 5])


def test_time_delay_shifts_the_input(linear):
    t = np.arange(0, 5, 0.01)
    v = 100.0 * t
    m = build_model(linear, {"time_delay": {"tau_s": 0.25}})
    y = m.evaluate(Signals(v=v, t_s=t), model_values(m))
    late = t >= 0.25
    np.testing.assert_allclose(y[late], 0.01 * 100.0 * (t[late] - 0.25), atol=1e-9)


def test_creep_relaxes_exponentially_after_a_step(linear):
    t = np.arange(0, 10, 0.05)
    v = np.where(t >= 1.0, 1000.0, 0.0)
    m = build_model(linear, {"creep": {"gain": 0.3, "tau_s": 2.0}})
    y = m.evaluate(Signals(v=v, t_s=t), model_values(m))
    k = t >= 1.0
    # a sample's value is held over the interval before it (zero-order hold), so
    # the step acts from the previous sample time, t = 0.95 s
    expected = 10.0 * (1 - 0.3 * np.exp(-(t[k] - 0.95) / 2.0))
    np.testing.assert_allclose(y[k], expected, rtol=1e-9)


def test_first_order_lag_handles_uneven_sampling():
    t = np.array([0.0, 0.5, 0.6, 2.0])
    x = first_order_lag(np.array([0.0, 1.0, 1.0, 1.0]), t, 1.0)
    # input 1 held from t = 0 on: x = 1 - exp(-t) exactly, whatever the spacing
    np.testing.assert_allclose(x[1:], 1 - np.exp(-t[1:]), rtol=1e-12)


def test_saturation_flattens_only_beyond_the_knee(linear):
    v = np.linspace(-5000, 5000, 1001)
    m = build_model(linear, {"saturation": {"knee_deg": 30.0, "limit_deg": 5.0}})
    y = m.evaluate(Signals(v=v), model_values(m))
    inside = np.abs(0.01 * v) <= 30.0
    np.testing.assert_allclose(y[inside], 0.01 * v[inside])
    assert np.all(np.abs(y) < 35.0) and np.all(np.diff(y) > 0)
    np.testing.assert_allclose(y, -y[::-1])


def test_backlash_holds_output_after_a_reversal(linear):
    v = np.concatenate([np.arange(0, 1001, 10.0), np.arange(990, 0, -10.0)])
    m = build_model(linear, {"backlash": {"width_counts": 200.0}})
    y = m.evaluate(Signals(v=v), model_values(m))
    top = int(np.argmax(v))
    # after the reversal the input travels 200 counts before the output moves
    held = (v[top:] >= 800.0) & (np.arange(v.size)[top:] >= top)
    assert np.ptp(y[top:][held]) == 0.0
    assert y[top:][v[top:] < 790.0].max() < y[top]


def test_dead_zone_is_the_tao_kokotovic_dead_band(linear):
    """No motion until |v| > d, then the model of v - d, rising or falling, with no
    memory of the last reversal (unlike backlash)."""
    v = np.concatenate([np.arange(0, 1001, 10.0), np.arange(990, -1001, -10.0)])
    m = build_model(linear, {"dead_zone": {"d_counts": 300.0}})
    y = m.evaluate(Signals(v=v), model_values(m))
    expect = 0.01 * np.sign(v) * np.maximum(np.abs(v) - 300.0, 0.0)
    np.testing.assert_allclose(y, expect)
    assert np.all(y[np.abs(v) <= 300.0] == 0.0)


def _ramps(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Ramps between random levels at random speeds with holds (30 Hz, whole counts)."""
    rng = np.random.default_rng(seed)
    kt, kv = [0.0], [0.0]
    for i in range(16):
        kt += [kt[-1] + rng.uniform(1.0, 8.0), 0.0]
        kv += [rng.uniform(0.3, 1.0) * 6000.0 if i % 2 == 0 else rng.uniform(0.0, 0.4) * 6000.0]
        kt[-1] = kt[-2] + rng.uniform(0.3, 2.0)
        kv.append(kv[-1])
    t = np.arange(0.0, kt[-1], 1 / 30)
    return t, np.round(np.interp(t, kt, kv))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_rate_dependent_play_equals_the_play_of_a_rate_dependent_play(seed):
    """Al Janaideh-Krejci thresholds ``r + beta |dv/dt|``: a play of the time-varying
    threshold ``r + c(t)`` equals a play of ``r`` after a play of ``c(t)`` (what the
    catalogue's ``rate_dependent_thresholds`` applies ahead of the base model's
    operators), to rounding, on ramps of varied speed with holds."""
    t, v = _ramps(seed)
    c = 0.4 * np.abs(np.gradient(v, t))
    for r in (0.0, 50.0, 400.0):
        direct = play_varying(v, r + c)
        composed = play_varying(play_varying(v, c), np.full(v.shape, r))
        np.testing.assert_allclose(composed, direct, atol=1e-9)
        assert np.max(np.abs(direct - play_varying(v, np.full(v.shape, r)))) > 100.0


@pytest.mark.parametrize(
    ("a3", "a4", "absorbed"), [(7e-3, 0.3, True), (8e-3, 0.3, True), (6e-3, 0.3, False)]
)
def test_backlash_on_a_gpi_input_is_a_gpi_with_moved_offsets_unless_bands_invert(a3, a4, absorbed):
    """Why a backlash can be *not excluded*: a play of half-width h on the input of a
    GPI with linear envelopes equals the GPI with ``a2 - a1 h`` and ``a4 + a3 h``
    exactly while every operator band is non-inverted (``gamma_l(v) - r <=
    gamma_r(v) + r``; here a3 >= a1, a4 > a2). Where the r = 0 band inverts (a3 < a1
    at high input) the GPI jumps at a reversal and the backlash holds first: they
    differ."""
    t, v = _ramps(4)
    h = 150.0
    g = gpi_model(a1=7e-3, a2=-0.2, a3=a3, a4=a4)
    x = g.values
    played = g.evaluate(Signals(v=play_varying(v, np.full(v.shape, h))), x)
    moved = x.copy()
    moved[1] -= x[0] * h
    moved[3] += x[2] * h
    diff = np.max(np.abs(played - g.evaluate(Signals(v=v), moved)))
    assert np.max(np.abs(played - g(v))) > 1.0  # the backlash itself is large
    assert (diff < 1e-9) if absorbed else (diff > 1.0)


def test_rate_dependent_thresholds_widen_with_speed_and_relax_at_rest(linear):
    t = np.arange(0, 12, 0.01)
    knots_t = [0, 1, 3, 5, 6, 12]
    knots_v = [0, 0, 1000, 1000, 3000, 3000]  # 500 counts/s, pause, 2000 counts/s, pause
    v = np.interp(t, knots_t, knots_v)
    eff = CATALOGUE["rate_dependent_thresholds"]
    sig = Signals(v=v, t_s=t)
    h = eff.half_width(sig, np.array([0.1]))
    np.testing.assert_allclose(h[(t > 1.5) & (t < 2.5)], 50.0, rtol=1e-6)
    np.testing.assert_allclose(h[(t > 5.3) & (t < 5.7)], 200.0, rtol=1e-6)
    assert np.all(h[(t > 6.2)] == 0.0)  # thresholds fall back at rest
    m = build_model(linear, {"rate_dependent_thresholds": {"beta_s": 0.1}})
    y = m.evaluate(sig, model_values(m))
    # while moving the output lags by the widened threshold, at rest it catches up
    np.testing.assert_allclose(y[(t > 5.3) & (t < 5.7)], 0.01 * (v - 200.0)[(t > 5.3) & (t < 5.7)])
    np.testing.assert_allclose(y[t > 6.2], 30.0)


def test_rate_dependent_weights_scale_the_output_with_speed(linear):
    t = np.arange(0, 12, 0.01)
    v = np.interp(t, [0, 1, 3, 5, 6, 12], [0, 0, 1000, 1000, 3000, 3000])
    m = build_model(linear, {"rate_dependent_weights": {"gain": 0.2}})
    y = m.evaluate(Signals(v=v, t_s=t), model_values(m))
    fast = (t > 5.3) & (t < 5.7)  # the 95th-percentile speed: gain 1.2
    np.testing.assert_allclose(y[fast], 1.2 * 0.01 * v[fast], rtol=1e-6)
    slow = (t > 1.5) & (t < 2.5)  # a quarter of that speed
    np.testing.assert_allclose(y[slow], 1.05 * 0.01 * v[slow], rtol=1e-6)
    np.testing.assert_allclose(y[t > 6.2], 30.0)


def test_log_creep_gains_the_same_per_decade_after_a_step(linear):
    t = np.arange(0, 400, 0.01)
    v = np.where(t >= 1.0, 1000.0, 0.0)  # 10 deg step at t = 1 s
    m = build_model(linear, {"creep_log": {"gamma_per_decade": 0.05, "tau0_s": 0.1}})
    y = m.evaluate(Signals(v=v, t_s=t), model_values(m))
    at = [np.interp(1.0 + dt, t, y) for dt in (1.0, 10.0, 100.0)]
    # 0.05 x 10 deg = 0.5 deg per decade (within the ripple of 2 relaxation times/decade)
    np.testing.assert_allclose(np.diff(at), 0.5, rtol=0.15)
    assert np.all(np.diff(y[t > 1.0]) >= 0)


def test_axis_coupling_adds_the_other_angle(linear):
    sig = _signals()
    m = build_model(
        linear, {"axis_coupling": {"gain_angle": 0.2, "gain_input_deg_per_count": 1e-3}}
    )
    y = m.evaluate(sig, model_values(m))
    np.testing.assert_allclose(y, 0.01 * sig.v + 0.2 * sig.theta_other_deg + 1e-3 * sig.v_other)


@settings(max_examples=30, deadline=None)
@given(
    st.lists(st.floats(-1e3, 1e3), min_size=2, max_size=60),
    st.floats(0.0, 200.0),
)
def test_play_output_stays_within_the_band(vals, h):
    v = np.array(vals)
    u = play_varying(v, np.full(v.size, h))
    assert np.all(u >= v - h - 1e-9) and np.all(u <= v + h + 1e-9)
    # the output only moves when the input pushes it to the band's edge
    moved = np.flatnonzero(np.diff(u) != 0) + 1
    assert np.allclose(np.abs(u[moved] - v[moved]), h)


def test_coupling_needs_the_other_axis_to_move():
    t = np.arange(0, 10, 0.1)
    noise = np.random.default_rng(1).normal(0, 0.2, t.size)
    assert not other_axis_moves(Signals(v=t, v_other=np.zeros_like(t), theta_other_deg=noise))
    assert not other_axis_moves(Signals(v=t, theta_other_deg=noise))
    assert other_axis_moves(Signals(v=t, theta_other_deg=10 * np.sin(t) + noise))
    assert other_axis_moves(Signals(v=t, v_other=t))
    assert CATALOGUE["axis_coupling"].available(Signals(v=t)) is not None


@pytest.mark.parametrize("kind", MODEL_KINDS)
def test_saved_extended_model_rebuilds_through_the_kind_registry(kind):
    """final_model.json round trip for every registry kind: same names, values and
    output; an unknown kind is a one-line CalibError."""
    base = model_for_kind(kind, n=12).with_fixed(fixed=("a1",))
    m = add_effect(add_effect(base, "time_delay", {"tau_s": 0.1}), "creep", {"gain": 0.2})
    back = model_from_dict(model_to_dict(m))
    assert back.names == m.names
    assert [p.fixed for p in back.parameters] == [p.fixed for p in m.parameters]
    np.testing.assert_array_equal(back.values, m.values)
    t = np.arange(0.0, 20.0, 1 / 30)
    sig = Signals(v=3000.0 * (1 - np.cos(2 * np.pi * t / 10.0)), t_s=t)
    np.testing.assert_allclose(back(sig), m(sig), atol=1e-12)
    rec = model_to_dict(m)
    rec["base"]["kind"] = "pi"
    with pytest.raises(CalibError, match="unknown model 'pi'"):
        model_from_dict(rec)
