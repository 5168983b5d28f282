"""The lab protocol of a rendered session (``protocol = "lab"``, docs/simulation.md).

Robots as labs drive them (issue 20): both motors at once in circles and figure-eights
through zero with holds (:func:`~i2ris_calib.simulation.two_motor.two_motor_trajectory`),
the driving under way ``lab_burn_in_s`` before the first frame (the video and the
encoder log start mid-loop), and the truth of
:mod:`i2ris_calib.simulation.two_motor` (one truth for the rendered sessions and the
pure-array benchmarks): per axis a two-tendon GPI (model kind ``"agpi"``) with the
angle ``lab_offset_deg`` at zero input, pitch following the yaw joint's bend with a
gain of ``lab_coupling`` x its own.

The tracker measures angles from a straight reference pose (docs/tracking.md), so
the robot is driven straight once: at video time ``lab_reference_s`` both inputs ramp
(:data:`RAMP_S`) from where they are to the counts at which both angles are 0 deg
(found by bisection on the truth from the hysteresis state there), hold
``lab_reference_hold_s``, then blend back into the loops over :data:`BLEND_S`. The
inputs there are not zero (the offsets), and the state is the loops' own: the
recording still starts anywhere. ``[track] reference_start_s`` must point into the
hold (:func:`reference_window`).

Times are motion times (s, controller clock), 0 at ``LEAD_S`` after the first frame,
as for the paper's protocol; the grid (1 kHz) begins with the burn-in.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from i2ris_calib.hysteresis.kinds import LAB_TRUTH
from i2ris_calib.hysteresis.presets import random_two_tendon_params
from i2ris_calib.hysteresis.registry import model_for_kind
from i2ris_calib.simulation.config import SimulationConfig
from i2ris_calib.simulation.two_motor import (
    coupling_factor,
    two_motor_angles,
    two_motor_trajectory,
)

__all__ = ["LabDrive", "lab_drive", "reference_window"]

#: Seconds of the ramp from the loops to the straight pose.
RAMP_S = 0.6
#: Seconds over which the loops take over again after the straight hold.
BLEND_S = 1.0
#: Sampling of the driving (Hz): the truth grid.
RATE_HZ = 1000.0
#: Seconds of video before motion time 0 (trajectory.LEAD_S; repeated to avoid a cycle).
_LEAD_S = 1.0


@dataclass(frozen=True)
class LabDrive:
    """The lab driving and its truth on a 1 kHz grid (arrays shape (n,)).

    Attributes
    ----------
    t_s : motion times (s), from the burn-in's start
    enc_yaw, enc_pitch : inputs (counts, whole numbers, float)
    yaw_deg, pitch_deg : true angles (deg)
    params : ``{"yaw": agpi values, "pitch": agpi values, "c": deg of pitch per deg
        of yaw bend, "coupling": lab_coupling}``
    straight_s : (start, end) motion times (s) of the straight hold
    """

    t_s: np.ndarray
    enc_yaw: np.ndarray
    enc_pitch: np.ndarray
    yaw_deg: np.ndarray
    pitch_deg: np.ndarray
    params: dict
    straight_s: tuple[float, float]


def motion_duration(cfg: SimulationConfig) -> float:
    """Motion seconds of a lab session: the video is ``lab_duration_s`` long."""
    return cfg.lab_duration_s - 2 * _LEAD_S


def reference_window(cfg: SimulationConfig) -> tuple[float, float]:
    """``([track] reference_start_s, reference_duration_s)`` inside the straight hold
    (0.2 s margins), seconds after the first frame."""
    start = cfg.lab_reference_s + RAMP_S + 0.2
    return round(start, 3), round(cfg.lab_reference_hold_s - 0.4, 3)


def lab_drive(cfg: SimulationConfig) -> LabDrive:
    """The driving and truth of ``cfg`` (module docstring); seeded by ``cfg.seed`` on its
    own random stream; cached."""
    keys = ("seed", "amplitude_counts", "lab_duration_s", "lab_burn_in_s", "lab_period_s",
            "lab_hold_fraction", "lab_offset_deg", "lab_coupling", "lab_reference_s",
            "lab_reference_hold_s")  # fmt: skip
    return _lab_drive(tuple((k, getattr(cfg, k)) for k in keys))


@lru_cache(maxsize=4)
def _lab_drive(key: tuple) -> LabDrive:
    c = dict(key)
    rng = np.random.default_rng(np.random.SeedSequence([int(c["seed"]), 9]))
    amp = tuple(float(a) for a in c["amplitude_counts"])
    params = {
        axis: random_two_tendon_params(rng, amp[i], offset_deg=float(c["lab_offset_deg"][i]))
        for i, axis in enumerate(("yaw", "pitch"))
    }
    params["c"] = coupling_factor(params, float(c["lab_coupling"]), amp)
    params["coupling"] = float(c["lab_coupling"])
    t0 = -(_LEAD_S + 2.0 + float(c["lab_burn_in_s"]))
    t1 = float(c["lab_duration_s"]) - 2 * _LEAD_S + _LEAD_S + 2.0
    n = int(round((t1 - t0) * RATE_HZ)) + 1
    _, ey, ep, _ = two_motor_trajectory(
        rng, n, RATE_HZ, amp, period_s=tuple(c["lab_period_s"]),
        hold_fraction=float(c["lab_hold_fraction"]), burn_in_s=0.0,
    )  # fmt: skip
    t = t0 + np.arange(n) / RATE_HZ
    ey, ep, straight = _straighten(t, ey, ep, params, amp, c)
    yaw, pitch = two_motor_angles(params, ey, ep)
    return LabDrive(t, ey, ep, yaw, pitch, params, straight)


def _straighten(t, ey, ep, params, amp, c):
    """Insert the ramp to the straight pose, the hold and the blend back (module doc)."""
    a = int(np.searchsorted(t, float(c["lab_reference_s"]) - _LEAD_S))
    n_ramp = int(round(RAMP_S * RATE_HZ))
    n_hold = int(round(float(c["lab_reference_hold_s"]) * RATE_HZ))
    n_blend = int(round(BLEND_S * RATE_HZ))
    b = a + n_ramp
    agpi = model_for_kind(LAB_TRUTH)
    yaw_model = agpi.with_values(params["yaw"])
    pitch_model = agpi.with_values(params["pitch"])
    # yaw straight; pitch = own + c (yaw - theta0_yaw) = 0 at yaw = 0: own = c theta0_yaw
    target_y = _target(yaw_model, ey[:a], 0.0, amp[0], n_ramp)
    own_target = params["c"] * params["yaw"]["theta0"]
    target_p = _target(pitch_model, ep[:a], own_target, amp[1], n_ramp)
    out = []
    for v, target in ((ey, target_y), (ep, target_p)):
        w = np.arange(1, n_ramp + 1) / n_ramp
        ramp = np.round(v[a - 1] + w * (target - v[a - 1]))
        rest = v[a:].copy()  # the loops resume where they would have been at the ramp's start
        m = v.size - (b + n_hold)
        tail = rest[:m]
        wb = np.clip(np.arange(1, m + 1) / n_blend, 0.0, 1.0)
        tail = np.round((1 - wb) * target + wb * tail)
        out.append(np.concatenate([v[:a], ramp, np.full(n_hold, float(target)), tail]))
    return out[0], out[1], (float(t[b]), float(t[b + n_hold - 1]))


def _target(model, history: np.ndarray, angle: float, amp: float, n_ramp: int) -> float:
    """Whole counts at which a straight ramp of ``n_ramp`` samples from the end of
    ``history`` leaves ``model``'s output at ``angle`` (bisection: from a given state the
    output at the end of a monotone ramp grows with its end)."""
    start = float(history[-1])

    def end_output(target: float) -> float:
        w = np.arange(1, n_ramp + 1) / n_ramp
        v = np.concatenate([history, np.round(start + w * (target - start))])
        return float(model(v)[-1])

    lo, hi = -amp, amp
    if not end_output(lo) <= angle <= end_output(hi):
        raise ValueError(
            "lab: no input straightens the tip (lab_offset_deg too large for the range)"
        )
    while hi - lo > 1.0:
        mid = round(0.5 * (lo + hi))
        if mid in (lo, hi):
            break
        lo, hi = (mid, hi) if end_output(mid) < angle else (lo, mid)
    return float(min((lo, hi), key=lambda x: abs(end_output(x) - angle)))
