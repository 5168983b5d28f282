"""Synthetic sync truth without video: encoder log, angles and flashes with known clocks.

Used by the sync tests and ``benchmarks/bench_sync.py``. The angle is produced by an
independent, deliberately plain implementation of the I2RIS EGPI model (MODEL.md
Eq16-24: one ascending and two descending linear envelopes, exponential density,
regulator ``kappa`` on the second descending stage below the flag point ``v_f``), so
the sync estimators are tested against a model they do not share code with.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from i2ris_calib.sync.log import EncoderLog, make_encoder_log


@dataclass(frozen=True)
class SyntheticSync:
    """A synthetic session reduced to what the sync stage reads, plus the truth.

    Attributes
    ----------
    angles : DataFrame
        angles.csv-like: frame, time_s (camera clock), yaw_deg, pitch_deg, status,
        mean_gray_<camera> for each camera.
    log : EncoderLog
        Encoder channels (and sync_flash when ``flashes`` was given).
    log_frame : DataFrame
        The log as encoders.csv columns: time_s, enc_yaw, enc_pitch[, sync_flash].
    offset_s, drift_ppm : float
        True clock parameters.
    backlash_deg : float
        Stage-1 loop width ``2 * sum_i p(r_i) r_i``, deg.
    """

    angles: pd.DataFrame
    log: EncoderLog
    log_frame: pd.DataFrame
    offset_s: float
    drift_ppm: float
    backlash_deg: float
    meta: dict = field(default_factory=dict)


def sweep_trajectory(
    t_s: np.ndarray, amplitudes: tuple[float, ...], period_s: float, rest_s: float
) -> np.ndarray:
    """Fig-5-like input: up-and-down sweeps from 0 of growing amplitude, with rests.

    Each sweep is ``A * (1 - cos(2 pi u)) / 2`` for ``u`` in [0, 1] over ``period_s``
    (the speed varies along the sweep, which is what separates a clock offset from
    backlash), followed by ``rest_s`` at 0.
    """
    v = np.zeros_like(t_s, dtype=float)
    t0 = 0.0
    for a in amplitudes:
        u = (t_s - t0) / period_s
        inside = (u >= 0) & (u <= 1)
        v[inside] = a * 0.5 * (1 - np.cos(2 * np.pi * u[inside]))
        t0 += period_s + rest_s
    return v


def egpi_truth(
    v: np.ndarray,
    slope_deg: float,
    backlash_deg: float,
    kappa: float = 2.0,
    v_f: float | None = None,
    n: int = 30,
) -> np.ndarray:
    """Plain-numpy EGPI (MODEL.md Eq16-24) with linear envelopes, for synthetic truth.

    Parameters
    ----------
    v : ndarray, shape (k,)
        Input (counts).
    slope_deg : float
        Envelope slope, deg per count (all three envelopes).
    backlash_deg : float
        Stage-1 loop width ``2 * sum p(r_i) r_i``, deg; thresholds are scaled to it.
    kappa : float
        Regulator of the second descending stage (``v <= v_f``).
    v_f : float, optional
        Flag point, counts; default 40% of max(v).
    n : int
        Number of nonzero thresholds (n + 1 operators).

    Returns
    -------
    ndarray, shape (k,)
        Angle, deg.
    """
    v = np.asarray(v, dtype=float)
    v_f = 0.4 * float(v.max()) if v_f is None else v_f
    r = np.concatenate([[0.0], np.linspace(0.05, 1.0, n)])
    p = np.exp(-1.0 * r)
    p /= p.sum()
    r = r * backlash_deg / (2 * float(p @ r))  # loop width = backlash_deg
    gl = gr1 = gr2 = slope_deg * v  # the stages differ by the threshold scale kappa
    w1 = np.clip(np.zeros_like(r), gl[0] - r, gr1[0] + r)
    w2 = np.clip(np.zeros_like(r), gl[0] - r, gr2[0] + kappa * r)
    y = np.empty_like(v)
    rising = True
    for k in range(v.size):
        if k and v[k] > v[k - 1]:
            w1 = np.maximum(gl[k] - r, w1)
            w2 = np.maximum(gl[k] - r, w2)
            rising = True
        elif k and v[k] < v[k - 1]:
            w1 = np.minimum(gr1[k] + r, w1)
            w2 = np.minimum(gr2[k] + kappa * r, w2)
            rising = False
        use2 = (not rising) and v[k] <= v_f
        y[k] = p @ (w2 if use2 else w1)
    return y


def make_sync_case(
    seed: int = 0,
    offset_s: float = 0.5,
    drift_ppm: float = 80.0,
    backlash_deg: float = 6.0,
    duration_s: float = 60.0,
    fps: float = 30.0,
    log_rate_hz: float = 500.0,
    angle_noise_deg: float = 0.1,
    flashes: tuple[tuple[float, float], ...] = (),
    exposure_frac: float = 1.0,
    gray_noise: float = 0.5,
    cameras: tuple[str, ...] = ("top", "side"),
    max_counts: float = 6000.0,
    slope_deg: float = 40.0 / 6000.0,
    kappa: float = 2.0,
    log_edge: str = "sampled",
) -> SyntheticSync:
    """A seeded synthetic sync case with known offset and drift.

    Parameters
    ----------
    seed : int
        Seed of every random choice (noise, frame phases).
    offset_s, drift_ppm : float
        True clock: ``t_ctrl = offset_s + (1 + drift_ppm*1e-6) * t_cam``.
    backlash_deg : float
        Stage-1 hysteresis loop width, deg (0 = no hysteresis).
    duration_s, fps : float
        Camera recording length (camera clock, s) and frame rate.
    log_rate_hz : float
        Encoder log rate (controller clock).
    angle_noise_deg : float
        Tracking noise added to the angles, deg (sd).
    flashes : tuple of (on_s, length_s)
        LED flashes in controller time relative to the first frame's controller time;
        () = no sync event (no ``sync_flash`` column).
    exposure_frac : float
        Exposure / frame interval; frame timestamps are the middle of the exposure.
    gray_noise : float
        Grey-level noise (sd, 0-255 scale).
    cameras : tuple of str
        Camera names (one mean_gray column each; their frames are offset by a
        random fraction of the frame interval).
    max_counts, slope_deg, kappa
        Trajectory amplitude (counts), envelope slope (deg/count), stage-2 regulator.
    log_edge : {"sampled", "tick"}
        "sampled": the LED switches at arbitrary times and the log samples its state
        (``sync.log_edge_at = "midpoint"``, like ``i2ris-calib simulate``); "tick": the
        LED switches at logged ticks (``log_edge_at = "first_on"``).
    """
    rng = np.random.default_rng(seed)
    drift = 1.0 + drift_ppm * 1e-6
    # controller timeline with margins around the video
    t_ctrl0 = offset_s - 1.0
    t_ctrl = t_ctrl0 + np.arange(int((duration_s * drift + 2.0) * log_rate_hz)) / log_rate_hz
    t_ctrl += rng.uniform(0, 0.2 / log_rate_hz, t_ctrl.size)  # small logging jitter
    t_ctrl = np.sort(t_ctrl)
    amps = tuple(max_counts * a for a in (0.35, 0.6, 0.8, 1.0, 0.5, 0.9, 0.7))
    period = (duration_s - 2.0) / len(amps) * 0.8
    rest = (duration_s - 2.0) / len(amps) * 0.2
    u = t_ctrl - (offset_s + 1.0)  # trajectory starts 1 s after the first frame
    yaw_true = sweep_trajectory(u, amps, period, rest)
    pitch_true = np.zeros_like(yaw_true)
    yaw_deg = egpi_truth(yaw_true, slope_deg, backlash_deg, kappa=kappa)
    enc_yaw = np.round(yaw_true)
    enc_pitch = np.round(pitch_true)

    # camera frames (shared camera clock, each camera with its own phase)
    interval = 1.0 / fps
    phase = rng.uniform(0, interval)
    t_cam = phase + np.arange(int(duration_s * fps)) * interval
    t_cam_ctrl = offset_s + drift * t_cam
    yaw_at_frames = np.interp(t_cam_ctrl, t_ctrl, yaw_deg)
    angles = pd.DataFrame(
        {
            "frame": np.arange(t_cam.size),
            "time_s": t_cam,
            "yaw_deg": yaw_at_frames + rng.normal(0, angle_noise_deg, t_cam.size),
            "pitch_deg": rng.normal(0, angle_noise_deg, t_cam.size),
            "status": "measured",
            "reproj_err_px": 0.1,
        }
    )
    flash_state = np.zeros_like(t_ctrl)
    on_intervals = []
    for on_rel, length in flashes:
        t_on = t_cam_ctrl[0] + on_rel + rng.uniform(0, 1 / log_rate_hz)
        t_off = t_on + length
        k_on, k_off = np.searchsorted(t_ctrl, [t_on, t_off])
        flash_state[k_on:k_off] = 1.0
        if log_edge == "tick":  # LED switched at logged controller ticks
            t_on, t_off = t_ctrl[k_on], t_ctrl[k_off]
        # "sampled": LED switched at t_on/t_off, the log samples its state
        on_intervals.append((t_on, t_off))
    exposure = exposure_frac * interval
    for i, cam in enumerate(cameras):
        shift = 0.0 if i == 0 else rng.uniform(0, interval)
        tc = t_cam + shift
        lit = _lit_exposure(offset_s + drift * tc, exposure * drift, on_intervals)
        gray = 60.0 + 5.0 * np.sin(0.3 * tc) + 120.0 * lit + rng.normal(0, gray_noise, tc.size)
        # angles.csv has one row per fused frame: sample this camera's grey at its own frames
        angles[f"mean_gray_{cam}"] = np.interp(t_cam, tc, gray) if shift == 0 else gray
        if shift:
            angles[f"time_s_{cam}"] = tc
    channels = {"enc_yaw": (t_ctrl, enc_yaw), "enc_pitch": (t_ctrl, enc_pitch)}
    frame = pd.DataFrame({"time_s": t_ctrl, "enc_yaw": enc_yaw, "enc_pitch": enc_pitch})
    flash = None
    if flashes:
        flash = (t_ctrl, flash_state)
        frame["sync_flash"] = flash_state.astype(int)
    log = make_encoder_log(channels, flash, "synthetic", max_gap_s=1.0)
    return SyntheticSync(
        angles=angles,
        log=log,
        log_frame=frame,
        offset_s=offset_s,
        drift_ppm=drift_ppm,
        backlash_deg=backlash_deg,
        meta={"seed": seed, "fps": fps, "exposure_s": exposure, "yaw_deg_ctrl": yaw_deg},
    )


def _lit_exposure(t_mid_ctrl: np.ndarray, exposure: float, on: list[tuple[float, float]]):
    """Fraction of each exposure (centred at ``t_mid_ctrl``, controller clock) lit by the LED."""
    lit = np.zeros_like(t_mid_ctrl)
    a, b = t_mid_ctrl - exposure / 2, t_mid_ctrl + exposure / 2
    for t_on, t_off in on:
        lit += np.clip(np.minimum(b, t_off) - np.maximum(a, t_on), 0, None) / exposure
    return lit
