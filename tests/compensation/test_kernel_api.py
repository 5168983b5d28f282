"""The kernel's public state API (issue 21): ``start`` / ``advance`` (the one state
update the batch and the online compensator share), ``invert(start_state=)`` and the
spike repair's ``Resume`` (only what a changed hold reaches is inverted again)."""

from __future__ import annotations

import numpy as np
import pytest

from i2ris_calib.compensation import kernel as K
from i2ris_calib.compensation.inverse import forward, kernel_params
from i2ris_calib.fitting.pipeline import model_from_params
from i2ris_calib.hysteresis.presets import gpi_values, paper_like_params
from i2ris_calib.hysteresis.registry import model_for_kind

KINDS = ("gpi", "egpi", "egpi_c", "agpi")


def _model(kind):
    if kind == "agpi":
        return model_for_kind("agpi", theta0=0.4, a1_p=0.008, a3_p=0.0072, a4_p=-1.2,
                              a1_n=0.0065, a3_n=0.006, a4_n=-0.8), (-4000.0, 4000.0)  # fmt: skip
    pp = paper_like_params("yaw+")
    return model_from_params(kind, gpi_values(pp) if kind == "gpi" else pp, 30, 2.0), (0, 6000)


@pytest.mark.parametrize("kind", KINDS)
def test_advance_is_the_forward_model(kind):
    model, (lo, hi) = _model(kind)
    rng = np.random.default_rng(1)
    v = np.rint(np.interp(np.linspace(0, 12, 900), np.arange(13), rng.uniform(lo, hi, 13)))
    code, c, r, p, kappa, vf, db = kernel_params(model)
    w, state = np.zeros((2, p.size)), np.zeros(K.STATE_SIZE)
    K.start(code, c, r, p, kappa, vf, db, v[0], True, w, state)
    ys = [state[3]]
    for x in v[1:]:  # one input at a time: the same as all at once
        ys.append(K.advance(code, c, r, p, kappa, vf, db, np.array([x]), w, state))
    np.testing.assert_allclose(ys, forward(model, v), atol=1e-10, rtol=0)


@pytest.mark.parametrize("kind", KINDS)
def test_invert_from_a_start_state_continues_an_inversion(kind):
    # inverting the second half from the state the first half left = one inversion
    model, (lo, hi) = _model(kind)
    code, c, r, p, kappa, vf, db = kernel_params(model)
    t = np.arange(1200) * 0.01
    target = (0 if kind == "agpi" else 15) + 7 * np.sin(0.9 * t) + 2 * np.sin(3.1 * t)
    args = (code, c, r, p, kappa, vf, db)
    whole = K.invert(*args, target, t, lo, hi, 4000.0, 1.0, 0.0, True, 0.01)
    h = 700
    w, state = np.zeros((2, p.size)), np.zeros(K.STATE_SIZE)
    K.start(*args, 0.0, True, w, state)
    K.advance(*args, whole[0][:h], w, state)
    tail = K.invert(*args, target[h:], t[h:], lo, hi, 4000.0, 1.0, 0.0, True, 0.01,
                    start_state=(w, state))  # fmt: skip
    # the last move's time restarts one interval before the tail (as after a history):
    # with 4000 counts/s at 100 Hz (40 counts a step) it never matters
    for a, b in zip(whole, tail, strict=True):
        np.testing.assert_array_equal(a[h:], b)


@pytest.mark.parametrize("kind", ["egpi", "agpi"])
def test_resume_after_new_holds_is_the_whole_inversion(kind):
    model, (lo, hi) = _model(kind)
    code, c, r, p, kappa, vf, db = kernel_params(model)
    n = 5 * K.RESUME_GRID + 123
    t = np.arange(n) * 0.01
    target = (0 if kind == "agpi" else 15) + 7 * np.sin(0.9 * t) + 2 * np.sin(3.1 * t)
    args = (code, c, r, p, kappa, vf, db, target, t, lo, hi, 3000.0, 1.0, 0.0, True, 0.01)
    rng = np.random.default_rng(2)
    hold = np.zeros(n, bool)
    hold[rng.choice(n, 5, replace=False)] = True
    resume = K.Resume()
    K.invert(*args, hold=hold, resume=resume)
    for _ in range(2):  # two repair rounds, each a few new holds anywhere
        new = np.sort(rng.choice(np.flatnonzero(~hold), 4, replace=False))
        hold[new] = True
        resume.changed = new
        got = K.invert(*args, hold=hold, resume=resume)
        want = K.invert(*args, hold=hold)
        for a, b in zip(got, want, strict=True):
            assert a.dtype == b.dtype and np.array_equal(a, b)
