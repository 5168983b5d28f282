"""``i2ris-calib sync``: read session + encoder log + angles, write synced.csv and sync.json.

Formats are documented in ``docs/sync.md``.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import typer
from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

from i2ris_calib.errors import CalibError
from i2ris_calib.io.angles import read_angles
from i2ris_calib.io.atomic import write_csv, write_json
from i2ris_calib.io.encoders import encoder_log_path, read_encoder_log
from i2ris_calib.io.outputs import claim_output_dir, output_dir, output_lock
from i2ris_calib.io.provenance import provenance
from i2ris_calib.io.session import SESSION_FILE, load_session
from i2ris_calib.sync.axes import axis_check
from i2ris_calib.sync.estimate import axis_series, check_overlap, estimate_clock, synced_table

SCHEMA = "i2ris-calib.sync/1"
CLOCK = "t_ctrl = offset_s + (1 + drift_ppm*1e-6) * t_cam"


#: The files ``sync`` writes in its output folder.
OUTPUTS = ("synced.csv", "sync.json")


def provenance_files(session: Path, log_path: Path, angles_path: Path) -> list[Path]:
    """Files whose hashes go into the provenance (a ROS2 bag folder: all its files)."""
    logs = (
        sorted(p for p in log_path.rglob("*") if p.is_file()) if log_path.is_dir() else [log_path]
    )
    return [session / SESSION_FILE, *logs, angles_path]


def sync_summary(clock, table: pd.DataFrame, n_dropped: int, log, t_cam: np.ndarray, cfg) -> dict:
    """The sync.json body (without provenance)."""
    t_ref = float(clock.evidence.get("t_ref_cam_s", 0.5 * (np.min(t_cam) + np.max(t_cam))))
    return {
        "schema": SCHEMA,
        "clock": CLOCK,
        "method": clock.method,
        "method_requested": cfg.sync.method,
        "offset_s": clock.offset_at(0.0),
        "drift_ppm": clock.drift_ppm,
        "offset_stderr_s": clock.offset_stderr_at(0.0),
        "drift_stderr_ppm": clock.drift_stderr_ppm,
        "t_ref_cam_s": t_ref,
        "offset_at_t_ref_s": clock.offset_at(t_ref),
        "offset_at_t_ref_stderr_s": clock.offset_stderr_at(t_ref),
        "n_rows": int(len(table)),
        "n_dropped_outside_log": n_dropped,
        "camera_time_range_s": [float(np.min(t_cam)), float(np.max(t_cam))],
        "log_time_range_s": list(log.time_range()),
        "time_origin_s": {"camera": clock.origin_cam_s, "controller": clock.origin_ctrl_s},
        "evidence": clock.evidence,
    }


def xcorr_comparison(angles: pd.DataFrame, log, sync_cfg) -> dict | None:
    """Plain cross-correlation result for comparison (None when it cannot run)."""
    if not axis_series(angles):
        return None
    try:
        c = estimate_clock(angles, log, replace(sync_cfg, method="xcorr"))
    except CalibError:
        return None
    return {"offset_s": c.offset_at(0.0), "drift_ppm": c.drift_ppm, "note": c.evidence["note"]}


def sync_session(
    session: str | Path, angles: str | Path | None, out: str | Path | None, cfg
) -> Path:
    """Synchronise one session; write ``OUT/synced.csv`` and ``OUT/sync.json``.

    Parameters
    ----------
    session : path
        Session folder (docs/session.md).
    angles : path, optional
        Tracked angles (default ``SESSION/track/angles.csv``).
    out : path, optional
        Output folder (default ``SESSION/sync``).
    cfg : PipelineConfig
        ``[sync]`` and ``[fit]`` sections are used.

    Returns
    -------
    Path
        The output folder.
    """
    root = Path(session)
    spec = load_session(root)
    angles_path = Path(angles) if angles is not None else root / "track" / "angles.csv"
    out_dir = Path(out) if out is not None else root / "sync"
    log_path = encoder_log_path(root, spec.encoder)
    inputs = provenance_files(root, log_path, angles_path)
    claim_output_dir(out_dir, "sync", [root, *inputs], OUTPUTS)
    with output_lock(out_dir, command="sync"):  # one sync at a time into ``out``
        log = read_encoder_log(root, spec.encoder, cfg.sync.max_gap_s)
        log = replace(log, interpolation=cfg.sync.encoder_interpolation)
        df = read_angles(angles_path)
        with Progress(
            SpinnerColumn(), TextColumn("{task.description}"), TimeElapsedColumn(), transient=True
        ) as bar:
            bar.add_task(
                f"sync {root.name}: estimating the clock (method {cfg.sync.method})", total=None
            )
            clock = estimate_clock(df, log, cfg.sync, cfg.fit)
            comparison = xcorr_comparison(df, log, cfg.sync) if clock.method != "xcorr" else None
        table, n_dropped = synced_table(df, clock, log)
        t_cam = df["time_s"].to_numpy(dtype=float)
        check_overlap(len(table), n_dropped, clock, log, t_cam, cfg.sync)
        summary = sync_summary(clock, table, n_dropped, log, t_cam, cfg)
        summary["n_backward_rejected"] = int(df.attrs.get("n_backward_rejected", 0))
        summary["axis_check"] = axis_check(table)
        summary["encoder_glitches"] = glitch_summary(log, table)
        summary["frames_outside_log"] = outside_log_summary(df, clock, log)
        summary["warnings"] = (
            axis_warnings(summary["axis_check"], root)
            + glitch_warnings(summary["encoder_glitches"], log_path)
            + outside_log_warnings(summary["frames_outside_log"], log_path)
        )
        for line in summary["warnings"]:
            typer.echo(f"warning: {line}", err=True)
        summary["xcorr_comparison"] = comparison
        summary["provenance"] = provenance(inputs, cfg)
        with output_dir(out_dir, "sync", [root, *inputs], OUTPUTS) as tmp:
            write_csv(tmp / "synced.csv", table, float_format="%.6f")
            write_json(tmp / "sync.json", summary)
        return out_dir


GLITCH_ACTION = (
    "replaced by linear interpolation between the nearest good samples (the series keeps "
    "every sample; the motor cannot have moved faster than the limit in between)"
)


def glitch_summary(log, table: pd.DataFrame) -> dict:
    """sync.json ``encoder_glitches``: per channel what the log reader replaced, and the
    synced frames interpolated from a replaced sample."""
    out: dict = {"action": GLITCH_ACTION, "n_samples": 0, "channels": {}}
    t = table["time_s"].to_numpy(dtype=float)
    for name, g in (log.meta.get("glitches") or {}).items():
        entry = dict(g)
        entry["n_frames_affected"] = 0
        if g["n_samples"]:
            ch = log.channels[name]
            bad = np.isin(ch.t_s, np.asarray(g["all_times_s"]))
            # a frame is affected when it is interpolated from a replaced sample
            k = np.clip(np.searchsorted(ch.t_s, t, side="right"), 1, ch.t_s.size - 1)
            entry["n_frames_affected"] = int(np.sum(bad[k - 1] | bad[k]))
        entry.pop("all_times_s", None)
        out["channels"][name] = entry
        out["n_samples"] += int(g["n_samples"])
    return out


def glitch_warnings(glitches: dict, log_path: Path) -> list[str]:
    """Terminal/sync.json warning per channel with encoder glitches."""
    lines = []
    for name, g in glitches["channels"].items():
        if g["n_samples"]:
            times = ", ".join(f"{x:.6f}" for x in g["first_times_s"][:3])
            lines.append(
                f"{g['n_samples']} encoder glitch sample(s) in {name} of {log_path} (faster than "
                f"{g['limit_counts_per_s']:.4g} counts/s and back; first at t = {times} s): "
                f"replaced by interpolation, {g['n_frames_affected']} frame(s) affected "
                "(set [encoder] max_counts_per_s if the limit is wrong)"
            )
    return lines


def outside_log_summary(angles: pd.DataFrame, clock, log) -> dict:
    """Frames whose controller time falls before the log starts or after it ends
    (left out of synced.csv at the ends of the recording, never extrapolated)."""
    t_cam = angles["time_s"].to_numpy(dtype=float)
    t = clock.to_ctrl(t_cam)
    lo, hi = log.time_range()
    before, after = t < lo, t > hi
    frames = angles["frame"].to_numpy()

    def part(mask):
        if not mask.any():
            return {"n": 0}
        k = np.flatnonzero(mask)
        return {
            "n": int(k.size),
            "frames": [int(frames[k[0]]), int(frames[k[-1]])],
            "camera_time_s": [float(t_cam[k[0]]), float(t_cam[k[-1]])],
        }

    return {"before_log_start": part(before), "after_log_end": part(after)}


def outside_log_warnings(outside: dict, log_path: Path) -> list[str]:
    """Warning when the log starts after the video or ends before it."""
    lines = []
    for key, what in (("before_log_start", "starts"), ("after_log_end", "ends")):
        p = outside[key]
        if p["n"]:
            a, b = p["camera_time_s"]
            lines.append(
                f"{p['n']} frame(s) (frames {p['frames'][0]}-{p['frames'][1]}, camera time "
                f"{a:.3f}-{b:.3f} s) fall outside the encoder log {log_path} (the video "
                f"{'starts before' if what == 'starts' else 'ends after'} it): not synced, left "
                "out of synced.csv (never extrapolated)"
            )
    return lines


def axis_warnings(check: dict, root: Path) -> list[str]:
    """Plain warning when an angle follows the other motor (sync.json and terminal)."""
    if not check["swapped_axes"]:
        return []
    rho = ", ".join(
        f"{a}_deg vs own motor {check[a]['own']}, other {check[a]['other']}"
        for a in check["swapped_axes"]
    )
    return [
        f"{', '.join(check['swapped_axes'])} follow(s) the other motor ({rho}; |step "
        f"correlation|): check [encoder] yaw_column/pitch_column and the cameras' view "
        f"labels in {root / SESSION_FILE}"
    ]


def with_method(cfg, method: str | None):
    """``cfg`` with ``[sync] method`` replaced (CLI ``--method``); CalibError if unknown."""
    if method is None:
        return cfg
    allowed = ("auto", "event", "model", "xcorr")
    if method not in allowed:
        raise CalibError(f"--method '{method}' is not one of {', '.join(allowed)}")
    return replace(cfg, sync=replace(cfg.sync, method=method))
