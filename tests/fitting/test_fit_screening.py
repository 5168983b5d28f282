"""The fitter's cheaper search paths (issue 20 item 7): screening on a row subsample,
the early stop of a start far above the best, the initial-state level profile with the
other motor's terms computed once, the active-set bounded polish.

Speed figures are in benchmarks/bench_speed.py; these tests check values only.
"""

from __future__ import annotations

import numpy as np
import pytest

from i2ris_calib.fitting import fit as F
from i2ris_calib.fitting.config import FitConfig
from i2ris_calib.fitting.pipeline import fit_kind
from i2ris_calib.hysteresis.coupled import coupled_two_tendon_model
from i2ris_calib.hysteresis.models import i2ris_egpi_model
from i2ris_calib.hysteresis.presets import random_two_tendon_params, through_zero_trajectory
from i2ris_calib.hysteresis.registry import model_for_kind
from i2ris_calib.hysteresis.two_tendon import two_tendon_gpi_model
from i2ris_calib.model import Signals


def _signals(n=3000, seed=0, phase=0.0):
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 40.0, n)
    v = np.round(3000 * np.sin(t + phase) + 200 * rng.standard_normal(n).cumsum() / np.sqrt(n))
    return Signals(v=v, v_other=np.round(2500 * np.cos(0.7 * t)))


def _coupled(**values):
    return coupled_two_tendon_model(
        **{
            "theta0": 1.0, "a1_p": 0.004, "a4_p": -2.0, "a1_n": 0.003, "a4_n": -1.5,
            "a1_cp": 0.002, "a3_cp": 0.0025, "a4_cp": -1.0, "a1_cn": 0.001,
            "a3_cn": 0.0015, "a4_cn": -0.5, "sign_cn": -1.0,
        } | values
    )  # fmt: skip


def _search(model, s, theta, used=None):
    used = np.isfinite(theta) if used is None else used
    return F._Search.of(model, F._frozen_inputs(s), theta, used, "linear", 0.5, "lm", 1e-7, 20)


def test_screening_drops_rows_only_above_screen_rows(monkeypatch):
    """Up to SCREEN_ROWS fitted samples the search itself; above, every k-th fitted
    sample (k the smallest step to about SCREEN_ROWS), the same model and inputs."""
    m = two_tendon_gpi_model()
    s = _signals()
    theta = m.evaluate(s, m.values)
    used = np.ones(theta.size, bool)
    used[::4] = False  # held out
    search = _search(m, s, theta, used)
    assert F._screening(search) is search  # 2250 fitted samples
    monkeypatch.setattr(F, "SCREEN_ROWS", 1000)
    screen = F._screening(search)
    np.testing.assert_array_equal(screen.counter.used_idx, search.counter.used_idx[::3])
    assert screen.counter.model is search.counter.model
    assert screen.counter.signals is search.counter.signals
    assert screen.lsq_free is search.lsq_free


def test_screening_keeps_every_sample_of_a_flag_point_model(monkeypatch, egpi_data):
    """The v_f profile's exact step tries the fitted samples' inputs: all of them."""
    _, v, theta = egpi_data
    monkeypatch.setattr(F, "SCREEN_ROWS", 100)
    search = _search(i2ris_egpi_model(), Signals(v=v), theta)
    assert search.pidx
    assert F._screening(search) is search


def _two_tendon_data(n=4000, seed=3):
    rng = np.random.default_rng(seed)
    truth = random_two_tendon_params(rng)
    _, v, start = through_zero_trajectory(rng, n, 30.0)
    y = model_for_kind("agpi").with_values(truth)(v)[start:]
    return v[start:], y + rng.normal(0.0, 0.25, y.size)


# ~6 s: slow since the default run reached its 5-minute budget
@pytest.mark.slow
def test_subsampled_screening_reaches_the_optimum_of_the_full_one(monkeypatch):
    """Synthetic two-tendon truth (0.25 deg noise, starting mid-loop: the initial
    state is fitted too): the fit screened on every 4th fitted sample ends within
    1e-3 of the cost (RMSE, held-out RMSE within 0.1 %) of the fit screened on all."""
    v, theta = _two_tendon_data()
    full = fit_kind("agpi", v, theta, FitConfig())
    monkeypatch.setattr(F, "SCREEN_ROWS", 800)
    sub = fit_kind("agpi", v, theta, FitConfig())
    assert sub.chisqr == pytest.approx(full.chisqr, rel=1e-3)
    assert sub.metrics.rmse_deg == pytest.approx(full.metrics.rmse_deg, rel=1e-3)
    assert sub.holdout_metrics.rmse_deg == pytest.approx(full.holdout_metrics.rmse_deg, rel=1e-3)
    assert sub.metrics.rmse_deg < 1.1 * 0.25


def test_run_stops_after_the_first_least_squares_run_above_stop_above(egpi_data):
    """``stop_above``: the steps after the first least-squares run are left out when
    it ends above; else the whole search."""
    _, v, theta = egpi_data
    m = i2ris_egpi_model()
    search = _search(m, Signals(v=v), theta)
    x0 = m.values
    first = search.run(x0, 5, ("fine", "lm"))
    stopped = search.run(x0, 5, F.FIRST_STEPS, stop_above=0.5 * first[0])
    np.testing.assert_array_equal(stopped[1], first[1])
    whole = search.run(x0, 5, F.FIRST_STEPS)
    kept = search.run(x0, 5, F.FIRST_STEPS, stop_above=2.0 * first[0])
    np.testing.assert_array_equal(kept[1], whole[1])


def test_screened_ends_in_start_order_and_a_far_start_left_early(monkeypatch, egpi_data):
    """Ends come back in the order of the starts (searched from the lowest start
    cost up); a start whose first run ends above SCREEN_STOP_RATIO x the best end so
    far is searched no further."""
    truth, v, theta = egpi_data
    m = i2ris_egpi_model()
    search = _search(m, Signals(v=v), theta)
    good = m.vector(truth)
    bad = good.copy()
    bad[m.names.index("a1")] *= 3.0
    calls = []
    real = F._Search.run

    def run(self, x0, nfev_limit, steps, how=None, stop_above=np.inf):
        calls.append(stop_above)
        return real(self, x0, nfev_limit, steps, how, stop_above)

    monkeypatch.setattr(F._Search, "run", run)
    ends = F._screened_ends(search, [bad, good], F.FIRST_STEPS)
    assert calls[0] == np.inf  # the good start (lower cost) first
    assert calls[1] == F.SCREEN_STOP_RATIO * search.counter.cost(ends[1])
    np.testing.assert_array_equal(ends[1], real(search, good, 20, F.FIRST_STEPS)[1])
    monkeypatch.setattr(F._Search, "run", real)
    short = search.run(bad, 20, ("fine", "lm"))
    if search.counter.cost(short[1]) > calls[1]:
        np.testing.assert_array_equal(ends[0], short[1])


def test_level_output_is_evaluate_to_the_last_bit():
    """The coupled model's level profile (the other motor's terms computed once) gives
    the output of the whole model after the pre-history, bit for bit; other models
    (and a recording without the other input) have none."""
    m = _coupled()
    s = F._frozen_inputs(_signals(phase=1.0))
    fl = F._FromLevel(m, s.v)
    full = np.append(m.values, [0.0, 0.0, 0.0])
    output = fl.level_output(s, full)
    for u in (float(s.v.min()), -700.0, 0.0, 1234.5, float(s.v.max())):
        trial = full.copy()
        trial[-1] = u
        np.testing.assert_array_equal(output(u), fl.evaluate(s, trial))
    # the earlier turning points, and a replayed opening cycle (the other motor moving)
    for cycle in (0, 40):
        fc = F._FromLevel(m, s.v, cycle)
        for idx in (len(full) - 2, len(full) - 3):
            turn = fc.level_output(s, full, idx)
            for u in (float(s.v.min()), 0.0, 1234.5):
                trial = full.copy()
                trial[idx] = u
                np.testing.assert_array_equal(turn(u), fc.evaluate(s, trial))
    # the other motor's own pre-history (six levels, three a motor): the own levels'
    # shortcut is still the whole model bit for bit; the other motor's levels have none
    f4 = F._FromLevel(m, s.v, 30, s.v_other)
    assert f4.levels == 6 and f4.n_other == 3
    full4 = np.append(m.values, [-600.0, 900.0, -800.0, 300.0, 0.0, 0.0])
    for idx in (len(full4) - 1, len(full4) - 2, len(full4) - 3):
        out4 = f4.level_output(s, full4, idx)
        for u in (float(s.v.min()), 0.0, 1234.5):
            trial = full4.copy()
            trial[idx] = u
            np.testing.assert_array_equal(out4(u), f4.evaluate(s, trial))
    assert f4.level_output(s, full4, len(full4) - 4) is None
    agpi = F._FromLevel(two_tendon_gpi_model(), s.v)
    assert agpi.level_output(s, np.append(two_tendon_gpi_model().values, [0.0] * 3)) is None
    assert fl.level_output(Signals(v=s.v), full) is None


def test_level_profile_costs_are_the_plain_costs():
    """``held_cost`` of the level: the costs of :meth:`_Counter.cost` to the last bit."""
    m = _coupled()
    s = _signals(phase=1.0)
    theta = m.evaluate(s, m.values) + np.random.default_rng(4).normal(0, 0.1, s.v.size)
    fl = F._FromLevel(m, s.v)
    search = _search(fl, s, theta)
    c = search.counter
    full = np.append(m.values, [100.0, 100.0, 100.0])
    held = c.held_cost(full, len(full) - 1)
    for u in np.linspace(search.lower[-1], search.upper[-1], 7):
        trial = full.copy()
        trial[-1] = u
        assert held(u) == c.cost(trial)


def test_bounded_polish_ends_at_a_bounded_minimum_no_worse_than_trf():
    """Data of a coupling side whose density grows with r (sigma_cp < 0, outside the
    bounds): from the truth clipped into the bounds, the active-set polish ends inside
    them with sigma_cp held on its bound (the cost still pushes it outward), its
    cost no worse than trf's from the same start (to 1e-6)."""
    m = _coupled(r1_cp=2.0, rn_cp=30.0)
    s = _signals(seed=1)
    i = m.names.index("sigma_cp")
    truth = m.values.copy()
    truth[i] = -0.1
    theta = m.evaluate(s, truth) + np.random.default_rng(2).normal(0, 0.1, s.v.size)
    search = _search(m, s, theta)
    c = search.counter
    x0 = np.clip(truth, search.lower, search.upper)
    held, _ = F._pushed_out(search, x0)
    assert held == [i]
    (cost, end, res), how = F._bounded_polish(search, x0, 300)
    assert how == "LM, sigma_cp held at a bound"
    assert not search.outside(end)
    assert end[i] == 0.0
    assert i in F._pushed_out(search, end)[0]
    assert res.jac.shape == (theta.size, search.lsq_free.size)
    assert cost == c.cost(end)
    trf_cost, _, _ = search.run(x0, 300, F.POLISH_STEPS, "trf")
    assert cost <= trf_cost * (1 + 1e-6)


def test_the_other_motor_holds_during_the_replayed_cycle():
    """The replayed first cycle is this motor's: the other motor's input holds its
    first value meanwhile, after its own levels (three turning points, in order)."""
    s = _signals(phase=1.0)
    vo = np.asarray(s.v_other, dtype=float)
    sig, n_pre = F.prehistory_signals(s, 0.0, cycle=40, other_levels=(-900.0, 800.0, -300.0))
    v_pre, vo_pre = np.asarray(sig.v)[:n_pre], np.asarray(sig.v_other)[:n_pre]
    np.testing.assert_array_equal(v_pre[-40:], np.asarray(s.v)[:40])
    assert np.all(vo_pre[-40:] == vo[0])
    turns = vo_pre[np.flatnonzero(np.diff(np.sign(np.diff(vo_pre))) != 0) + 1]
    assert vo_pre[0] == -900.0 and list(turns[:2]) == [800.0, -300.0]


def test_state_levels_of_the_other_motor():
    """An initial state's levels in the fitted model's order, the other motor's three
    first; a missing turning point is the next one's."""
    st = F.InitialState(10.0, 5, 0.0, "", v_turn=-20.0, other_v_turn=7.0, other_v_from=-3.0,
                        v0_other=1.0, v_turn2=30.0, other_v_turn2=-9.0)  # fmt: skip
    assert F.state_levels(st, 6) == [-9.0, 7.0, -3.0, 30.0, -20.0, 10.0]
    assert F.state_levels(st, 4, 2) == [7.0, -3.0, -20.0, 10.0]
    bare = F.InitialState(10.0, 5, 0.0, "", other_v_from=-3.0, v0_other=1.0)
    assert F.state_levels(bare, 6) == [-3.0, -3.0, -3.0, 10.0, 10.0, 10.0]


def test_last_levels_are_also_profiled_close_to_the_first_input():
    """The wide profile of each motor's last level (``v_from``, ``other_v_from``) also
    tries the first input +- 1, 2, 4, ... pre-history steps (below the grid's spacing,
    within the bounds); the earlier turning points only the grid."""
    m = _coupled()
    s = _signals(phase=1.0)
    fl = F._FromLevel(m, s.v, 0, s.v_other)
    n = len(fl.parameters)
    lo, hi = F.level_bounds(np.asarray(s.v))
    spacing = (hi - lo) / (F.INITIAL_STATE_GRID - 1)
    near = F._near_first(fl, s, n - 1, lo, hi)
    d = np.abs(near - float(s.v[0])) / fl.step
    assert near.size and np.all((near >= lo) & (near <= hi))
    np.testing.assert_allclose(np.log2(d), np.round(np.log2(d)))
    assert d.min() == 1.0 and d.max() * fl.step <= spacing < 2 * d.max() * fl.step
    olo, ohi = F.level_bounds(np.asarray(s.v_other))
    other = F._near_first(fl, s, n - fl.n_own - 1, olo, ohi)
    assert other.size and np.min(np.abs(other - float(s.v_other[0]))) == fl.other_step
    for idx in (n - 2, n - 3, n - fl.n_own - 2, 0):
        assert F._near_first(fl, s, idx, lo, hi).size == 0
    assert F._near_first(m, s, n - 1, lo, hi).size == 0


def test_pair_grid_tries_its_loop_one_turning_point_back():
    """The other motor came through a loop and turned a few steps before the first
    sample: the 13 x 13 grid (relaxed at one level, ramping to another) cannot stand for
    it, its loop one turning point back with the last reversal profiled close to the
    first input finds the truth's state (the other parameters held)."""
    m = _coupled()
    s = _signals(phase=1.0)
    fl = F._FromLevel(m, s.v, 0, s.v_other)
    vo0, step = float(s.v_other[0]), fl.other_step
    d = -step * (4.0 if s.v_other[1] > s.v_other[0] else -4.0)  # behind its first motion
    olo, ohi = F.level_bounds(np.asarray(s.v_other))
    loop = np.linspace(olo, ohi, F.PAIR_GRID)[[2, -3]]
    if d > 0:
        loop = loop[::-1]  # the loop ends on the far side of the reversal
    truth = np.append(m.values, [loop[0], loop[1], vo0 + d, 0.0, 0.0, 0.0])
    theta = fl.evaluate(s, truth)
    search = _search(fl, s, theta)
    start = truth.copy()
    start[-6:-3] = vo0
    turns, last = F._motors_levels(search)[1]
    grid = np.linspace(olo, ohi, F.PAIR_GRID)
    on_grid = []
    for a in grid:
        for b in grid:
            trial = start.copy()
            trial[turns], trial[last] = a, b
            on_grid.append(search.counter.cost(trial))
    assert min(on_grid) > 1e-6 * search.counter.cost(start)
    cost, full = F._pair_grid(search, start, turns, last)
    assert cost == search.counter.cost(full) <= 1e-20
    # the loop's second extreme and the last reversal (the first: as far as it is seen)
    np.testing.assert_array_equal(full[-5:-3], truth[-5:-3])
