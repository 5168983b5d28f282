"""The fitter's faster paths give the values of the plain ones (issue 20 item 7).

Speed figures are in benchmarks/bench_speed.py; these tests check values only.
"""

from __future__ import annotations

import numpy as np

from i2ris_calib.fitting import fit as F
from i2ris_calib.hysteresis.coupled import coupled_two_tendon_model
from i2ris_calib.hysteresis.models import continuous_egpi_model, gpi_model
from i2ris_calib.hysteresis.two_tendon import two_tendon_gpi_model
from i2ris_calib.model import Signals


def _signals(n=3000, seed=0, other=True):
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 40.0, n)
    v = np.round(3000 * np.sin(t) + 200 * rng.standard_normal(n).cumsum() / np.sqrt(n))
    vo = np.round(2500 * np.cos(0.7 * t)) if other else None
    return Signals(v=v, v_other=vo)


def _coupled():
    return coupled_two_tendon_model(
        theta0=1.0, a1_p=0.004, a4_p=-2.0, a1_n=0.003, a4_n=-1.5,
        a1_cp=0.002, a3_cp=0.0025, a4_cp=-1.0, a1_cn=0.001, a3_cn=0.0015, a4_cn=-0.5,
        sign_cn=-1.0,
    )  # fmt: skip


def test_coupled_jacobian_is_each_sides_gpi_jacobian_and_its_rows():
    """Assembled column by column: theta0, each own side's and each coupling side's GPI
    Jacobian on that side's input (signed as the side enters the output; the GPI
    Jacobian itself is checked against central differences in test_jacobian.py), the
    held signs 0; ``rows`` picks rows of the whole."""
    m = _coupled()
    s = _signals()
    x = m.values
    jac = m.jacobian(s, x)
    assert jac.shape == (s.v.size, x.size)
    assert np.all(jac[:, 0] == 1.0)
    val = m.named(x)
    for first, suffix, u, sign in (
        (1, "p", np.maximum(s.v, 0), 1.0),
        (9, "n", np.maximum(-s.v, 0), -1.0),
        (17, "cp", np.maximum(s.v_other, 0), val["sign_cp"]),
        (26, "cn", np.maximum(-s.v_other, 0), -val["sign_cn"]),
    ):
        gpi = gpi_model(n=m.n)
        xs = np.array([val[f"{k}_{suffix}"] for k in gpi.names])
        np.testing.assert_array_equal(jac[:, first : first + 8], sign * gpi.jacobian(u, xs))
    assert np.all(jac[:, [25, 34]] == 0.0)
    rows = np.array([0, 5, 17, 1000, 2999])
    np.testing.assert_array_equal(m.jacobian(s, x, rows=rows), jac[rows])


def test_coupled_jacobian_without_other_input_is_the_two_tendon_one():
    m = _coupled()
    s = _signals(other=False)
    jac = m.jacobian(s, m.values)
    own = two_tendon_gpi_model().jacobian(s, m.values[:17])
    np.testing.assert_array_equal(jac[:, :17], own)
    assert np.all(jac[:, 17:] == 0.0)


def test_coupled_output_same_on_a_read_only_other_input():
    """The other input's sides are kept for a read-only array: same output."""
    m = _coupled()
    s = _signals()
    vo = np.array(s.v_other)
    vo.flags.writeable = False
    frozen = Signals(v=s.v, v_other=vo)
    y = m.evaluate(s, m.values)
    np.testing.assert_array_equal(m.evaluate(frozen, m.values), y)
    np.testing.assert_array_equal(m.evaluate(frozen, m.values), y)  # from the cache


def _search(model, s, theta):
    used = np.isfinite(theta)
    return F._Search.of(model, s, theta, used, "linear", 1.0, "lm", 1e-8, 20)


def test_into_bounds_is_inside_and_never_worse_than_clipping():
    m = _coupled()
    s = _signals(seed=1)
    theta = m.evaluate(s, m.values) + np.random.default_rng(2).normal(0, 0.1, s.v.size)
    search = _search(m, s, theta)
    # an end outside the bounds that clipping ruins: a coupling density growing with r
    full = m.values.copy()
    i = m.names.index("sigma_cp")
    full[i] = -0.8
    left = search.outside(full)
    assert left == [i]
    c = search.counter
    clipped = np.clip(full, search.lower, search.upper)
    start = F._into_bounds(search, full, left, 50)
    assert not search.outside(start)
    assert c.cost(start) <= c.cost(clipped)
    # a mild clip: the clipped point itself
    full[i] = -1e-9
    start = F._into_bounds(search, full, [i], 50)
    np.testing.assert_array_equal(start, np.clip(full, search.lower, search.upper))


def test_into_bounds_holds_what_the_held_lm_pushes_out(monkeypatch):
    """When the held LM pushes another parameter out of its bounds, that one is held at
    its bound too and the rest refitted: the start is inside and no worse than clipping."""
    m = _coupled()
    s = _signals(seed=1)
    theta = m.evaluate(s, m.values) + np.random.default_rng(2).normal(0, 0.1, s.v.size)
    search = _search(m, s, theta)
    full = m.values.copy()
    i, j = m.names.index("sigma_cp"), m.names.index("sigma_cn")
    full[i] = -0.8
    real, runs = F._lsq, []

    def lsq(counter, x0, free, *args):
        runs.append(set(free.tolist()))
        end, res = real(counter, x0, free, *args)
        if len(runs) == 1:  # the first held run pushes sigma_cn out
            end = end.copy()
            end[j] = -0.5
        return end, res

    monkeypatch.setattr(F, "_lsq", lsq)
    monkeypatch.setattr(F, "CLIP_COST_RATIO", 0.0)  # the held LM runs whatever clipping costs
    start = F._into_bounds(search, full, [i], 50)
    assert len(runs) == 2
    assert i not in runs[0] and j in runs[0]
    assert i not in runs[1] and j not in runs[1]
    assert not search.outside(start)
    c = search.counter
    assert c.cost(start) <= c.cost(np.clip(full, search.lower, search.upper))


def test_into_bounds_of_a_flag_point_model_is_the_clipped_point(monkeypatch):
    """A model with a profiled flag point (the continuous EGPI) starts its bounded refit
    (trf) at the clipped point: no held LM, whatever clipping costs."""
    m = continuous_egpi_model()
    s = Signals(v=np.abs(_signals(seed=3, other=False).v))
    theta = m.evaluate(s, m.values) + np.random.default_rng(4).normal(0, 0.1, s.v.size)
    search = _search(m, s, theta)
    assert search.pidx
    full = m.values.copy()
    i = m.names.index("sigma")
    full[i] = -0.5
    runs = []
    monkeypatch.setattr(F, "_lsq", lambda *a: runs.append(a) or (a[1], None))
    monkeypatch.setattr(F, "CLIP_COST_RATIO", 0.0)
    start = F._into_bounds(search, full, search.outside(full), 50)
    assert not runs
    np.testing.assert_array_equal(start, np.clip(full, search.lower, search.upper))


def test_loss_samples_and_start_vectors():
    theta = np.array([1.0, np.nan, 2.0, 3.0, 4.0])
    hold, used = F._loss_samples(
        theta, np.array([1, 1, 1, 0, 1], bool), np.array([0, 0, 1, 0, 0], bool)
    )
    np.testing.assert_array_equal(hold, [0, 0, 1, 0, 0])
    np.testing.assert_array_equal(used, [1, 0, 0, 0, 1])
    m = two_tendon_gpi_model()
    (x0,) = F._start_vectors(m, None)
    np.testing.assert_array_equal(x0, m.values)
    assert F._start_vectors(m, [[1] * 17])[0].dtype == float


def test_bounded_polish_holds_what_the_held_lm_pushes_out(monkeypatch):
    """When the active-set LM of the bounded polish pushes a parameter out of its
    bounds, that one is held at the bound it crossed and the rest refitted from there
    by LM (not trf from the start again); a trf that may follow (a held parameter
    pulled inward) starts at that held end."""
    m = _coupled()
    s = _signals(seed=1)
    theta = m.evaluate(s, m.values) + np.random.default_rng(2).normal(0, 0.1, s.v.size)
    search = _search(m, s, theta)
    x0 = m.values.copy()
    assert not search.outside(x0)
    j = m.names.index("sigma_cn")
    real, runs = F._lsq, []

    def lsq(counter, start, free, lower, upper, method, *args):
        runs.append((method, set(free.tolist()), start.copy()))
        end, res = real(counter, start, free, lower, upper, method, *args)
        if len(runs) == 1:  # the first held run pushes sigma_cn out
            end = end.copy()
            end[j] = -0.5
        return end, res

    monkeypatch.setattr(F, "_lsq", lsq)
    (cost, end, _), how = F._bounded_polish(search, x0, 50)
    assert runs[0][0] == "lm" and j in runs[0][1]
    assert runs[1][0] == "lm" and j not in runs[1][1]
    assert runs[1][2][j] == search.lower[j]  # held at the bound it crossed
    assert all(not np.array_equal(r[2], x0) for r in runs[2:])  # no trf from x0
    assert not search.outside(end)
    assert cost <= search.counter.cost(x0)
    if how != "trf":
        assert "sigma_cn" in how
