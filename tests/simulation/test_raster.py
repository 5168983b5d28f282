"""Exact area coverage of the rasteriser against analytic areas."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from i2ris_calib.simulation.raster import accumulate_quads


def _cover(quad, shape=(40, 40)):
    S = np.zeros(shape, np.float32)
    C = np.zeros(shape, np.float32)
    accumulate_quads(S, C, np.asarray([quad], float), np.array([1.0]), np.array([True]), 0.0, 0.0)
    return C


def test_axis_aligned_rectangle_has_exact_fractional_coverage():
    # rectangle x in [10.2, 20.7], y in [5.5, 9.25]; pixel c covers [c-0.5, c+0.5]
    C = _cover([[10.2, 5.5], [20.7, 5.5], [20.7, 9.25], [10.2, 9.25]])
    assert C[7, 10] == np.float32(0.3)  # x 10.2..10.5 inside pixel 10
    assert abs(C[9, 15] - 0.75) < 1e-6  # y 8.5..9.25
    assert abs(C[7, 15] - 1.0) < 1e-6
    assert abs(C.sum() - 10.5 * 3.75) < 1e-4


@settings(max_examples=40, deadline=None)
@given(cx=st.floats(12, 28), cy=st.floats(12, 28), half=st.floats(0.3, 9), ang=st.floats(0, np.pi))
def test_total_coverage_equals_polygon_area_for_rotated_squares(cx, cy, half, ang):
    c, s = np.cos(ang), np.sin(ang)
    pts = np.array([[-half, -half], [half, -half], [half, half], [-half, half]]) @ np.array(
        [[c, s], [-s, c]]
    )
    C = _cover(pts + [cx, cy])
    assert abs(C.sum() - (2 * half) ** 2) < 1e-3 * max(1.0, (2 * half) ** 2)
    assert C.max() <= 1.0 + 1e-5 and C.min() >= 0.0


def test_adjacent_quads_tile_without_gaps_or_overlap():
    S = np.zeros((20, 20), np.float32)
    C = np.zeros_like(S)
    q1 = [[3.3, 3.1], [9.7, 4.0], [9.1, 12.2], [3.9, 11.6]]
    q2 = [[9.7, 4.0], [15.2, 3.3], [15.8, 12.9], [9.1, 12.2]]
    accumulate_quads(S, C, np.asarray([q1, q2], float), np.ones(2), np.ones(2, bool), 0.0, 0.0)
    assert C.max() <= 1.0 + 1e-5  # shared edge: coverages add to at most one
