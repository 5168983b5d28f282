"""The second camera's grey level (sync flash) keeps its own frame time in angles.csv."""

from __future__ import annotations

import numpy as np

from i2ris_calib.io.track import nearest_frame_gray
from i2ris_calib.tracking.config import TrackingConfig


def test_lagged_camera_grey_is_its_own_frame_not_interpolated():
    """Side frames 5 ms after the top frames, an LED step between two side frames: each
    top row gets the nearest side frame's grey level and that frame's time (an
    interpolated grey would be a lit fraction no exposure had)."""
    t_top = np.arange(30) / 30.0
    t_side = t_top + 0.005
    gray = np.where(t_side > 0.5, 100.0, 60.0)
    g, t = nearest_frame_gray(t_side, gray, t_top, TrackingConfig())
    np.testing.assert_array_equal(t, t_side)
    np.testing.assert_array_equal(g, gray)
    assert set(np.unique(g)) == {60.0, 100.0}


def test_no_frame_within_the_gap_gives_nan():
    t_side = np.array([0.0, 0.033, 0.5, 0.533])
    g, t = nearest_frame_gray(
        t_side, np.arange(4.0), np.array([0.02, 0.25, 0.52]), TrackingConfig()
    )
    np.testing.assert_array_equal(g[[0, 2]], [1.0, 3.0])
    assert np.isnan(g[1]) and np.isnan(t[1])  # 0.217 s from the nearest frame > 0.1 s
