"""Encoder input trajectories (Fig-5-like), clocks, frame times and scripted events.

The session runs the datasets one after another; in each, one motor ramps out and
back (with pauses at the peaks and after each return) while the other motor holds
zero. Times here are seconds from the start of the motion, on the controller clock.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from i2ris_calib.simulation.config import SimulationConfig

#: Seconds of video before the motion starts and after it ends.
LEAD_S = 1.0


@dataclass(frozen=True)
class Block:
    """One dataset: which motor, which sign, and its time span (s from motion start)."""

    name: str  # "yaw+", "yaw-", "pitch+", "pitch-"
    axis: str  # "yaw" | "pitch"
    sign: int  # +1 | -1
    t0_s: float
    t1_s: float
    settle_start_s: float  # residual angle relaxed to 0 from here to t1_s


def dataset_knots(cfg: SimulationConfig, amplitude: float) -> tuple[np.ndarray, np.ndarray]:
    """Piecewise-linear |input| knots (times s, counts) of one dataset, starting at 0 s.

    Shape (k,) each. Rest, then ``cycles`` ramps out to ``cycle_fractions[i] *
    amplitude`` and back at constant speed, a pause at each peak and after each return,
    then ``settle_s`` at zero.
    """
    t, v = [0.0, cfg.rest_s], [0.0, 0.0]
    speed = amplitude / cfg.ramp_s
    for i in range(cfg.cycles):
        peak = cfg.cycle_fractions[i % len(cfg.cycle_fractions)] * amplitude
        dur = peak / speed
        for target in (peak, 0.0):
            t += [t[-1] + dur, t[-1] + dur + cfg.pause_s]
            v += [target, target]
    t.append(t[-1] + cfg.settle_s)
    v.append(0.0)
    return np.asarray(t), np.asarray(v)


def session_blocks(cfg: SimulationConfig) -> list[Block]:
    """The datasets laid end to end (controller seconds from the motion start)."""
    blocks, t = [], 0.0
    for name in cfg.datasets:
        axis, sign = name[:-1], (1 if name[-1] == "+" else -1)
        amp = cfg.amplitude_counts[0 if axis == "yaw" else 1]
        kt, _ = dataset_knots(cfg, amp)
        blocks.append(Block(name, axis, sign, t, t + kt[-1], t + kt[-1] - cfg.settle_s))
        t += kt[-1]
    return blocks


def session_inputs(cfg: SimulationConfig, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Integer encoder counts (yaw, pitch), each shape (n,), at motion times ``t_s``."""
    out = {"yaw": np.zeros(t_s.shape), "pitch": np.zeros(t_s.shape)}
    for b in session_blocks(cfg):
        amp = cfg.amplitude_counts[0 if b.axis == "yaw" else 1]
        kt, kv = dataset_knots(cfg, amp)
        inside = (t_s >= b.t0_s) & (t_s <= b.t1_s)
        out[b.axis][inside] = b.sign * np.interp(t_s[inside] - b.t0_s, kt, kv)
    return np.rint(out["yaw"]).astype(np.int64), np.rint(out["pitch"]).astype(np.int64)


def motion_duration_s(cfg: SimulationConfig) -> float:
    """Controller seconds from motion start to motion end."""
    return session_blocks(cfg)[-1].t1_s


def ctrl_from_cam(cfg: SimulationConfig, t_cam: np.ndarray) -> np.ndarray:
    """Controller-clock time of camera-clock times (COMMON.md clock convention)."""
    return cfg.offset_s + (1.0 + cfg.drift_ppm * 1e-6) * np.asarray(t_cam, dtype=float)


def cam_from_ctrl(cfg: SimulationConfig, t_ctrl: np.ndarray) -> np.ndarray:
    """Inverse of :func:`ctrl_from_cam`."""
    return (np.asarray(t_ctrl, dtype=float) - cfg.offset_s) / (1.0 + cfg.drift_ppm * 1e-6)


def motion_start_ctrl_s(cfg: SimulationConfig) -> float:
    """Controller time at which the motion starts (LEAD_S after the first frame)."""
    return float(ctrl_from_cam(cfg, cfg.camera_start_s + LEAD_S))


def video_duration_s(cfg: SimulationConfig) -> float:
    """Camera seconds covered by the videos."""
    return motion_duration_s(cfg) + 2 * LEAD_S


def frame_times(cfg: SimulationConfig, camera_index: int, rng: np.random.Generator) -> np.ndarray:
    """Camera-clock times (s) of every captured frame of one camera, shape (n,).

    Includes frames that will be dropped; jitter keeps times strictly increasing.
    """
    n = int(np.floor(video_duration_s(cfg) * cfg.fps)) + 1
    t = cfg.camera_start_s + np.arange(n) / cfg.fps + camera_index * cfg.second_camera_phase_s
    if cfg.timestamp_jitter_s > 0:
        jit = rng.normal(0.0, cfg.timestamp_jitter_s, n)
        t = t + np.clip(jit, -0.3 / cfg.fps, 0.3 / cfg.fps)
    return t


def kept_frames(cfg: SimulationConfig, n: int, rng: np.random.Generator) -> np.ndarray:
    """Boolean mask (n,): frames written to the video (the others are dropped).

    The first and last frames are always kept.
    """
    keep = rng.random(n) >= cfg.drop_fraction
    keep[0] = keep[-1] = True
    return keep


def flash_intervals_cam(cfg: SimulationConfig) -> np.ndarray:
    """Sync-flash on/off intervals (k, 2) in camera-clock seconds (empty if disabled)."""
    if not cfg.sync_flash:
        return np.zeros((0, 2))
    if cfg.flash_times_s:
        return np.array([[s, s + cfg.flash_duration_s] for s in cfg.flash_times_s])
    # n_flashes spread over the recording (first 0.5 s after the first frame, last ending
    # 0.5 s before the end), each a little longer than the one before so the sync can
    # match them unambiguously, and shifted by a different fraction of a frame so their
    # edges do not all fall at the same exposure phase.
    k = np.arange(cfg.n_flashes)
    durations = cfg.flash_duration_s * (1.0 + 0.25 * k)
    first = cfg.camera_start_s + 0.5 * LEAD_S
    last = cfg.camera_start_s + video_duration_s(cfg) - 0.5 * LEAD_S - durations[-1]
    starts = np.linspace(first, last, cfg.n_flashes) if cfg.n_flashes > 1 else np.array([first])
    starts = starts + (0.37 * k % 1.0) / cfg.fps
    return np.column_stack([starts, starts + durations])


def occlusion_intervals_cam(cfg: SimulationConfig, rng: np.random.Generator) -> np.ndarray:
    """Random occlusion intervals (k, 2) in camera seconds, inside the motion."""
    if cfg.occlusions <= 0:
        return np.zeros((0, 2))
    t0 = cfg.camera_start_s + LEAD_S + 1.0
    t1 = cfg.camera_start_s + video_duration_s(cfg) - LEAD_S - cfg.occlusion_s
    starts = np.sort(rng.uniform(t0, max(t1, t0 + 1e-3), cfg.occlusions))
    return np.stack([starts, starts + cfg.occlusion_s], axis=1)


def interval_overlap(t0: np.ndarray, t1: np.ndarray, intervals: np.ndarray) -> np.ndarray:
    """Fraction of each window [t0, t1] (arrays (n,)) covered by ``intervals`` (k, 2)."""
    t0 = np.asarray(t0, dtype=float)
    t1 = np.asarray(t1, dtype=float)
    cov = np.zeros(t0.shape)
    for a, b in intervals:
        cov += np.clip(np.minimum(t1, b) - np.maximum(t0, a), 0.0, None)
    width = np.maximum(t1 - t0, 1e-12)
    return np.clip(cov / width, 0.0, 1.0)
