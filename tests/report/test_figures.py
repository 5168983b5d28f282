"""Figures: fixed pixel sizes, determinism, degraded inputs; helper invariants."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from runfolder import _dataset

from i2ris_calib.report import figures
from i2ris_calib.report.render import png_size


@pytest.fixture(scope="module")
def pred() -> pd.DataFrame:
    return _dataset("yaw", "+", np.arange(0, 30, 0.05), 1.0)[1]


def test_fit_figure_has_fixed_size_and_is_deterministic(pred):
    a = figures.fit_figure_png(pred, "yaw+", "yaw", False, dpi=50)
    b = figures.fit_figure_png(pred, "yaw+", "yaw", False, dpi=50)
    assert png_size(a) == (600, 180)  # 12 x 3.6 in at 50 dpi
    assert a == b


def test_fit_figure_depends_on_data(pred):
    a = figures.fit_figure_png(pred, "yaw+", "yaw", False, dpi=50)
    other = pred.assign(egpi_deg=pred["egpi_deg"] + 5.0)
    assert figures.fit_figure_png(other, "yaw+", "yaw", False, dpi=50) != a


def test_fit_figure_without_models(pred):
    no_egpi = pred.drop(columns=["egpi_deg"]).assign(gpi_deg=np.nan)
    png = figures.fit_figure_png(no_egpi, "yaw-", "yaw", True, dpi=40)
    assert png_size(png) == (480, 144)


def test_tracking_figure_without_flags_or_reprojection():
    a = pd.DataFrame(
        {
            "time_s": np.arange(50) / 30,
            "yaw_deg": np.arange(50.0),
            "pitch_deg": 0.0,
            "status": "measured",
        }
    )
    png = figures.tracking_figure_png(a, 1.0, dpi=40)
    assert png_size(png) == (400, 320)


def test_synced_figure_size():
    s = pd.DataFrame(
        {"enc_yaw": np.arange(20), "enc_pitch": np.arange(20), "yaw_deg": 1.0, "pitch_deg": 2.0}
    )
    assert png_size(figures.synced_figure_png(s, dpi=40)) == (400, 144)


def test_holdout_spans():
    t = np.arange(10.0)
    h = np.array([0, 0, 1, 1, 0, 0, 0, 1, 1, 1], dtype=bool)
    assert figures.holdout_spans(t, h) == [(2.0, 3.0), (7.0, 9.0)]
    assert figures.holdout_spans(t, np.zeros(10, bool)) == []
    assert figures.holdout_spans(t[:0], h[:0]) == []


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(0, 100, allow_nan=False), min_size=1, max_size=60),
    st.floats(0.01, 50),
    st.integers(0, 2**32 - 1),
)
def test_detection_rate_matches_brute_force(times, window, seed):
    t = np.sort(np.asarray(times))
    measured = np.random.default_rng(seed).random(t.size) < 0.7
    rate = figures.detection_rate(t, measured, window)
    for i, ti in enumerate(t):
        inside = (t >= ti - window / 2) & (t <= ti + window / 2)
        assert rate[i] == pytest.approx(measured[inside].mean(), abs=1e-12)
    assert np.all((rate >= 0) & (rate <= 1))


@given(st.integers(0, 10**6), st.integers(1, 10**5))
def test_thinning_step_bounds_points(n, max_points):
    k = figures.thinning_step(n, max_points)
    assert k >= 1 and len(range(0, n, k)) <= max(max_points, 1)
    if k > 1:
        assert len(range(0, n, k - 1)) > max_points  # smallest such step
