"""Encoder input trajectories, clocks, frame times and scripted events.

Two motions (config ``motion``):

* ``"fig5"`` (default): the datasets run one after another; in each, one motor ramps
  out and back (with pauses at the peaks and after each return) while the other motor
  holds zero.
* ``protocol = "lab"`` (any ``motion``): both motors at once through zero, the
  recording starting mid-loop (:mod:`i2ris_calib.simulation.lab`); no datasets.
* ``"excursions"``: random excursions of every axis and direction of ``datasets`` in a
  shuffled order, each out to its own peak at its own speeds (up and down differ),
  a pause at every turning point, some with a minor loop on the way down, holds at
  zero of random length between excursions, and some run on both axes at once
  (compound moves). Two excursions per direction reach full amplitude (the first and
  the last), so a held-out cycle lies inside the fitted range.

Times here are seconds from the start of the motion, on the controller clock.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from i2ris_calib.simulation import lab
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
    """The datasets laid end to end (controller seconds from the motion start).

    With ``motion = "excursions"``: one block per excursion (sorted by start; the
    blocks of a compound move overlap in time; ``settle_start_s = t1_s``). With
    ``protocol = "lab"``: none (both motors move all the time).
    """
    if cfg.protocol == "lab":
        return []
    if cfg.motion == "excursions":
        return [e.block for e in excursion_schedule(cfg)]
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
    t_s = np.asarray(t_s, dtype=float)
    if cfg.protocol == "lab":
        d = lab.lab_drive(cfg)
        ey, ep = np.interp(t_s, d.t_s, d.enc_yaw), np.interp(t_s, d.t_s, d.enc_pitch)
        return np.rint(ey).astype(np.int64), np.rint(ep).astype(np.int64)
    if cfg.motion == "excursions":
        out = {}
        for axis in ("yaw", "pitch"):
            kt, kv = axis_knots(excursion_schedule(cfg), axis)
            out[axis] = np.interp(t_s, kt, kv, left=0.0, right=0.0) if kt.size else 0.0 * t_s
        return np.rint(out["yaw"]).astype(np.int64), np.rint(out["pitch"]).astype(np.int64)
    out = {"yaw": np.zeros(t_s.shape), "pitch": np.zeros(t_s.shape)}
    for b in session_blocks(cfg):
        amp = cfg.amplitude_counts[0 if b.axis == "yaw" else 1]
        kt, kv = dataset_knots(cfg, amp)
        inside = (t_s >= b.t0_s) & (t_s <= b.t1_s)
        out[b.axis][inside] = b.sign * np.interp(t_s[inside] - b.t0_s, kt, kv)
    return np.rint(out["yaw"]).astype(np.int64), np.rint(out["pitch"]).astype(np.int64)


def motion_duration_s(cfg: SimulationConfig) -> float:
    """Controller seconds from motion start to motion end."""
    if cfg.protocol == "lab":
        return lab.motion_duration(cfg)
    if cfg.motion == "excursions":
        return max(b.t1_s for b in session_blocks(cfg)) + cfg.settle_s
    return session_blocks(cfg)[-1].t1_s


@dataclass(frozen=True)
class Excursion:
    """One excursion of ``motion = "excursions"``.

    ``block`` names it and gives its span (s from the motion start); ``knots_t``
    (s, from ``block.t0_s``) and ``knots_v`` (|input|, counts) are its piecewise-linear
    profile, shape (k,) each, starting and ending at 0.
    """

    block: Block
    knots_t: np.ndarray
    knots_v: np.ndarray


def excursion_profile(
    rng: np.random.Generator,
    peak: float,
    base_speed: float,
    speed_factors: tuple[float, float],
    pause_s: float,
    minor_loop: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """Knots (times s from 0, |input| counts), shape (k,) each, of one excursion.

    Out to ``peak`` and back to 0; every ramp at its own speed ``base_speed x
    U(speed_factors)`` (counts/s); a pause of ``pause_s x U(0.5, 1.5)`` (at least
    0.15 s, so every frame-rate sampling sees the turning point) at each turn. With
    ``minor_loop``: on the way down, turn back up at 30-60 % of the peak to 60-90 %
    of the way back to it, then down to 0.
    """
    levels = [peak]
    if minor_loop:
        low = peak * rng.uniform(0.3, 0.6)
        levels += [low, low + (peak - low) * rng.uniform(0.6, 0.9)]
    levels.append(0.0)
    t, v = [0.0], [0.0]
    for i, target in enumerate(levels):
        speed = base_speed * rng.uniform(*speed_factors)
        t.append(t[-1] + abs(target - v[-1]) / speed)
        v.append(target)
        if i < len(levels) - 1:
            t.append(t[-1] + max(0.15, pause_s * rng.uniform(0.5, 1.5)))
            v.append(target)
    return np.asarray(t), np.asarray(v)


def excursion_schedule(cfg: SimulationConfig) -> list[Excursion]:
    """The excursions of ``motion = "excursions"``, sorted by start time.

    ``excursions`` per axis and direction named in ``datasets``, shuffled; peaks
    ``U(excursion_fractions) x amplitude`` except the first and last of each direction
    (full amplitude). With probability ``compound_fraction`` an excursion starts
    together with the next one when that one moves the other axis (the later one
    lagging by up to 40 % of the first's duration). ``rest_s`` at zero before the
    first, ``U(hold_s)`` at zero after every group. Deterministic in ``cfg.seed``
    (its own random stream: the other draws of the session do not change).
    """
    rng = np.random.default_rng(np.random.SeedSequence([int(cfg.seed), 8]))
    items = [(name[:-1], 1 if name[-1] == "+" else -1) for name in cfg.datasets]
    order = [it for it in items for _ in range(cfg.excursions)]
    order = [order[i] for i in rng.permutation(len(order))]
    seen: dict[tuple[str, int], int] = {}
    fracs = []
    lo, hi = cfg.excursion_fractions
    for it in order:
        seen[it] = seen.get(it, 0) + 1
        last = seen[it] == cfg.excursions
        fracs.append(1.0 if seen[it] == 1 or last else float(rng.uniform(lo, hi)))
    out, t, i = [], cfg.rest_s, 0
    while i < len(order):
        group = [i]
        if (
            i + 1 < len(order)
            and order[i + 1][0] != order[i][0]
            and rng.random() < cfg.compound_fraction
        ):
            group.append(i + 1)
        end, lag = t, 0.0
        for j in group:
            axis, sign = order[j]
            amp = cfg.amplitude_counts[0 if axis == "yaw" else 1]
            kt, kv = excursion_profile(
                rng, fracs[j] * amp, amp / cfg.ramp_s, cfg.speed_factors, cfg.pause_s,
                bool(rng.random() < cfg.minor_loop_fraction),
            )  # fmt: skip
            t0 = t + lag
            name = f"{axis}{'+' if sign > 0 else '-'}"
            out.append(Excursion(Block(name, axis, sign, t0, t0 + kt[-1], t0 + kt[-1]), kt, kv))
            end = max(end, t0 + kt[-1])
            lag = float(rng.uniform(0.0, 0.4)) * kt[-1]
        t = end + float(rng.uniform(*cfg.hold_s))
        i += len(group)
    return sorted(out, key=lambda e: e.block.t0_s)


def axis_knots(schedule: list[Excursion], axis: str) -> tuple[np.ndarray, np.ndarray]:
    """Signed input knots (times s from the motion start, counts) of one axis, (k,) each."""
    ts, vs = [], []
    for e in schedule:
        if e.block.axis == axis:
            ts.append(e.block.t0_s + e.knots_t)
            vs.append(e.block.sign * e.knots_v)
    if not ts:
        return np.zeros(0), np.zeros(0)
    return np.concatenate(ts), np.concatenate(vs)


def ctrl_from_cam(cfg: SimulationConfig, t_cam: np.ndarray) -> np.ndarray:
    """Controller-clock time of camera-clock times (docs/sync.md clock convention)."""
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
