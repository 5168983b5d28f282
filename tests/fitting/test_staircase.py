"""The start state of a recording that begins mid-loop: the pre-history's levels as the
turning points of a history from rest, and the search over whole staircases
(``fit._staircases``).

The fit's use of both on in-family cases is in tests/fitting/test_optimum.py
(``STAIRCASE_CASES``).
"""

from __future__ import annotations

import numpy as np

import i2ris_calib.fitting.fit as F
from i2ris_calib.fitting.prehistory import _FromLevel
from i2ris_calib.hysteresis.slip import slip_model
from i2ris_calib.model import Signals


def _through(points, step: float = 25.0) -> np.ndarray:
    """Input ramping through ``points`` in steps of about ``step`` (the last included)."""
    parts = [
        np.linspace(a, b, max(int(np.ceil(abs(b - a) / step)), 1) + 1)[:-1]
        for a, b in zip(points[:-1], points[1:], strict=True)
    ]
    return np.concatenate([*parts, [points[-1]]])


def _slip() -> object:
    """An elasto-slip model (Maxwell slip): 8 elements up to 7,000 counts, stiffness
    falling with the threshold, a linear part and an offset."""
    w = {f"w{j}": 2e-3 * np.exp(-j / 4) for j in range(1, 9)}
    return slip_model(n=8, theta0=1.5, w0=4e-3, r_max=7000.0, **w)


def test_levels_are_the_turning_points_of_a_history_from_rest():
    """An elasto-slip model run after the fitted pre-history with the levels at the true
    turning points (-7,933, 6,027, -5,144) gives exactly the output of the model run over
    the whole history from rest: relaxed at the first level is the state of an input
    that came there from rest (each element's rest value clamped into its band), for a
    level that would not wipe the elements out too (6,027, -5,144 alone: the elements
    wider than 5,585 counts, half the last loop, remember the rest)."""
    model = _slip()
    recording = _through([4456.0, 6000.0, -6000.0, 2000.0])[1:]  # on up: no new turn
    fl = _FromLevel(model, recording, 0, None, 3)
    for turns in ([-7933.0, 6027.0, -5144.0], [6027.0, 6027.0, -5144.0]):
        history = _through([F.ORIGIN, *turns, 4456.0])
        full = np.asarray(model.evaluate(Signals(v=np.concatenate([history, recording])),
                                         model.values))[history.size :]  # fmt: skip
        fitted = fl.evaluate(Signals(v=recording), np.append(model.values, turns))
        np.testing.assert_allclose(fitted, full, rtol=0, atol=1e-9)


def test_four_levels_hold_a_staircase_that_three_cannot():
    """A history of four turning points of shrinking loops (-6,000, 5,000, -3,000,
    2,500, then the recording from 1,500): four levels (``v_turn3`` first) give exactly the
    output of the model run over the whole history from rest; three of them, any one
    dropped, do not (each element remembers the loops it is narrower than)."""
    model = _slip()
    recording = _through([1500.0, 6000.0, -6000.0, 2000.0])[1:]
    turns = [-6000.0, 5000.0, -3000.0, 2500.0]
    history = _through([F.ORIGIN, *turns, 1500.0])
    full = np.asarray(model.evaluate(Signals(v=np.concatenate([history, recording])),
                                     model.values))[history.size :]  # fmt: skip
    four = _FromLevel(model, recording, 0, None, 4)
    assert [p.name for p in four.parameters[-4:]] == [
        four.TURN3, four.TURN2, four.TURN, four.PARAM]  # fmt: skip
    fitted = four.evaluate(Signals(v=recording), np.append(model.values, turns))
    np.testing.assert_allclose(fitted, full, rtol=0, atol=1e-9)
    three = _FromLevel(model, recording, 0, None, 3)
    for k in range(4):
        fewer = turns[:k] + turns[k + 1 :]
        y = three.evaluate(Signals(v=recording), np.append(model.values, fewer))
        assert np.max(np.abs(y - full)) > 0.05, k  # deg (0.11-7.3 measured; range 87)


def test_wiped_keeps_the_turning_points_a_play_operator_remembers():
    """A reversal pair is wiped out by a later point beyond its first; the rest is never
    wiped; and two pre-histories with one key leave one state (the model's output)."""
    assert F._wiped([0.0, 5000.0, -3000.0, 6000.0, 1000.0]) == (0.0, 6000.0, 1000.0)
    assert F._wiped([0.0, 5000.0, -6000.0, 2000.0]) == (0.0, 5000.0, -6000.0, 2000.0)
    assert F._wiped([0.0, 5000.0, -3000.0, 4000.0, -1000.0]) == (
        0.0, 5000.0, -3000.0, 4000.0, -1000.0,
    )  # fmt: skip
    model = _slip()
    recording = _through([1000.0, 3000.0, -3000.0])[1:]
    outs = []
    for pts in ([0.0, 5000.0, -3000.0, 6000.0, 1000.0], [0.0, 6000.0, 1000.0]):
        h = _through(pts)
        y = model.evaluate(Signals(v=np.concatenate([h, recording])), model.values)
        outs.append(np.asarray(y)[h.size :])
    np.testing.assert_allclose(outs[0], outs[1], rtol=0, atol=1e-9)


def test_staircase_grid_keeps_distinct_reversing_staircases():
    """The grid's staircases (``_best_staircases``): those kept as they are reverse at
    every level on the way from rest to the first input, are distinct states and come
    lowest cost first; the first ``STAIRCASE_REFINED`` (the lowest ones refined together
    on a local grid) cost no more than the staircases they came from."""
    model = _slip()
    turns = [-7933.0, 6027.0, -5144.0]
    recording = _through([4456.0, 6000.0, -6000.0, 2000.0, -3000.0])[1:]
    history = _through([F.ORIGIN, *turns, 4456.0])
    theta = np.asarray(
        model.evaluate(Signals(v=np.concatenate([history, recording])), model.values)
    )[history.size :]
    fl = _FromLevel(model, recording, 0, None, 3)
    search = F._Search.of(fl, Signals(v=recording), theta, np.ones(recording.size, bool),
                          "linear", 1.0, "lm", 1e-10, 20)  # fmt: skip
    x = np.append(model.values, [recording[0]] * 3)
    head, m = fl._opening(search.counter.signals)
    hc = F._Counter(fl, head, theta[:m], np.ones(m, bool))
    idx = list(search.level_idx)
    kept = F._best_staircases(search, hc, x, idx, True)
    r = F.STAIRCASE_REFINED
    assert 2 * r < len(kept) <= r + F.STAIRCASE_SCREENED
    keys = set()
    for t in kept[r:]:
        path = [F.ORIGIN, *[u for u in t[idx] if u != F.ORIGIN], float(recording[0])]
        steps = np.diff(path)
        assert np.all(steps[:-1] * steps[1:] < 0)  # a reversal at every level
        keys.add(F._wiped(path))
    assert len(keys) == len(kept) - r
    costs = [hc.cost(t) for t in kept]
    assert costs[r:] == sorted(costs[r:])
    assert all(costs[i] <= costs[r + i] for i in range(r))
    assert min(costs[:r]) <= min(costs[r:])
    # the true staircase's state is found: the lowest kept costs (almost) nothing
    assert min(costs) < 1e-3 * float(np.sum((theta[:m] - theta[:m].mean()) ** 2))


def test_four_level_grid_extends_the_three_level_one():
    """With four levels the grid (``_best_staircases``) extends the three-level grid's
    lowest staircases (``heads``, which the three-level grid fills) one turning point
    back: its staircases reverse at every level, are distinct states and all have four
    turns (a history of four shrinking loops). The grids alone need not reach a four-turn state: the
    short LM runs and polishes of ``_staircases`` do that (maxwell_slip:65 and :67 in
    tests/fitting/test_optimum.py)."""
    model = _slip()
    turns = [-6000.0, 5000.0, -3000.0, 2500.0]
    recording = _through([1500.0, 6000.0, -6000.0, 2000.0])[1:]
    history = _through([F.ORIGIN, *turns, 1500.0])
    theta = np.asarray(
        model.evaluate(Signals(v=np.concatenate([history, recording])), model.values)
    )[history.size :]
    heads: list = []
    for n in (3, 4):
        fl = _FromLevel(model, recording, 0, None, n)
        search = F._Search.of(fl, Signals(v=recording), theta, np.ones(recording.size, bool),
                              "linear", 1.0, "lm", 1e-10, 20)  # fmt: skip
        x = np.append(model.values, [recording[0]] * n)
        head, m = fl._opening(search.counter.signals)
        hc = F._Counter(fl, head, theta[:m], np.ones(m, bool))
        idx = list(search.level_idx)
        kept = F._best_staircases(search, hc, x, idx, True, heads)
        assert 0 < len(heads) <= F.STAIRCASE_HEADS
        r = F.STAIRCASE_REFINED
        keys = set()
        for t in kept[r:]:
            levels = list(t[idx])
            while levels and levels[0] == F.ORIGIN:
                levels.pop(0)  # a leading level at the rest: fewer turning points
            path = [F.ORIGIN, *levels, float(recording[0])]
            steps = np.diff(path)
            assert np.all(steps[:-1] * steps[1:] < 0)  # a reversal at every level
            keys.add(F._wiped(path))
        assert len(keys) == len(kept) - r
    assert len(idx) == 4 and all(t[idx[0]] != F.ORIGIN for t in kept)  # four turns
