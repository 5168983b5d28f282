"""Regressions from rendered sessions: the EGPI fit must never end worse than GPI."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import i2ris_calib.fitting.fit as fit_module
from i2ris_calib.fitting.config import FitConfig
from i2ris_calib.fitting.fit import fit_model
from i2ris_calib.fitting.pipeline import fit_all, nested_gpi_start, unfitted_model
from i2ris_calib.hysteresis.models import gpi_model, i2ris_egpi_model
from i2ris_calib.hysteresis.presets import gpi_values, loading_trajectory, paper_like_params

DATA = Path(__file__).parent / "data" / "rendered_yaw_plus.csv"


@pytest.fixture(scope="module")
def rendered_yaw_plus():
    """(v counts, theta deg) of the yaw+ block of a rendered session (simulate -> track ->
    sync, seed 0; true model EGPI, tracking floor ~0.04 deg), 220 samples."""
    df = pd.read_csv(DATA)
    return df["v_counts"].to_numpy(float), df["theta_deg"].to_numpy(float)


def test_egpi_nests_gpi(rng):
    """a5 = a3, a6 = a4, kappa = 1 and any v_f: EGPI output == GPI output exactly."""
    _, v = loading_trajectory(rng, n_cycles=3, n_samples=1500)
    g = gpi_values(paper_like_params("pitch+"))
    egpi = unfitted_model("egpi", v)
    for v_f in (500.0, 3000.0, 5500.0):
        start = egpi.vector(egpi.value_dict() | {"v_f": v_f})
        x = nested_gpi_start(egpi, g, start)
        np.testing.assert_array_equal(egpi.evaluate(v, x), gpi_model().evaluate_dict(v, g))


# ~4.4 s: slow since the default run neared its 5-minute budget (on the default run,
# EGPI beating GPI on two-stage data: tests/fitting/test_fit.py; this recording's fits
# never worse than a start: below)
@pytest.mark.slow
def test_rendered_yaw_plus_egpi_beats_gpi(rendered_yaw_plus):
    """Rendered yaw+ (was: EGPI RMSE 2.95 deg, max 35 deg, 'converged', parameters clamped
    at the bounds, GPI 0.54 deg). EGPI (the true model) must beat GPI on the fitted and on
    the held-out cycles, end inside the bounds and converge."""
    v, theta = rendered_yaw_plus
    res = fit_all(v, theta, FitConfig())
    e, g = res["egpi"], res["gpi"]
    assert e.metrics.rmse_deg < 0.1 < g.metrics.rmse_deg  # deg; truth scores 0.073 here
    assert e.metrics.max_abs_err_deg < 0.5
    assert e.holdout_metrics.rmse_deg < g.holdout_metrics.rmse_deg
    assert e.converged and not e.extra["outside_bounds"]
    assert all(p.lower <= p.value <= p.upper for p in e.model.parameters)


def test_result_never_worse_than_a_start(rendered_yaw_plus, monkeypatch):
    """An optimiser step that ends worse than the start (simulated: every LM call
    returns a far-off point) must not be accepted: the result is never worse than the
    start."""
    v, theta = rendered_yaw_plus
    model = i2ris_egpi_model().with_fixed(fixed=("lam", "v_f"))
    x0 = nested_gpi_start(model, gpi_values(paper_like_params("yaw+")), model.values)
    start_cost = float(np.nansum((model.evaluate(v, x0) - theta) ** 2))
    real = fit_module._lsq

    def bad_lm(counter, x, free, lower, upper, method, max_nfev, ftol):
        full, res = real(counter, x, free, lower, upper, method, 3, ftol)
        if method == "lm":
            full = full.copy()
            full[1] += 20.0  # a2: loading envelope 20 deg too high, inside the bounds
        return full, res

    monkeypatch.setattr(fit_module, "_lsq", bad_lm)
    res = fit_model(model, v, theta, starts=[x0], max_nfev=50)
    assert float(np.sum(res.residuals[np.isfinite(theta)] ** 2)) <= start_cost
    # which part of the search rescues it (the bounded refit from the start, noted
    # "worse than a start", or a later restart) depends on the LM's path; the bounded
    # refit's note itself is checked by test_not_a_minimum_is_flagged


def test_not_a_minimum_is_flagged(rendered_yaw_plus, monkeypatch):
    """If even the bounded refit cannot reach the start's cost, converged is False."""
    v, theta = rendered_yaw_plus
    model = gpi_model().with_fixed(fixed=("lam",))
    x0 = model.vector(gpi_values(paper_like_params("yaw+")))
    real = fit_module._lsq

    def always_worse(counter, x, free, lower, upper, method, max_nfev, ftol):
        full, res = real(counter, x, free, lower, upper, method, 2, ftol)
        full = full.copy()
        full[1] += 20.0  # a2: loading envelope 20 deg too high, inside the bounds
        return full, res

    real_search = fit_module._global_search

    def worse_search(search, starts, max_nfev, steps, hops, spent=0.0):
        # every polished end 20 deg too high too (the global search would otherwise
        # find a point below the start through the bounded refit's clipping)
        found = real_search(search, starts, max_nfev, steps, 0)
        worse = found.best()[1].copy()
        worse[1] += 20.0
        found.polished = [(search.counter.cost(worse), worse, None, ())]
        return found

    monkeypatch.setattr(fit_module, "_lsq", always_worse)
    monkeypatch.setattr(fit_module, "_global_search", worse_search)
    # nor a fourth start-state level after the search (its staircases' polishes are not
    # made worse above: they would find the point below the start)
    monkeypatch.setattr(fit_module, "_one_level_back", lambda *args: None)
    res = fit_model(model, v, theta, starts=[x0])
    assert not res.converged and "NOT a minimum" in res.message
