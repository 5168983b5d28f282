"""Synthetic truth for the fitting tests."""

from __future__ import annotations

import numpy as np
import pytest

from i2ris_calib.hysteresis.models import i2ris_egpi_model
from i2ris_calib.hysteresis.presets import loading_trajectory, paper_like_params

NOISE = 0.1


@pytest.fixture(scope="module")
def egpi_data():
    """(truth dict, v counts, theta deg) from the yaw+ preset, 3000 samples, 0.1 deg noise."""
    rng = np.random.default_rng(5)
    truth = paper_like_params("yaw+")
    _, v = loading_trajectory(rng, n_cycles=5, n_samples=3000)
    y = i2ris_egpi_model(deadband_counts=2.0).evaluate_dict(v, truth)
    return truth, v, y + rng.normal(0, NOISE, v.size)
