"""Inversion from a known history (issue 21): the state a conditioning sweep or the
commands sent before leave, against the forward model over the whole sequence (truth)."""

from __future__ import annotations

import numpy as np
import pytest

from i2ris_calib.compensation import compensate
from i2ris_calib.compensation.inverse import forward
from i2ris_calib.compensation.safety import conditioning_sweep
from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.pipeline import model_from_params
from i2ris_calib.hysteresis.presets import gpi_values, paper_like_params

KINDS = ("gpi", "egpi", "egpi_c")
P = paper_like_params("yaw+")
T = np.arange(0, 8, 0.01)
TARGET = 15 + 6 * np.sin(T)
KW = dict(v_limits=(0.0, 6000.0), max_rate=3000.0)


def _model(kind):
    return model_from_params(kind, gpi_values(P) if kind == "gpi" else P, 30, 2.0)


def _walk(seed, n=400):
    rng = np.random.default_rng(seed)
    knots = rng.uniform(0, 6000, 9)
    return np.rint(np.interp(np.linspace(0, 8, n), np.arange(9), knots))


def _past(seed):
    """A random walk, then up to 5500 and down to 2000 counts: the robot at 2000 on a
    falling branch, which its state at rest there is not."""
    w = _walk(seed)
    return np.concatenate((w, np.linspace(w[-1], 5500.0, 60), np.linspace(5500.0, 2000.0, 60)))


@pytest.mark.parametrize("kind", KINDS)
def test_one_sample_history_is_the_start_from_rest(kind):
    m = _model(kind)
    a = compensate(m, TARGET, T, v_initial=300.0, **KW)
    b = compensate(m, TARGET, T, v_history=[300.0], **KW)
    np.testing.assert_array_equal(a.commands, b.commands)
    np.testing.assert_array_equal(a.entry_commands, b.entry_commands)
    np.testing.assert_allclose(a.predicted_deg, b.predicted_deg, atol=1e-12)


@pytest.mark.parametrize("kind", KINDS)
def test_prediction_is_the_model_over_history_entry_and_commands(kind):
    m = _model(kind)
    hist = np.concatenate((_walk(1), [1000.0]))
    r = compensate(m, TARGET, T, v_history=hist, **KW)
    v = np.concatenate((hist, r.entry_commands, r.commands))
    tt = np.concatenate((r.history_t_s, r.entry_t_s, T))
    y = forward(m, v, tt)
    np.testing.assert_allclose(r.predicted_deg, y[-T.size :], atol=1e-10)
    np.testing.assert_allclose(r.history_predicted_deg, y[: hist.size], atol=1e-10)
    assert np.all(np.diff(tt) > 0) and r.history_commands.size == hist.size
    # the inverse meets its model from that state as from rest
    assert np.sqrt(np.mean(r.error_deg[r.reachable] ** 2)) < 0.01


@pytest.mark.parametrize("kind", KINDS)
def test_after_a_sweep_the_unknown_past_does_not_matter(kind):
    # truth: a play operator's memory is wiped by a monotone move across the range, so
    # two different pasts followed by the same conditioning sweep leave the same state:
    # the same commands, and the plant (= the model) from either past tracks them
    m = _model(kind)
    sweep = conditioning_sweep(2000.0, 0.0, 6000.0, 3000.0, 0.01, 1.0, last="lo")
    outs = []
    for seed in (2, 3):
        past = _past(seed)
        r = compensate(m, TARGET, T, v_history=np.concatenate((past, sweep)), **KW)
        outs.append(r)
    np.testing.assert_array_equal(outs[0].commands, outs[1].commands)
    np.testing.assert_allclose(outs[0].predicted_deg, outs[1].predicted_deg, atol=1e-9)
    # whereas from rest, without the sweep, the plant that has that past misses more
    rest = compensate(m, TARGET, T, v_initial=2000.0, **KW)
    past = _past(2)
    y = forward(m, np.concatenate((past, rest.entry_commands, rest.commands)))[-T.size :]
    e_rest = np.sqrt(np.mean((y - TARGET) ** 2))
    e_sweep = np.sqrt(np.mean(outs[0].error_deg ** 2))
    e_floor = np.sqrt(np.mean(rest.error_deg**2))  # the model's own miss (rate limit)
    assert e_sweep <= 1.01 * e_floor + 1e-9 and e_rest > e_sweep + 0.1


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"v_history": [0.0, 7000.0]}, "outside v_limits"),
        ({"v_history": [0.0, np.nan]}, "finite"),
        ({"v_history": [0.0, 10.0], "v_initial": 0.0}, "not the history's last"),
        ({"v_other_history": [0.0]}, "needs v_history"),
    ],
)
def test_bad_history_one_line(kw, match):
    with pytest.raises(CalibError, match=match) as exc:
        compensate(_model("gpi"), TARGET, T, **KW, **kw)
    assert "\n" not in str(exc.value)
