"""Start-value helpers (hysteresis/start.py) against known lines."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from i2ris_calib.hysteresis.start import _least_squares_line, _line


@pytest.mark.parametrize("offset", [0.0, 5_000.0, 1e7])
def test_line_is_exact_far_from_zero(offset):
    # a short stretch far from zero: a Vandermonde fit is poorly conditioned there
    x = offset + np.linspace(0.0, 3.0, 40)
    y = 0.004 * x - 12.5
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        slope, intercept = _least_squares_line(x, y)
    assert slope == pytest.approx(0.004, rel=1e-9)
    assert intercept == pytest.approx(-12.5, abs=1e-9 * max(1.0, offset))


def test_line_ignores_an_outlier():
    rng = np.random.default_rng(3)
    v = np.linspace(0.0, 6000.0, 200)
    theta = 0.005 * v + 1.0 + rng.normal(0.0, 0.05, v.size)
    theta[50] += 40.0  # a tracking outlier
    slope, intercept = _line(v, theta, np.ones(v.size, bool))
    assert slope == pytest.approx(0.005, rel=2e-3)
    assert intercept == pytest.approx(1.0, abs=0.05)


def test_line_none_when_input_constant():
    v = np.full(20, 100.0)
    assert _line(v, np.arange(20.0), np.ones(20, bool)) is None
