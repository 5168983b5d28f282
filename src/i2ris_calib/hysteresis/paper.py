"""The paper's simulation verification (Section 3.1, Fig 3c, 3d, 4) and dead-zone detection."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from i2ris_calib.hysteresis.kernel import motion_direction
from i2ris_calib.hysteresis.models import EGPIModel, egpi_model

# Section 3.1: tanh envelopes, n = 30, two stages with kappa1 = 5, kappa2 = 10.
PAPER_SIM_VALUES = {
    "l1_amp": 8.0, "l1_gain": 0.2, "l1_shift": -0.5, "l1_offset": 0.0,  # gamma_l1 = 8 tanh(0.2 v - 0.5)
    "r1_amp": 9.0, "r1_gain": 0.2, "r1_shift": -0.1, "r1_offset": 0.0,  # gamma_r1 = 9 tanh(0.2 v - 0.1)
    "l2_amp": 8.0, "l2_gain": 0.2, "l2_shift": -1.0, "l2_offset": 0.0,  # gamma_l2 = 8 tanh(0.2 v - 1)
    "r2_amp": 10.0, "r2_gain": 0.2, "r2_shift": 0.5, "r2_offset": 0.1,  # gamma_r2 = 10 tanh(0.2 v + 0.5) + 0.1
    "kappa_l2": 5.0, "kappa_r2": 10.0,
    "vf_rise1": 1.5, "vf_fall1": -0.3,
    "lam": 0.07, "sigma": 0.1, "r1": 0.25, "rn": 7.25,
}  # fmt: skip
PAPER_SIM_RATE_HZ = 1000.0  # the paper gives no sampling rate; our choice
PAPER_SIM_DURATION_S = 10.0


def paper_sim_model() -> EGPIModel:
    """The two-stage tanh EGPI of Section 3.1 (Eq4-8) with the paper's parameters."""
    return egpi_model([("tanh", "tanh"), ("tanh", "tanh")], PAPER_SIM_VALUES, n=30)


def paper_sim_input(rate_hz: float = PAPER_SIM_RATE_HZ) -> tuple[np.ndarray, np.ndarray]:
    """``t`` (s) and ``v(t) = 8 exp(-0.04 t) sin(2 pi t + pi/4)`` on [0, 10] s, inclusive."""
    t = np.arange(0.0, PAPER_SIM_DURATION_S + 0.5 / rate_hz, 1.0 / rate_hz)
    return t, 8.0 * np.exp(-0.04 * t) * np.sin(2.0 * np.pi * t + np.pi / 4.0)


@dataclass(frozen=True)
class PaperSim:
    """Arrays of the simulation, all shape (n,): time (s), input, z1, z2, EGPI output z."""

    t: np.ndarray
    v: np.ndarray
    z1: np.ndarray
    z2: np.ndarray
    z: np.ndarray


def run_paper_sim(rate_hz: float = PAPER_SIM_RATE_HZ) -> PaperSim:
    """Simulate Section 3.1: the GPI outputs z1, z2 (Fig 3c, 3d) and the EGPI z (Fig 4)."""
    t, v = paper_sim_input(rate_hz)
    model = paper_sim_model()
    z1, z2 = model.families(v, model.values)
    return PaperSim(t, v, z1, z2, model(v))


@dataclass(frozen=True)
class DeadZoneInterval:
    """An input interval of one monotone branch where the output does not follow.

    Attributes
    ----------
    branch : int
        Index of the monotone branch (0-based, in time order).
    rising : bool
        Branch direction.
    v_start, v_end : float
        Input where the dead zone starts and ends (in the branch's direction).
    """

    branch: int
    rising: bool
    v_start: float
    v_end: float


def dead_zones(
    v: np.ndarray, y: np.ndarray, rel_slope: float = 0.25, min_width_frac: float = 0.02
) -> list[DeadZoneInterval]:
    """Dead zones of ``y`` against ``v`` on every monotone branch of ``v``.

    A dead zone is a maximal run of samples within a branch where
    ``|dy/dv| < rel_slope * (90th percentile of |dy/dv|)`` (the output is nearly
    flat while the input moves), at least ``min_width_frac`` of the input range
    wide. An output step (|dy| larger than 10x the typical step) ends a run, so two
    flat stretches separated by a switch count as two.
    """
    v = np.ascontiguousarray(v, dtype=float)
    y = np.asarray(y, dtype=float)
    d = motion_direction(v, 0.0)
    dv, dy = np.diff(v), np.diff(y)
    moving = dv != 0
    slope = np.zeros(dv.size)
    slope[moving] = np.abs(dy[moving] / dv[moving])
    ref = float(np.percentile(slope[moving], 90))
    step_ref = float(np.median(np.abs(dy[moving])))
    flat = moving & (slope < rel_slope * ref)
    jump = np.abs(dy) > 10 * step_ref + 1e-12
    seg = np.concatenate(([0], np.cumsum(d[1:] != d[:-1])))
    width = min_width_frac * float(np.ptp(v))
    zones: list[DeadZoneInterval] = []
    k = 0
    n = dv.size
    while k < n:
        if not flat[k]:
            k += 1
            continue
        j = k
        while j + 1 < n and flat[j + 1] and seg[j + 2] == seg[k + 1] and not jump[j + 1]:
            j += 1
        if abs(v[j + 1] - v[k]) >= width:
            zones.append(
                DeadZoneInterval(int(seg[k + 1]), bool(d[k + 1] > 0), float(v[k]), float(v[j + 1]))
            )
        k = j + 1
    return zones
