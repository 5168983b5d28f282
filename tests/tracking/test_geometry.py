"""Rotation conventions (docs/tracking.md)."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from i2ris_calib.tracking.geometry import (
    FACE_ROTATIONS,
    NOMINAL_CAMERA_ROTATIONS,
    euler_zyx_deg,
    rodrigues,
    tip_rotation,
)

ang = st.floats(-80, 80)


@given(ang, ang, ang)
def test_euler_round_trip(yaw, pitch, roll):
    assert np.allclose(euler_zyx_deg(tip_rotation(yaw, pitch, roll)), [yaw, pitch, roll], atol=1e-8)


def test_positive_yaw_turns_tip_towards_plus_y_and_pitch_towards_minus_z():
    assert tip_rotation(10, 0)[:, 0][1] > 0
    assert tip_rotation(0, 10)[:, 0][2] < 0


def test_frames_are_proper_rotations_and_markers_face_their_cameras():
    for view in ("top", "side"):
        for R in (FACE_ROTATIONS[view], NOMINAL_CAMERA_ROTATIONS[view]):
            assert np.allclose(R @ R.T, np.eye(3)) and np.isclose(np.linalg.det(R), 1)
        # marker z axis (out of the face) points against the camera's viewing direction
        z_marker_in_cam = NOMINAL_CAMERA_ROTATIONS[view] @ FACE_ROTATIONS[view][:, 2]
        assert z_marker_in_cam[2] < -0.99


@given(st.lists(st.floats(-2, 2), min_size=3, max_size=3))
def test_rodrigues_is_a_rotation(r):
    R = rodrigues(np.array(r))
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-12)
