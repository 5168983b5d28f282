"""A two-motor I2RIS recording as a lab drives it: both motors at once, through zero.

Pure arrays, seeded: the tests and ``benchmarks/bench_two_motor.py`` share it.

Each axis is an antagonistic tendon pair, the two-tendon GPI (model kind ``"agpi"``,
docs/models.md): a GPI per tendon with its own gain (each side's bending range drawn
on its own), an angle offset ``theta0`` within +-10 deg at zero input. The pitch
tendons pass the yaw joint, so the yaw joint's bend changes their path length: the
pitch angle also follows the yaw joint's bend (docs/models.md, "Both motors at
once")::

    yaw   = Y_yaw[enc_yaw]
    pitch = Y_pitch[enc_pitch] + c (Y_yaw[enc_yaw] - theta0_yaw)

with ``c`` chosen so that the coupling's gain (deg of pitch per yaw count) is
``coupling`` (0.3-0.8) x pitch's own gain (deg per pitch count). The coupling carries
the yaw joint's hysteresis (it is its bend), not the yaw motor's position.

Driving (:func:`two_motor_trajectory`): circles (the two inputs a quarter period
apart), figure-eights (pitch at twice yaw's frequency) and holds, each loop with its
own amplitudes (0.2-1 of full scale per motor) and period (4-12 s), blended from
where the inputs are; the recording starts ``burn_in_s`` into the driving (mid-loop).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from i2ris_calib.hysteresis.kinds import LAB_TRUTH
from i2ris_calib.hysteresis.presets import V_MAX_COUNTS, random_two_tendon_params
from i2ris_calib.hysteresis.registry import model_for_kind

__all__ = [
    "TwoMotorRecording",
    "coupling_factor",
    "simulate_two_motor",
    "two_motor_angles",
    "two_motor_trajectory",
]


@dataclass(frozen=True)
class TwoMotorRecording:
    """One simulated recording; arrays of shape (n,), in time order.

    Attributes
    ----------
    t_s : ndarray
        Sample times (s), starting at 0.
    enc_yaw, enc_pitch : ndarray
        Motor inputs (encoder counts, whole numbers, signed).
    yaw_deg, pitch_deg : ndarray
        Measured angles (deg): truth plus white noise of sd ``noise_deg``.
    yaw_true_deg, pitch_true_deg : ndarray
        True angles (deg).
    noise_deg : float
        Measurement noise sd (deg).
    coupling : float
        Gain of pitch on the yaw motor as a fraction of pitch's own gain.
    truth : dict
        ``{"yaw": agpi values, "pitch": agpi values, "c": deg of pitch per deg of yaw bend}``.
    """

    t_s: np.ndarray
    enc_yaw: np.ndarray
    enc_pitch: np.ndarray
    yaw_deg: np.ndarray
    pitch_deg: np.ndarray
    yaw_true_deg: np.ndarray
    pitch_true_deg: np.ndarray
    noise_deg: float
    coupling: float
    truth: dict

    def columns(self) -> dict[str, np.ndarray]:
        """The synced-CSV columns (``time_s, enc_yaw, enc_pitch, yaw_deg, pitch_deg``)."""
        return {
            "time_s": self.t_s,
            "enc_yaw": self.enc_yaw,
            "enc_pitch": self.enc_pitch,
            "yaw_deg": self.yaw_deg,
            "pitch_deg": self.pitch_deg,
        }


def _gain(values: dict[str, float], v_max: float) -> float:
    """Mean gain of a two-tendon axis (deg/count): half its swing from -v_max to +v_max
    on a slow loading ramp, divided by v_max."""
    v = np.concatenate([np.linspace(0, v_max, 200), np.linspace(0, -v_max, 200)])
    y = model_for_kind(LAB_TRUTH).with_values(values)(v)
    return float(abs(y[199] - y[-1]) / (2.0 * v_max))


def coupling_factor(
    truth: dict, coupling: float, v_max_counts: float | tuple[float, float] = V_MAX_COUNTS
) -> float:
    """``c`` (deg of pitch per deg of yaw bend) that makes the coupling's gain (deg of
    pitch per yaw count) ``coupling`` x pitch's own gain (deg per pitch count).

    ``truth``: ``{"yaw": agpi values, "pitch": agpi values}``; ``v_max_counts``: full
    scale of each motor (counts), or (yaw, pitch).
    """
    vy, vp = np.broadcast_to(np.asarray(v_max_counts, dtype=float), (2,))
    return float(coupling * _gain(truth["pitch"], vp) / _gain(truth["yaw"], vy))


def two_motor_angles(
    truth: dict, enc_yaw: np.ndarray, enc_pitch: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """True (yaw, pitch) angles (deg), shape (n,) each, of the inputs (counts, (n,),
    the whole history in time order): ``yaw = Y_yaw[enc_yaw]``, ``pitch =
    Y_pitch[enc_pitch] + c (yaw - theta0_yaw)`` (module docstring).

    ``truth``: ``{"yaw": agpi values, "pitch": agpi values, "c": float}``.
    """
    agpi = model_for_kind(LAB_TRUTH)
    yaw = np.asarray(agpi.with_values(truth["yaw"])(np.asarray(enc_yaw, float)), dtype=float)
    own = np.asarray(agpi.with_values(truth["pitch"])(np.asarray(enc_pitch, float)), dtype=float)
    return yaw, own + truth["c"] * (yaw - truth["yaw"]["theta0"])


def two_motor_trajectory(
    rng: np.random.Generator,
    n_samples: int,
    rate_hz: float = 30.0,
    v_max_counts: float | tuple[float, float] = V_MAX_COUNTS,
    period_s: tuple[float, float] = (4.0, 12.0),
    hold_fraction: float = 0.15,
    burn_in_s: float = 20.0,
    lockstep: float | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Both motors driven at once through zero: circles, figure-eights, holds.

    Parameters
    ----------
    rng : numpy Generator
    n_samples : int
        Samples of the recording (after the burn-in).
    rate_hz : float
        Sampling rate (Hz).
    v_max_counts : float or (float, float)
        Full scale of each motor (counts), or (yaw, pitch).
    period_s : (float, float)
        Range of a loop's period (s).
    hold_fraction : float
        Probability that a segment is a hold (both motors still, 0.5-2 s).
    burn_in_s : float
        Driving before the recording's first sample (a recording starting mid-loop).
    lockstep : float, optional
        When given, the pitch motor is ``lockstep`` x the yaw motor throughout (a
        recording that cannot separate coupling).

    Returns
    -------
    t_s : ndarray, shape (m,)
        Times (s), ``t_s[start] = 0``.
    enc_yaw, enc_pitch : ndarray, shape (m,)
        Inputs (counts, whole numbers).
    start : int
        Index of the recording's first sample.
    """
    n_burn = int(round(burn_in_s * rate_hz))
    m = n_burn + int(n_samples)
    v = np.empty((2, m))
    k, phase = 0, float(rng.uniform(0.0, 2.0 * np.pi))
    while k < m:
        if rng.uniform() < hold_fraction:
            n_hold = int(rng.uniform(0.5, 2.0) * rate_hz)
            v[:, k : k + n_hold] = v[:, k - 1 : k] if k > 0 else 0.0
            k += n_hold
            continue
        amp = rng.uniform(0.2, 1.0, 2) * np.asarray(v_max_counts, dtype=float)
        n_loop = max(int(rng.uniform(*period_s) * rate_hz), 8)
        ph = phase + 2.0 * np.pi * np.arange(1, n_loop + 1) / n_loop
        if rng.uniform() < 0.5:  # circle (an ellipse: each motor its own amplitude)
            seg = np.stack([amp[0] * np.sin(ph), amp[1] * np.cos(ph)])
        else:  # figure-eight: pitch at twice the yaw frequency
            seg = np.stack([amp[0] * np.sin(ph), amp[1] * np.sin(2.0 * ph)])
        if k > 0:  # continue from where the inputs are: blend over a quarter loop
            w = np.clip(np.arange(1, n_loop + 1) / (0.25 * n_loop), 0.0, 1.0)
            seg = (1 - w) * v[:, k - 1 : k] + w * seg
        v[:, k : k + n_loop] = seg[:, : m - k]
        k += n_loop
    if lockstep is not None:
        v[1] = lockstep * v[0]
    t = (np.arange(m) - n_burn) / rate_hz
    return t, np.round(v[0]), np.round(v[1]), n_burn


def simulate_two_motor(
    seed: int,
    n_samples: int = 3000,
    rate_hz: float = 30.0,
    noise_deg: float | None = None,
    coupling: float | None = None,
    lockstep: float | None = None,
    v_max_counts: float = V_MAX_COUNTS,
) -> TwoMotorRecording:
    """A seeded two-motor recording (module docstring).

    Parameters
    ----------
    seed : int
    n_samples : int
        Samples recorded.
    rate_hz : float
        Sampling rate (Hz): 5 or 30 in the benchmark.
    noise_deg : float, optional
        Measurement noise sd (deg); default U(0.15, 0.5).
    coupling : float, optional
        Pitch's gain on the yaw motor / its own gain; default U(0.3, 0.8); 0: none.
    lockstep : float, optional
        Pitch motor = ``lockstep`` x yaw motor (:func:`two_motor_trajectory`).
    v_max_counts : float
        Full scale of each motor (counts).
    """
    rng = np.random.default_rng(seed)
    truth = {ax: random_two_tendon_params(rng, v_max_counts) for ax in ("yaw", "pitch")}
    k = float(rng.uniform(0.3, 0.8)) if coupling is None else float(coupling)
    sd = float(rng.uniform(0.15, 0.5)) if noise_deg is None else float(noise_deg)
    t, ey, ep, start = two_motor_trajectory(rng, n_samples, rate_hz, v_max_counts,
                                            lockstep=lockstep)  # fmt: skip
    c = coupling_factor(truth, k, v_max_counts)
    yaw, pitch = two_motor_angles({**truth, "c": c}, ey, ep)
    cut = slice(start, None)
    n = yaw[cut].size
    return TwoMotorRecording(
        t_s=t[cut],
        enc_yaw=ey[cut],
        enc_pitch=ep[cut],
        yaw_deg=yaw[cut] + rng.normal(0.0, sd, n),
        pitch_deg=pitch[cut] + rng.normal(0.0, sd, n),
        yaw_true_deg=yaw[cut],
        pitch_true_deg=pitch[cut],
        noise_deg=sd,
        coupling=k,
        truth={**truth, "c": c},
    )
