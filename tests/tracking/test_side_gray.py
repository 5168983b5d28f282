"""A second camera triggered later than the first: its grey level keeps its own frame
time (sync flash), its corners can be extrapolated from either side of a step."""

from __future__ import annotations

import numpy as np
import pytest

from i2ris_calib.tracking.config import TrackingConfig
from i2ris_calib.tracking.timing import nearest_frame_gray, one_sided_corners, resample_corners


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


def test_one_sided_corners_follow_each_side_of_a_step():
    """Side frames 5 ms after the top frames, corners moving linearly then jumping by
    10 px between two side frames: extrapolation from the frames before reproduces the
    pre-step line exactly, from the frames after the post-step line; the two-sided
    interpolation is neither (the fused frame then disagrees with the top view)."""
    cfg = TrackingConfig()
    t_side = np.arange(20) / 30.0 + 0.005
    x = 100.0 + 3.0 * t_side * 30.0 + np.where(t_side > 0.32, 10.0, 0.0)
    c = np.repeat(x[:, None, None], 4, axis=1).repeat(2, axis=2)
    t = np.array([10 / 30.0])  # top frame 10; side frame 10 (5 ms later) is past the step
    before = one_sided_corners(t_side, c, t, "before", cfg)[0, 0, 0]
    after = one_sided_corners(t_side, c, t, "after", cfg)[0, 0, 0]
    both = resample_corners(t_side, c, t, cfg)[0, 0, 0]
    assert before == pytest.approx(100.0 + 3.0 * 10)
    assert after == pytest.approx(110.0 + 3.0 * 10)
    assert not np.isclose(both, before) and not np.isclose(both, after)
    assert np.isnan(one_sided_corners(t_side, c, np.array([0.0]), "before", cfg)).all()
