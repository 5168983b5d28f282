"""Safe commands (issue 21): no up-and-back spikes, the rate limit with its entry ramp,
the fastest input move of a recording."""

from __future__ import annotations

import numpy as np
import pytest

from i2ris_calib.compensation import compensate
from i2ris_calib.compensation.inverse import forward
from i2ris_calib.compensation.rate import max_input_rate
from i2ris_calib.compensation.safety import entry_ramp, find_spikes
from i2ris_calib.fitting.pipeline import model_from_params

# an EGPI fitted by 'fit' to a synthetic yaw- recording (the issue's case): its inverse
# of -15 - 10 sin(t) (yaw-) went 255 -> 914 -> 255 counts at t = 4.67 s (a reversal
# below v_f switches the shown family; the far side met the target 0.003 deg better)
FITTED_EGPI = {
    "a1": 0.010505373502177229, "a2": 1.9778155073047947, "a3": 0.010008732677759664,
    "a4": 2.9554273145536123, "a5": 0.037204789280279545, "a6": -23.703462022860226,
    "lam": 0.041678395368393586, "sigma": 0.37907772763448844, "r1": 0.24145309119231909,
    "rn": 6.446306528773251, "kappa": 12.83040168958112, "v_f": 4389.0,
}  # fmt: skip
DEADBAND = 1.81580674632517


def _issue_case():
    model = model_from_params("egpi", FITTED_EGPI, 30, DEADBAND)
    t = np.arange(0, 20, 0.01)
    return model, t, 15 + 10 * np.sin(t)


def test_inverse_had_a_spike_and_repair_removes_it():
    model, t, target = _issue_case()
    raw = compensate(model, target, t, v_limits=(0, 6000), v_initial=0.0, repair_spikes=False)
    spikes = find_spikes(raw.commands, raw.predicted_deg, target, raw.tol_deg, 6000, 1.0)
    assert spikes.size >= 1  # the issue's up-and-back spike
    res = compensate(model, target, t, v_limits=(0, 6000), v_initial=0.0)
    assert find_spikes(res.commands, res.predicted_deg, target, res.tol_deg, 6000, 1.0).size == 0
    assert res.spikes_left == 0 and res.flags["spike_removed"].sum() >= 1
    d = np.diff(res.commands)
    assert not np.any((np.abs(d[:-1]) > 60) & (np.abs(d[1:]) > 60) & (d[:-1] * d[1:] < 0))
    # the held sample costs little: still within 0.05 deg everywhere
    assert np.max(np.abs(res.error_deg)) < 0.05


@pytest.mark.parametrize("rate", [420.0, 5000.0])
def test_rate_limit_holds_including_the_entry_ramp(rate):
    model, t, target = _issue_case()
    res = compensate(model, target, t, v_limits=(0, 6000), v_initial=0.0, max_rate=rate)
    assert res.entry_commands.size > 0 and res.entry_commands[0] > 0
    u = np.concatenate(([0.0], res.entry_commands, res.commands))
    tt = np.concatenate(([res.entry_t_s[0] - 0.01], res.entry_t_s, t))
    assert np.max(np.abs(np.diff(u)) / np.diff(tt)) <= rate + 1e-6
    assert res.max_rate_seen() <= rate + 1e-6
    assert np.all(np.diff(res.entry_commands) >= 0)  # a monotone entry
    # the predicted angle is the model over entry + commands from rest
    both = forward(model, np.concatenate((res.entry_commands, res.commands)),
                   np.concatenate((res.entry_t_s, t)), 0.0)  # fmt: skip
    np.testing.assert_allclose(res.predicted_deg, both[res.entry_commands.size :], atol=1e-9)
    assert find_spikes(res.commands, res.predicted_deg, target, res.tol_deg, 6000, 1.0).size == 0


def test_less_than_a_count_per_sample_still_moves():
    model, _, _ = _issue_case()
    t = np.arange(0, 5, 0.001)  # 1 kHz, 400 counts/s = 0.4 counts per sample
    res = compensate(model, np.full(t.size, 8.0), t, v_limits=(0, 6000), v_initial=0.0,
                     max_rate=400.0, entry=False)  # fmt: skip
    assert res.commands[-1] > 1000  # moved (it stayed at 0 before)
    moves = np.flatnonzero(np.diff(np.concatenate(([0.0], res.commands))))
    gaps = np.diff(t[moves])
    assert np.all(gaps >= 1 / 400 - 1e-9)


def test_max_input_rate_and_entry_ramp():
    t = np.arange(0, 10, 1 / 30)
    v = np.clip(400 * (t - 1), 0, 2000).round()
    assert max_input_rate(v, t) == pytest.approx(420, abs=15)
    assert max_input_rate(np.zeros(5), np.arange(5.0)) is None
    ramp = entry_ramp(0.0, 100.0, 420.0, 0.01, 1.0)
    steps = np.diff(np.concatenate(([0.0], ramp, [100.0])))
    assert np.all(steps <= 4.2) and np.all(steps > 0) and ramp.size == 24


@pytest.mark.parametrize("last", ["lo", "hi"])
def test_conditioning_sweep_reaches_both_ends_at_the_rate(last):
    from i2ris_calib.compensation.safety import conditioning_sweep

    s = conditioning_sweep(1234.0, -3000.0, 4000.0, 500.0, 0.02, 1.0, last=last)
    v = np.concatenate(([1234.0], s))
    assert np.max(np.abs(np.diff(v))) <= 500.0 * 0.02 + 1e-9
    assert np.all(v == np.rint(v))
    first, end = (4000.0, -3000.0) if last == "lo" else (-3000.0, 4000.0)
    k = int(np.flatnonzero(v == first)[0])
    assert v[-1] == end and np.all(np.diff(v[: k + 1]) * np.sign(first - 1234.0) > 0)
    assert np.all(np.diff(v[k:]) * np.sign(end - first) > 0)  # one straight move across
    # no limit: the two ends; a bad end name: ValueError
    np.testing.assert_array_equal(
        conditioning_sweep(0.0, 0.0, 10.0, np.inf, 0.01, 1.0, last=last),
        [10.0, 0.0] if last == "lo" else [0.0, 10.0][1:],
    )
    with pytest.raises(ValueError, match="last"):
        conditioning_sweep(0.0, 0.0, 10.0, 1.0, 0.01, 1.0, last="middle")
