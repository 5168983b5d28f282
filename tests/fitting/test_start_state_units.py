"""A fit in a rescaled input unit (volts: ``fit_kind`` divides the input by
``input_scale``) returns its start state in the input's own unit: the levels of
``FitResult.initial_state`` and its sentence are converted back with the parameters, so
``predict`` on the recording's own signals runs the pre-history the fit ran."""

from __future__ import annotations

import numpy as np
import pytest

from i2ris_calib.fitting.config import FitConfig
from i2ris_calib.fitting.fit import fit_cost
from i2ris_calib.fitting.metrics import NAN_METRICS
from i2ris_calib.fitting.pipeline import (
    _scaled_fit,
    fit_kind,
    input_scale,
    split_masks,
    unfitted_model,
)
from i2ris_calib.fitting.prehistory import InitialState, level_bounds, state_text
from i2ris_calib.fitting.result import FitResult
from i2ris_calib.hysteresis.effects import model_values
from i2ris_calib.model import Signals

NOISE_DEG = 0.05
VOLTS = 1e-3  # volts per count: max |v| 4 V, which fit_kind rescales
T = np.arange(0, 60, 0.05)
V_COUNTS = np.round(4000 * np.sin(2 * np.pi * T / 12) * np.minimum(1, T / 6))
V_OTHER = np.round(3000 * np.cos(2 * np.pi * T / 12) * np.minimum(1, T / 6))
#: The recording starts at t = 28 s: input 3464 counts (3.464 V), falling from the peak.
K0 = 560


def _levels(st: InitialState) -> list[float]:
    fields = (st.v_from, st.v_turn, st.v_turn2, st.v_turn3, st.v0, st.other_v_from,
              st.other_v_turn, st.other_v_turn2, st.v0_other)  # fmt: skip
    return [x for x in fields if x is not None]


def test_a_fit_in_volts_keeps_its_start_state_in_volts():
    """GPI truth, a recording in volts starting mid-loop on the falling branch: the
    state's levels are in volts (the first input exactly the recording's), its sentence
    says so, and ``predict`` on the volts signals reproduces the fit's cost."""
    cfg = FitConfig()
    truth = unfitted_model("gpi", V_COUNTS, cfg, None)
    y = truth.evaluate(Signals(v=V_COUNTS, t_s=T), model_values(truth))
    rng = np.random.default_rng(7)
    v = V_COUNTS[K0:] * VOLTS
    theta = y[K0:] + rng.normal(0, NOISE_DEG, v.size)
    assert input_scale(v) != 1.0 and v[1] < v[0]  # rescaled; falling at the start
    s = Signals(v=v, t_s=T[K0:] - T[K0])
    res = fit_kind("gpi", s, theta, cfg)

    st = res.initial_state
    assert st is not None
    assert st.v0 == v[0]  # exactly: predict knows the fit's own data by it
    assert st.v_from > v[0]  # turned above the first input: the falling branch
    lo, hi = level_bounds(v)
    assert all(lo <= x <= hi for x in _levels(st)), st  # volts, not counts
    assert st.text == state_text(st)
    assert f"input {v[0]:.6g}," in st.text and "a falling branch" in st.text

    used = np.isfinite(theta) & ~split_masks(v, cfg)[1]
    cost = float(np.sum((res.predict(s) - theta)[used] ** 2))
    assert cost == pytest.approx(res.chisqr, rel=1e-6)
    # the truth's noise, n sigma^2 (a fit at the truth: within a few tens of percent)
    assert res.chisqr < 1.5 * used.sum() * NOISE_DEG**2


def _result(model, st: InitialState) -> FitResult:
    """A FitResult carrying ``model``'s values and the start state ``st``."""
    names = [p.name for p in model.parameters]
    x = model_values(model)
    return FitResult(
        model, dict(zip(names, map(float, x), strict=True)), dict.fromkeys(names, 0.0),
        np.zeros((len(names), len(names))), np.zeros(0), NAN_METRICS, NAN_METRICS,
        0.0, 0.0, True, "", 1, 0, tuple(names), initial_state=st,
    )  # fmt: skip


def test_a_coupled_start_state_converts_with_the_other_motors_levels():
    """agpi_coupled (a state of the other motor's input too): the counts result converted
    to volts (as ``fit_kind`` converts a fit back) predicts the same angles on the volts
    signals and costs the same (``fit_cost`` after its state); every level, the other
    motor's too, is the counts level times the scale, the first inputs exactly the
    recording's."""
    cfg = FitConfig()
    model = unfitted_model("agpi_coupled", V_COUNTS, cfg, None)
    s_counts = Signals(v=V_COUNTS[K0:], t_s=T[K0:] - T[K0], v_other=V_OTHER[K0:])
    s_volts = Signals(v=s_counts.v * VOLTS, t_s=s_counts.t_s, v_other=s_counts.v_other * VOLTS)
    st = InitialState(
        4100.0, 0, float(s_counts.v[0]), "", 0, v_turn=-2500.0, v_turn2=3900.0,
        v_turn3=-4400.0, other_v_turn=-3100.0, other_v_from=-1200.0, v0_other=float(s_counts.v_other[0]),
        other_v_turn2=2800.0,
    )  # fmt: skip
    st = InitialState(**st.as_dict() | {"text": state_text(st)})
    counts = _result(model, st)
    volts = _scaled_fit(counts, VOLTS, signals=s_volts)

    sv = volts.initial_state
    assert sv.v0 == s_volts.v[0] and sv.v0_other == s_volts.v_other[0]
    assert _levels(sv) == pytest.approx([x * VOLTS for x in _levels(st)], rel=1e-15)
    assert sv.text == state_text(sv) and "input 3.464," in sv.text and "to -1.5 " in sv.text
    assert "pre-history from -4.4 via 3.9 via -2.5 via 4.1," in sv.text  # four own levels

    y = counts.predict(s_counts)
    assert not np.allclose(y, counts.predict(s_counts, initial_state=False))  # it matters
    np.testing.assert_allclose(volts.predict(s_volts), y, rtol=0, atol=1e-9)
    theta = y + np.random.default_rng(3).normal(0, NOISE_DEG, y.size)
    c_counts = fit_cost(counts.model, s_counts, theta, initial_state=st)
    c_volts = fit_cost(volts.model, s_volts, theta, initial_state=sv)
    assert c_volts == pytest.approx(c_counts, rel=1e-9)
