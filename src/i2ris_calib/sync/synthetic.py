"""Synthetic sync truth without video: encoder log, angles and flashes with known clocks.

Used by the sync tests and ``benchmarks/bench_sync.py``. The input is the
hysteresis presets' Fig-5-like loading trajectory and the angle the I2RIS EGPI model
(docs/models.md, Eq16-24) with the presets' parameter recipe, rescaled to a chosen backlash.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from i2ris_calib.hysteresis.models import density, i2ris_egpi_model, thresholds
from i2ris_calib.hysteresis.presets import loading_trajectory, random_i2ris_egpi_params
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
        Stage-1 reversal dead band of the truth, deg.
    meta : dict
        seed, fps, exposure_s, truth_params (EGPI) and flash_intervals_ctrl_s (the
        true LED on/off times, controller clock).
    """

    angles: pd.DataFrame
    log: EncoderLog
    log_frame: pd.DataFrame
    offset_s: float
    drift_ppm: float
    backlash_deg: float
    meta: dict = field(default_factory=dict)


def egpi_truth_params(rng: np.random.Generator, backlash_deg: float) -> dict[str, float]:
    """I2RIS-EGPI truth (hysteresis presets recipe) rescaled to a given backlash.

    ``backlash_deg`` is the stage-1 reversal dead band ``2 * sum p(r_i) r_i / sum p(r_i)``
    (deg): the angle the input must "take up" after a reversal. Thresholds scale by
    ``c``, ``sigma`` by ``1/c`` (same density over the operators), and the envelope
    offsets follow the recipe (loading from rest starts at ~0 deg, both families meet
    at v = 0). 0 gives a hysteresis-free (linear) truth.
    """
    p = random_i2ris_egpi_params(rng)
    r = thresholds(p["r1"], p["rn"], 30)
    w = density(r, p["lam"], p["sigma"])
    b0 = 2 * float(w @ r) / float(w.sum())
    c = max(backlash_deg, 1e-9) / b0
    gap = p["a2"] - p["a4"]
    p.update(r1=p["r1"] * c, rn=p["rn"] * c, sigma=p["sigma"] / c)
    pr_over_p = 0.5 * backlash_deg
    p.update(a2=pr_over_p, a4=pr_over_p - gap * c)
    p["a6"] = p["a4"] + (1.0 - p["kappa"]) * pr_over_p
    return p


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
    n_cycles: int = 4,
    speed_counts_s: float = 1500.0,
    pause_s: float = 1.0,
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
        Stage-1 reversal dead band of the EGPI truth, deg (see :func:`egpi_truth_params`).
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
    n_cycles, speed_counts_s, pause_s
        Fig-5-like input (hysteresis presets ``loading_trajectory``): ramps out to
        0..6000 counts and back at constant speed with pauses; it starts 1 s after
        the first frame and stays at 0 once done (keep ``duration_s`` long enough).
    log_edge : {"sampled", "tick"}
        "sampled": the LED switches at arbitrary times and the log samples its state
        (``sync.log_edge_at = "midpoint"``, like ``i2ris-calib simulate``); "tick": the
        LED switches at logged ticks (``log_edge_at = "first_on"``).
    """
    rng = np.random.default_rng(seed)
    drift = 1.0 + drift_ppm * 1e-6
    # every helper below draws from ``rng``: their order fixes each seed's case
    # controller timeline with margins around the video
    t_ctrl = _controller_times(rng, offset_s - 1.0, duration_s * drift + 2.0, log_rate_hz)
    enc_yaw, yaw_deg, truth = _yaw_truth(  # trajectory starts 1 s after the first frame
        rng, t_ctrl - (offset_s + 1.0), backlash_deg, n_cycles, speed_counts_s, pause_s
    )

    # camera frames (shared camera clock, each camera with its own phase)
    interval = 1.0 / fps
    phase = rng.uniform(0, interval)
    t_cam = phase + np.arange(int(duration_s * fps)) * interval
    t_cam_ctrl = offset_s + drift * t_cam
    angles = _frame_angles(rng, t_cam, np.interp(t_cam_ctrl, t_ctrl, yaw_deg), angle_noise_deg)
    flash_state, on_intervals = _flash_state(
        rng, t_ctrl, t_cam_ctrl[0], flashes, log_rate_hz, log_edge
    )
    exposure = exposure_frac * interval
    grays = _camera_grays(
        rng, t_cam, cameras, (offset_s, drift), (interval, exposure), on_intervals, gray_noise
    )
    for name, column in grays.items():
        angles[name] = column
    log, frame = _encoder_log(t_ctrl, enc_yaw, flash_state if flashes else None)
    return SyntheticSync(
        angles=angles,
        log=log,
        log_frame=frame,
        offset_s=offset_s,
        drift_ppm=drift_ppm,
        backlash_deg=backlash_deg,
        meta={
            "seed": seed,
            "fps": fps,
            "exposure_s": exposure,
            "truth_params": truth,
            "flash_intervals_ctrl_s": on_intervals,
        },
    )


def _controller_times(
    rng: np.random.Generator, t0: float, length_s: float, rate_hz: float
) -> np.ndarray:
    """Jittered, sorted controller-clock sample times (s), ``length_s * rate_hz`` of them
    from ``t0`` (s); the jitter is uniform over 0.2 sample intervals."""
    t_ctrl = t0 + np.arange(int(length_s * rate_hz)) / rate_hz
    t_ctrl += rng.uniform(0, 0.2 / rate_hz, t_ctrl.size)  # small logging jitter
    return np.sort(t_ctrl)


def _yaw_truth(
    rng: np.random.Generator,
    u: np.ndarray,
    backlash_deg: float,
    n_cycles: int,
    speed_counts_s: float,
    pause_s: float,
) -> tuple[np.ndarray, np.ndarray, dict[str, float]]:
    """Yaw encoder counts and true yaw angle at trajectory times ``u`` (s, 0 = start).

    Returns
    -------
    enc_yaw : ndarray, shape (n,)
        Fig-5-like loading input, whole counts, 0 outside the trajectory.
    yaw_deg : ndarray, shape (n,)
        I2RIS-EGPI truth angle, deg.
    truth : dict
        The EGPI parameters (:func:`egpi_truth_params`).
    """
    t_traj, v_traj = loading_trajectory(
        rng, n_cycles=n_cycles, rate_hz=1000.0, speed_counts_s=speed_counts_s, pause_s=pause_s
    )
    truth = egpi_truth_params(rng, backlash_deg)
    enc_yaw = np.interp(u, t_traj, v_traj, left=0.0, right=0.0).round()
    return enc_yaw, i2ris_egpi_model().evaluate_dict(enc_yaw, truth), truth


def _frame_angles(
    rng: np.random.Generator, t_cam: np.ndarray, yaw_deg: np.ndarray, noise_deg: float
) -> pd.DataFrame:
    """angles.csv rows at camera times ``t_cam`` (s, shape (m,)): the true yaw (deg) plus
    tracking noise of sd ``noise_deg``, pitch noise only, every frame measured."""
    return pd.DataFrame(
        {
            "frame": np.arange(t_cam.size),
            "time_s": t_cam,
            "yaw_deg": yaw_deg + rng.normal(0, noise_deg, t_cam.size),
            "pitch_deg": rng.normal(0, noise_deg, t_cam.size),
            "status": "measured",
            "reproj_err_px": 0.1,
        }
    )


def _flash_state(
    rng: np.random.Generator,
    t_ctrl: np.ndarray,
    t_first_frame_ctrl: float,
    flashes: tuple[tuple[float, float], ...],
    log_rate_hz: float,
    log_edge: str,
) -> tuple[np.ndarray, list[tuple[float, float]]]:
    """Logged LED state and the true LED on/off times of ``flashes``.

    Returns
    -------
    flash_state : ndarray, shape (n,)
        1.0 at the controller samples ``t_ctrl`` where the LED is logged on, else 0.0.
    on_intervals : list of (t_on, t_off)
        True LED on/off times, controller clock, s.
    """
    flash_state = np.zeros_like(t_ctrl)
    on_intervals = []
    for on_rel, length in flashes:
        t_on = t_first_frame_ctrl + on_rel + rng.uniform(0, 1 / log_rate_hz)
        t_off = t_on + length
        k_on, k_off = np.searchsorted(t_ctrl, [t_on, t_off])
        flash_state[k_on:k_off] = 1.0
        if log_edge == "tick":  # LED switched at logged controller ticks
            t_on, t_off = t_ctrl[k_on], t_ctrl[k_off]
        # "sampled": LED switched at t_on/t_off, the log samples its state
        on_intervals.append((t_on, t_off))
    return flash_state, on_intervals


def _encoder_log(
    t_ctrl: np.ndarray, enc_yaw: np.ndarray, flash_state: np.ndarray | None
) -> tuple[EncoderLog, pd.DataFrame]:
    """The encoder log (yaw moving, pitch at 0, ``sync_flash`` when ``flash_state`` is
    given) and the same as encoders.csv columns."""
    enc_pitch = np.zeros_like(enc_yaw)
    channels = {"enc_yaw": (t_ctrl, enc_yaw), "enc_pitch": (t_ctrl, enc_pitch)}
    frame = pd.DataFrame({"time_s": t_ctrl, "enc_yaw": enc_yaw, "enc_pitch": enc_pitch})
    flash = None
    if flash_state is not None:
        flash = (t_ctrl, flash_state)
        frame["sync_flash"] = flash_state.astype(int)
    log = make_encoder_log(channels, flash, "synthetic", max_gap_s=1.0)
    return log, frame


def _camera_grays(
    rng: np.random.Generator,
    t_cam: np.ndarray,
    cameras: tuple[str, ...],
    clock: tuple[float, float],
    frame_exposure: tuple[float, float],
    on_intervals: list[tuple[float, float]],
    gray_noise: float,
) -> dict[str, np.ndarray]:
    """Mean grey level of each camera at the fused frames, and the own frame times of
    the cameras after the first.

    Parameters
    ----------
    t_cam : ndarray, shape (m,)
        Fused frame times (middle of the exposure), camera clock, s.
    clock : (offset_s, drift)
        True clock: ``t_ctrl = offset_s + drift * t_cam`` (``drift`` a factor, ~1).
    frame_exposure : (interval, exposure)
        Frame interval and exposure, camera clock, s.
    on_intervals : list of (t_on, t_off)
        LED on/off times, controller clock, s.
    gray_noise : float
        Grey-level noise sd (0-255 scale).

    Returns
    -------
    dict of str to ndarray, shape (m,)
        angles.csv columns in order: ``mean_gray_<camera>`` (0-255) and, for each camera
        after the first (shifted by a random fraction of the frame interval),
        ``time_s_<camera>`` (s).
    """
    offset_s, drift = clock
    interval, exposure = frame_exposure
    columns = {}
    for i, cam in enumerate(cameras):
        shift = 0.0 if i == 0 else rng.uniform(0, interval)
        tc = t_cam + shift
        lit = _lit_exposure(offset_s + drift * tc, exposure * drift, on_intervals)
        gray = 60.0 + 5.0 * np.sin(0.3 * tc) + 120.0 * lit + rng.normal(0, gray_noise, tc.size)
        # angles.csv has one row per fused frame: sample this camera's grey at its own frames
        columns[f"mean_gray_{cam}"] = np.interp(t_cam, tc, gray) if shift == 0 else gray
        if shift:
            columns[f"time_s_{cam}"] = tc
    return columns


def _lit_exposure(t_mid_ctrl: np.ndarray, exposure: float, on: list[tuple[float, float]]):
    """Fraction of each exposure (centred at ``t_mid_ctrl``, controller clock) lit by the LED."""
    lit = np.zeros_like(t_mid_ctrl)
    a, b = t_mid_ctrl - exposure / 2, t_mid_ctrl + exposure / 2
    for t_on, t_off in on:
        lit += np.clip(np.minimum(b, t_off) - np.maximum(a, t_on), 0, None) / exposure
    return lit
