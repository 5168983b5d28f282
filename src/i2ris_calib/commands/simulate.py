"""``i2ris-calib simulate``: write a synthetic session folder with known truth.

Layout (docs/session.md): session.toml, one video + timestamp CSV (camera clock) per
camera, encoders.csv (controller clock), the true intrinsics as <camera>.yaml, and
truth/ (truth.json, truth_controller.csv, truth_frames.csv, frames_<camera>.csv).
The two videos render in two processes; the folder appears atomically when done.
"""

from __future__ import annotations

import multiprocessing as mp
import time
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
from rich.progress import Progress

from i2ris_calib.errors import CalibError
from i2ris_calib.hysteresis.kinds import LAB_TRUTH, SESSION_TRUTH
from i2ris_calib.io.atomic import write_csv, write_json, write_text
from i2ris_calib.io.camera_yaml import write_camera_yaml
from i2ris_calib.io.outputs import claim_output_dir, output_dir, output_lock
from i2ris_calib.io.provenance import provenance
from i2ris_calib.io.video import open_writer
from i2ris_calib.io.workers import quiet_pool
from i2ris_calib.simulation import trajectory as tj
from i2ris_calib.simulation.config import SimulationConfig
from i2ris_calib.simulation.lab import reference_window as lab_reference_window
from i2ris_calib.simulation.render import FrameRenderer
from i2ris_calib.simulation.scene import CameraModel, make_cameras, make_cube, true_marker_corners
from i2ris_calib.simulation.truth import Truth, session_truth, truth_at
from i2ris_calib.tracking.geometry import tip_rotation


@dataclass(frozen=True)
class CameraPlan:
    """Everything one render worker needs for one camera."""

    cam: CameraModel
    path: Path
    rotations: np.ndarray  # (n_kept, samples, 3, 3)
    flash: np.ndarray  # (n_kept,)
    occluded: np.ndarray  # (n_kept,) bool
    seed: int


#: The names ``simulate`` writes (older, unmarked session folders are recognised by them).
OUTPUTS = ("session.toml", "encoders.csv", "truth", "*_timestamps.csv", "*.mp4", "*.avi",
           "*.mkv", "*.yaml")  # fmt: skip


def write_simulated_session(
    out: Path, config, seed: int | None = None, force: bool = False
) -> Path:
    """Render a session into ``out`` (see module doc); returns the folder.

    Parameters
    ----------
    out : Path
        Session folder to create; must be new or empty, unless ``force`` and it was
        written by ``simulate`` (a folder the tool did not write is never replaced).
    config : PipelineConfig
        Uses its ``simulate`` section.
    seed : int, optional
        Overrides ``simulate.seed``.
    """
    cfg: SimulationConfig = config.simulate
    if seed is not None:
        cfg = replace(cfg, seed=int(seed))
    out = Path(out)
    if out.exists() and not force and not (out.is_dir() and not any(out.iterdir())):
        raise CalibError(
            f"{out} already exists (choose another --out or pass --force to replace it)"
        )
    claim_output_dir(out, "simulate", (), OUTPUTS)
    with output_lock(out, command="simulate"):  # one simulate at a time into ``out``
        with output_dir(out, "simulate", (), OUTPUTS) as tmp:
            build_session(tmp, cfg, name=out.name, progress=True)
        return out


def build_session(
    folder: Path, cfg: SimulationConfig, name: str = "session", progress: bool = False
) -> dict:
    """Write all session files into the existing ``folder``; returns the truth summary."""
    ss = np.random.SeedSequence(cfg.seed)
    s_cam, s_time, s_render = ss.spawn(3)
    cams = make_cameras(cfg, np.random.default_rng(s_cam))
    dictionary = cv2.aruco.getPredefinedDictionary(_dictionary_id(cfg.dictionary))
    bits = {
        c.view: cv2.aruco.generateImageMarker(dictionary, c.marker_id, _cells(dictionary))
        for c in cams
    }
    cube = make_cube(cfg, bits)
    truth = session_truth(cfg)
    rng_t = np.random.default_rng(s_time)
    t0_ctrl = tj.motion_start_ctrl_s(cfg)
    occl = {c.name: tj.occlusion_intervals_cam(cfg, rng_t) for c in cams}
    flashes = tj.flash_intervals_cam(cfg)
    plans, frame_tables = [], {}
    seeds = s_render.generate_state(len(cams))
    for i, cam in enumerate(cams):
        plan, table = _camera_plan(
            folder, cfg, cam, i, truth, t0_ctrl, (flashes, occl[cam.name]), rng_t, int(seeds[i])
        )
        plans.append(plan)
        frame_tables[cam.name] = table
        write_csv(folder / f"{cam.name}_timestamps.csv", table[["frame", "time_s"]], "%.6f")
        if cfg.write_calibration:
            write_camera_yaml(
                folder / f"{cam.name}.yaml", cam.K, np.zeros(5), cam.width_px, cam.height_px
            )
    _render_all(plans, cube, cfg, progress)
    _write_encoders(folder, cfg, truth, t0_ctrl, flashes)
    summary = _write_truth(folder, cfg, cams, truth, t0_ctrl, frame_tables)
    write_text(folder / "session.toml", session_toml(cfg, cams, name))
    return summary


def _camera_plan(folder, cfg, cam, i: int, truth, t0_ctrl: float, intervals, rng_t, seed: int):
    """(CameraPlan, frame table) of camera ``i``: its frame times (drawn from ``rng_t``:
    jitter, dropped frames), the tip's rotation over each exposure, the flash and
    occlusion (``intervals`` = (flashes, this camera's occlusions)) per frame, and the
    truth table (frame, camera and controller times, angles in deg, visible, occluded,
    flash)."""
    flashes, occlusions = intervals
    t_all = tj.frame_times(cfg, i, rng_t)
    keep = tj.kept_frames(cfg, t_all.size, rng_t)
    t_cam = t_all[keep]
    rot, yaw, pitch = _exposure_rotations(cfg, truth, t_cam, t0_ctrl)
    half = cfg.exposure_s / 2
    flash = tj.interval_overlap(t_cam - half, t_cam + half, flashes)
    occluded = tj.interval_overlap(t_cam - half, t_cam + half, occlusions) > 0
    video = folder / f"{cam.name}.{cfg.video_format}"
    plan = CameraPlan(cam, video, rot, flash, occluded, seed)
    inside = _marker_inside(cfg, cam, rot[:, rot.shape[1] // 2])
    table = pd.DataFrame(
        {
            "frame": np.arange(t_cam.size),
            "time_s": t_cam,
            "time_ctrl_s": tj.ctrl_from_cam(cfg, t_cam),
            "yaw_deg": yaw,
            "pitch_deg": pitch,
            "visible": (~occluded & inside).astype(int),
            "occluded": occluded.astype(int),
            "flash": flash,
        }
    )
    return plan, table


def _dictionary_id(name: str) -> int:
    if not hasattr(cv2.aruco, name):
        raise CalibError(f"unknown ArUco dictionary '{name}' (use e.g. DICT_4X4_50)")
    return getattr(cv2.aruco, name)


def _cells(dictionary) -> int:
    return int(dictionary.markerSize) + 2


def _exposure_rotations(cfg, truth: Truth, t_cam: np.ndarray, t0_ctrl: float):
    """Tip rotations over each exposure (n, m, 3, 3) and mid-exposure truth angles."""
    m = cfg.motion_blur_samples
    offs = (np.arange(m) + 0.5) / m - 0.5 if m > 1 else np.zeros(1)
    tt = t_cam[:, None] + offs[None, :] * cfg.exposure_s
    tau = tj.ctrl_from_cam(cfg, tt) - t0_ctrl
    yaw, pitch = truth_at(cfg, truth, tau)  # exact at these times (whole_history truth)
    rot = np.array(
        [
            [tip_rotation(y, p) for y, p in zip(ry, rp, strict=True)]
            for ry, rp in zip(yaw, pitch, strict=True)
        ]
    )
    tau_mid = tj.ctrl_from_cam(cfg, t_cam) - t0_ctrl
    return (rot, *truth_at(cfg, truth, tau_mid))


def _marker_inside(cfg, cam: CameraModel, rotations: np.ndarray) -> np.ndarray:
    """Whether the whole marker lies inside the image (2 px margin), per frame."""
    ok = np.empty(len(rotations), bool)
    for k, R in enumerate(rotations):
        uv = true_marker_corners(cam, cfg.cube_size_mm, cfg.marker_size_mm, cfg.pivot_mm, R)
        ok[k] = (
            (uv.min() >= 2)
            and (uv[:, 0].max() <= cam.width_px - 3)
            and (uv[:, 1].max() <= cam.height_px - 3)
        )
    return ok


_COUNTER = None


def _init_worker(counter) -> None:
    global _COUNTER
    _COUNTER = counter


def _render_camera(plan: CameraPlan, cube, cfg: SimulationConfig) -> int:
    """Render and encode one camera's video (runs in a worker process)."""
    renderer = FrameRenderer(cfg, plan.cam, cube, plan.seed)
    writer = open_writer(plan.path, cfg.fps, (cfg.width_px, cfg.height_px))
    try:
        for k in range(len(plan.rotations)):
            img = renderer.render(
                list(plan.rotations[k]), float(plan.flash[k]), bool(plan.occluded[k])
            )
            writer.write(img)
            if _COUNTER is not None and k % 10 == 9:
                with _COUNTER.get_lock():
                    _COUNTER.value += 10
    finally:
        writer.release()
    return len(plan.rotations)


def _render_all(plans: list[CameraPlan], cube, cfg: SimulationConfig, progress: bool) -> None:
    """Render the cameras in parallel processes with a progress bar."""
    ctx = mp.get_context("spawn")  # fork can deadlock on inherited OpenCV threads
    counter = ctx.Value("l", 0)
    total = sum(len(p.rotations) for p in plans)
    work = [(_render_camera, p, cube, cfg) for p in plans]
    with quiet_pool(len(plans), ctx, work, _init_worker, (counter,)) as futs:
        with Progress(disable=not progress, transient=True) as bar:
            task = bar.add_task("rendering videos", total=total)
            while not all(f.done() for f in futs):
                bar.update(task, completed=counter.value)
                time.sleep(0.2)
        for f in futs:
            f.result()


def _write_encoders(folder: Path, cfg, truth: Truth, t0_ctrl: float, flashes: np.ndarray) -> None:
    """encoders.csv (controller clock) and truth/truth_controller.csv."""
    t_first = float(tj.ctrl_from_cam(cfg, cfg.camera_start_s)) - 0.5
    t_last = float(tj.ctrl_from_cam(cfg, cfg.camera_start_s + tj.video_duration_s(cfg))) + 0.5
    t_ctrl = np.arange(t_first, t_last, 1.0 / cfg.encoder_rate_hz)
    tau = t_ctrl - t0_ctrl
    idx = np.clip(np.rint((tau - truth.t_s[0]) * 1000.0).astype(int), 0, truth.t_s.size - 1)
    enc = pd.DataFrame(
        {"time_s": t_ctrl, "enc_yaw": truth.enc_yaw[idx], "enc_pitch": truth.enc_pitch[idx]}
    )
    if cfg.sync_flash:
        on = tj.ctrl_from_cam(cfg, flashes)
        enc["sync_flash"] = tj.interval_overlap(t_ctrl, t_ctrl + 1e-9, on).round().astype(int)
    write_csv(folder / "encoders.csv", enc, "%.6f")
    tc = enc[["time_s", "enc_yaw", "enc_pitch"]].copy()
    tc["yaw_deg"], tc["pitch_deg"] = truth_at(cfg, truth, tau)
    names = np.array([b.name for b in tj.session_blocks(cfg)] + [""])
    tc["dataset"] = names[truth.block[idx]]
    write_csv(folder / "truth" / "truth_controller.csv", tc, "%.6f")


def _write_truth(folder: Path, cfg, cams, truth: Truth, t0_ctrl: float, tables: dict) -> dict:
    """truth.json and the per-frame truth tables."""
    first = cams[0].name
    tf = tables[first][["frame", "time_s", "time_ctrl_s", "yaw_deg", "pitch_deg"]].copy()
    for c in cams:
        other = tables[c.name]
        j = np.clip(
            np.searchsorted(other["time_s"].to_numpy(), tf["time_s"].to_numpy()), 0, len(other) - 1
        )
        tf[f"visible_{c.name}"] = other["visible"].to_numpy()[j]
    write_csv(folder / "truth" / "truth_frames.csv", tf, "%.6f")
    for c in cams:
        write_csv(folder / "truth" / f"frames_{c.name}.csv", tables[c.name], "%.6f")
    blocks = tj.session_blocks(cfg)
    summary = {
        "schema": "i2ris-calib.truth/1",
        "seed": cfg.seed,
        "offset_s": cfg.offset_s,
        "drift_ppm": cfg.drift_ppm,
        "clock": "t_ctrl = offset_s + (1 + drift_ppm*1e-6) * t_cam",
        "motion_start_ctrl_s": t0_ctrl,
        "datasets": [
            {"name": b.name, "axis": b.axis, "sign": b.sign, "t0_ctrl_s": t0_ctrl + b.t0_s,
             "t1_ctrl_s": t0_ctrl + b.t1_s, "settle_start_ctrl_s": t0_ctrl + b.settle_start_s,
             "model": SESSION_TRUTH, "params": truth.params.get(b.name, {})}
            for b in blocks
        ],
        "effects": cfg.effects,
        "protocol": cfg.protocol,
        **({"lab": _lab_summary(cfg, truth, t0_ctrl)} if cfg.protocol == "lab" else {}),
        "cameras": {
            c.name: {"view": c.view, "marker_id": c.marker_id, "K": c.K, "R_cam_from_base": c.R_cb,
                     "t_cam_from_base_mm": c.t_cb, "frames": len(tables[c.name]),
                     "occluded_frames": int(tables[c.name]["occluded"].sum()),
                     "invisible_frames": int((tables[c.name]["visible"] == 0).sum())}
            for c in cams
        },
        "flash_intervals_cam_s": tj.flash_intervals_cam(cfg),
        "provenance": provenance([], cfg),
    }  # fmt: skip
    write_json(folder / "truth" / "truth.json", summary)
    return summary


def _lab_summary(cfg, truth: Truth, t0_ctrl: float) -> dict:
    """truth.json ``lab``: the two-motor truth and where the tip is held straight."""
    s0, s1 = truth.params["straight_motion_s"]
    start, duration = lab_reference_window(cfg)
    return {
        "model": LAB_TRUTH, "yaw": truth.params["yaw"], "pitch": truth.params["pitch"],
        "pitch_per_yaw_deg": truth.params["c"], "coupling": truth.params["coupling"],
        "angle_at_zero_input_deg": {"yaw": truth.params["yaw"]["theta0"],
                                    "pitch": truth.params["pitch"]["theta0"]},
        "driving_before_first_frame_s": cfg.lab_burn_in_s,
        "straight_ctrl_s": [t0_ctrl + s0, t0_ctrl + s1],
        "track_reference": {"reference_start_s": start, "reference_duration_s": duration},
    }  # fmt: skip


def session_toml(cfg: SimulationConfig, cams: list[CameraModel], name: str) -> str:
    """session.toml text for a simulated session (format in docs/session.md)."""
    lines = [
        "# Simulated session written by `i2ris-calib simulate` (docs/session.md).",
        f'name = "{name}"',
        'notes = "synthetic; truth in truth/"',
        "",
        "[encoder]",
        'file = "encoders.csv"',
        'format = "csv"',
        "",
        "[marker]",
        f'dictionary = "{cfg.dictionary}"',
        f"marker_size_mm = {cfg.marker_size_mm}",
        f"cube_size_mm = {cfg.cube_size_mm}",
    ]
    for c in cams:
        lines += [
            "",
            f"[cameras.{c.name}]",
            f'video = "{c.name}.{cfg.video_format}"',
            f'timestamps = "{c.name}_timestamps.csv"',
            f'view = "{c.view}"',
            f"marker_id = {c.marker_id}",
        ]
        if cfg.write_calibration:
            lines += ['model = "pinhole"', f'calibration = "{c.name}.yaml"']
        else:
            lines += ['model = "weak_perspective"']
    return "\n".join(lines) + "\n"
