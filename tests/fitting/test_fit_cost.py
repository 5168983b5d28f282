"""The fit's own cost at given values (fit_cost, dataset_cost), the rule that tells a
lower optimum from the same one (lower_optimum), and further starts of a fit (given):
what a later stage uses to replace a stored fit (issue 31)."""

from __future__ import annotations

import numpy as np
import pytest

from i2ris_calib.fitting.config import FitConfig
from i2ris_calib.fitting.fit import SAME_MINIMUM, fit_cost, lower_optimum
from i2ris_calib.fitting.pipeline import fit_kind, split_masks
from i2ris_calib.hysteresis.models import i2ris_egpi_model
from i2ris_calib.hysteresis.presets import paper_like_params
from i2ris_calib.model import Signals


def _recording(v0_phase: float = 0.0, n: int = 900, seed: int = 2):
    """(signals, angle, holdout) of 3 loading cycles of the paper-like EGPI; the input
    starts at ``v0_phase`` of a cycle (0: at rest at zero)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 18.0, n)
    v = 1400.0 * np.sin(np.pi * ((t / 6.0 + v0_phase) % 1.0)) ** 2
    theta = i2ris_egpi_model().evaluate_dict(v, paper_like_params("yaw+"))
    theta = theta + rng.normal(0.0, 0.05, n)
    return Signals(v=v, t_s=t), theta, split_masks(v, FitConfig())[1]


@pytest.mark.parametrize("phase", [0.0, 0.3])
def test_fit_cost_at_the_fitted_values_is_the_certificate_best_cost(phase):
    """At rest and mid-loop (the model run after the fitted start state)."""
    s, theta, hold = _recording(phase)
    res = fit_kind("gpi", s, theta, FitConfig(), hold)
    assert (res.initial_state is not None) == (phase > 0)
    cost = fit_cost(res.model, s, theta, holdout_mask=hold, initial_state=res.initial_state)
    assert cost == pytest.approx(res.certificate.best_cost, rel=1e-9)
    assert cost == pytest.approx(np.nansum(res.residuals[~hold] ** 2), rel=1e-9)


def test_lower_optimum_is_lower_by_more_than_the_certificate_tolerance():
    assert SAME_MINIMUM == 1e-3
    assert not lower_optimum(100.0, 100.0)
    assert not lower_optimum(100.0, 99.95)  # within 0.1 %: the same minimum
    assert lower_optimum(100.0, 99.8)
    assert not lower_optimum(100.0, float("nan"))
    assert not lower_optimum(100.0, 120.0)


def test_a_given_start_is_a_floor_of_the_fit():
    """A fit rerun from a lower cost another stage found ends at or below it, and
    counts it among its starts; without one it is the fit it was."""
    s, theta, hold = _recording()
    cfg = FitConfig(max_nfev=10, n_starts=1, max_restarts=0)
    short = fit_kind("gpi", s, theta, cfg, hold)
    assert fit_kind("gpi", s, theta, cfg, hold, given=()).params == short.params
    good = fit_kind("gpi", s, theta, FitConfig(), hold)
    good_cost = fit_cost(good.model, s, theta, holdout_mask=hold)
    rerun = fit_kind("gpi", s, theta, cfg, hold, given=(good.params,))
    assert fit_cost(rerun.model, s, theta, holdout_mask=hold) <= good_cost * (1 + 1e-9)
    assert rerun.certificate.starts == short.certificate.starts + 1
