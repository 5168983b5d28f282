"""Tracking benchmark on a rendered session with known truth (issue 3 targets).

    python benchmarks/bench_tracking.py            # 2-minute 1280x1024 session (slow)
    python benchmarks/bench_tracking.py --quick    # ~25 s of the same scene
    python benchmarks/bench_tracking.py --format mp4 --keep /tmp/bench_mp4
    python benchmarks/bench_tracking.py --quick --keep /tmp/bq --decode   # + decode-only speed
    python benchmarks/bench_tracking.py --issue-session /tmp/issue11   # the issue's 60 s session

Scene (preset "benchmark"): 200 px markers, grey-level noise sigma 2, defocus blur,
3 deg camera misalignment, f = 50000 px (near-orthographic), three occlusions per
camera, sync flashes. Prints fused and plain (IPPE_SQUARE top solution, one camera,
no fusion) errors against the truth, detection figures, and speed per stream:
frames per second of wall time (two streams in parallel on a shared machine) and
per CPU-second of the stream's process (decoding + detection + edge refinement on
one core).

``--decode`` adds decode-only speed per input format (docs/video.md): the first
``--decode-frames`` frames of the top camera are written as FFV1 .mkv/.avi, MJPG .avi,
mp4v .mp4, an 8-bit PNG and a 16-bit TIFF sequence, then read back with
``io.video.iter_frames`` serially (``ahead=0``) and with the decode-ahead thread, with
FFmpeg's default decoder threads and with one; then one stream decoded AND detected,
serially and with the decode-ahead thread (interleaved, twice each). Figures: frames/s
of wall time and CPU ms per frame (all threads of this process; the machine may be shared, so wall
time alone says little).

Targets: RMS <= 0.03 deg, max <= 0.15 deg, zero flips (errors > 1 deg), >= 99 %
of frames with both markers visible measured, occluded frames flagged, no reported
angle off by > 1 deg, >= 100 frames/s per stream on one core.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
from issue_session import ensure_session, tracking_figures

from i2ris_calib.commands.simulate import build_session
from i2ris_calib.commands.track import track, track_session
from i2ris_calib.config import PipelineConfig
from i2ris_calib.io.session import load_session
from i2ris_calib.io.video import iter_frames, open_writer
from i2ris_calib.simulation.presets import preset_config
from i2ris_calib.tracking.config import TrackingConfig
from i2ris_calib.tracking.detect import MarkerDetector
from i2ris_calib.tracking.geometry import euler_zyx_deg


def evaluate(session: Path, angles: pd.DataFrame) -> dict:
    """Error and detection figures of ``angles`` against ``session/truth``."""
    truth = pd.read_csv(session / "truth" / "truth_frames.csv")
    m = angles.merge(truth, on="frame", suffixes=("", "_true"))
    ok = m["status"] == "measured"
    out = {}
    for axis in ("yaw", "pitch"):
        e = (m[f"{axis}_deg"] - m[f"{axis}_deg_true"])[ok]
        out[f"fused_{axis}_rms"] = float(np.sqrt(np.mean(e**2)))
        out[f"fused_{axis}_max"] = float(e.abs().max())
        out[f"fused_{axis}_over_1deg"] = int((e.abs() > 1).sum())
        for cam in ("top", "side"):
            ep = (m[f"{axis}_plain_{cam}_deg"] - m[f"{axis}_deg_true"]).dropna()
            out[f"plain_{cam}_{axis}_rms"] = float(np.sqrt(np.mean(ep**2)))
            out[f"plain_{cam}_{axis}_max"] = float(ep.abs().max())
            out[f"plain_{cam}_{axis}_over_1deg"] = int((ep.abs() > 1).sum())
    vis = (m["visible_top"] == 1) & (m["visible_side"] == 1)
    out["frames"] = len(m)
    out["visible_frames"] = int(vis.sum())
    out["measured_of_visible"] = float(ok[vis].mean())
    out["occluded_frames"] = int((~vis).sum())
    out["occluded_flagged"] = float((~ok[~vis]).mean()) if (~vis).any() else float("nan")
    out["status_counts"] = m["status"].value_counts().to_dict()
    return out


def decode_speed(video: Path, frames: int, out: Path) -> list[dict]:
    """Decode-only figures of ``frames`` frames of ``video`` re-encoded in each format."""

    imgs = []
    for img in iter_frames(video):
        imgs.append(img)
        if len(imgs) >= frames:
            break
    h, w = imgs[0].shape
    out.mkdir(parents=True, exist_ok=True)
    inputs = {}
    for name, suffix, codec in (("FFV1 .mkv", ".mkv", "FFV1"), ("FFV1 .avi", ".avi", "FFV1"),
                                ("MJPG .avi", ".avi", "MJPG"), ("mp4v .mp4", ".mp4", "mp4v")):  # fmt: skip
        path = out / f"{codec.lower()}{suffix}"
        wr = open_writer(path, 30.0, (w, h), codec=codec)
        for img in imgs:
            wr.write(img)
        wr.release()
        inputs[name] = path
    for name, suffix, shift in (("PNG 8-bit seq", ".png", 0), ("TIFF 16-bit seq", ".tif", 4)):
        d = out / f"seq{suffix[1:]}"
        d.mkdir(exist_ok=True)
        for k, img in enumerate(imgs):
            cv2.imwrite(
                str(d / f"frame_{k:06d}{suffix}"), img.astype(np.uint16) << shift if shift else img
            )
        inputs[name] = d
    rows = []
    for name, path in inputs.items():
        for ahead, threads in ((0, 0), (8, 0), (0, 1), (8, 1)):
            t0, c0 = time.perf_counter(), time.process_time()
            n = sum(1 for _ in iter_frames(path, ahead=ahead, threads=threads))
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            rows.append({"format": name, "ahead": ahead, "threads": threads or "default",
                         "frames": n, "fps_wall": n / wall, "cpu_ms": 1000 * cpu / n})  # fmt: skip
    return rows


#: Cross-axis cases (--cross-axis): (misalignment deg, pinhole focal px, seed) on the
#: preset "exact_ci" (320x256, 80 px markers, random excursions with compound moves).
CROSS_AXIS_CASES = ((0.5, 20000.0, 11), (2.0, 35000.0, 12), (5.0, 50000.0, 13))


def cross_axis_figures(session: Path, angles: pd.DataFrame) -> dict:
    """RMS per axis overall and while the other axis is beyond 15 deg, max, >1 deg, measured."""
    truth = pd.read_csv(session / "truth" / "truth_frames.csv")
    m = angles.merge(truth, on="frame", suffixes=("", "_true"))
    ok = m["status"] == "measured"
    vis = (m["visible_top"] == 1) & (m["visible_side"] == 1)
    out = {"measured": float(ok[vis].mean()), "frames": int(vis.sum())}
    for axis, other in (("yaw", "pitch"), ("pitch", "yaw")):
        e = (m[f"{axis}_deg"] - m[f"{axis}_deg_true"])[ok]
        big = m[f"{other}_deg_true"][ok].abs() > 15
        out[axis] = (float(np.sqrt(np.mean(e**2))), float(np.sqrt(np.mean(e[big] ** 2))),
                     float(e.abs().max()), int((e.abs() > 1).sum()), int(big.sum()))  # fmt: skip
    return out


def cross_axis(args) -> int:
    """The reference-roll leak (issue 11): rendered sessions with compound moves, three
    misalignments and focal lengths, each tracked with the pinhole and the
    weak-perspective camera model; ``--before`` adds the window-only reference.
    1 when a case with the session reference misses RMS <= 0.02 deg overall or
    <= 0.03 deg while the other axis is beyond 15 deg."""
    missed = []

    root = args.keep or Path(tempfile.mkdtemp(prefix="bench_cross_axis_"))
    print("case | model | reference | yaw RMS / beyond-15 / max | pitch RMS / beyond-15 / max"
          " | >1 deg | measured | roll correction +- sd (deg) | true roll error of the reference (deg)")  # fmt: skip
    for mis, f, seed in CROSS_AXIS_CASES:
        folder = root / f"mis{mis}_f{int(f)}_s{seed}"
        if not (folder / "session.toml").is_file():
            folder.mkdir(parents=True, exist_ok=True)
            cfg = preset_config("exact_ci", misalignment_deg=mis, focal_px=f, seed=seed)
            build_session(folder, cfg, name=folder.name)
        for model in ("pinhole", "weak_perspective"):
            spec = load_session(folder)
            cams = {k: dataclasses.replace(c, model=model) for k, c in spec.cameras.items()}
            spec = dataclasses.replace(spec, cameras=cams)
            for mode in ("window", "session") if args.before else ("session",):
                res = track(folder, spec, TrackingConfig(reference_roll=mode))
                fig = cross_axis_figures(folder, res["angles"])
                ref = res["summary"]["reference"]
                truth = json.loads((folder / "truth" / "truth.json").read_text())
                R_true = np.asarray(truth["cameras"]["top"]["R_cam_from_base"])
                M = np.asarray(ref["tip_to_top_camera"])
                roll_err = float(euler_zyx_deg(R_true.T @ M)[2])
                y, p = fig["yaw"], fig["pitch"]
                print(f"{mis} deg, f {f:.0f} | {model} | {mode} | "
                      f"{y[0]:.4f} / {y[1]:.4f} / {y[2]:.3f} | {p[0]:.4f} / {p[1]:.4f} / {p[2]:.3f}"
                      f" | {y[3] + p[3]} | {fig['measured']:.4f} of {fig['frames']} | "
                      f"{ref['roll_correction_deg']} +- {ref['roll_sd_deg']} | {roll_err:.4f}",
                      flush=True)  # fmt: skip
                if mode == "session" and not (
                    max(y[0], p[0]) <= 0.02 and np.nanmax([y[1], p[1]]) <= 0.03
                ):
                    missed.append(f"{mis} deg, f {f:.0f}, {model}")
    if args.keep is None:
        shutil.rmtree(root, ignore_errors=True)
    print("targets (RMS <= 0.02 overall, <= 0.03 beyond 15 deg): "
          + ("met" if not missed else "MISSED: " + "; ".join(missed)))  # fmt: skip
    return 1 if missed else 0


def issue_session(folder: Path, seed: int, sim: list[str] | None = None) -> int:
    """The issue's session (``issue_session.py``): render once, track (written to
    ``folder/track`` for ``bench_sync.py --issue-session``), print the issue's figures;
    1 when the targets over all frames are missed."""

    over = {}
    for item in sim or []:  # KEY=VALUE overrides of the issue's [simulate] settings
        key, value = item.split("=", 1)
        over[key] = json.loads(value)
    ensure_session(folder, seed, **over)
    t0 = time.perf_counter()
    track_session(folder, folder / "track", PipelineConfig())
    wall = time.perf_counter() - t0
    angles = pd.read_csv(folder / "track" / "angles.csv")
    summary = json.loads((folder / "track" / "track.json").read_text())
    fig = tracking_figures(folder, angles)
    print(f"issue session {folder} (seed {seed}): track {wall:.1f} s wall")
    print(f"frames measured: {fig['measured_visible']}/{fig['visible']} with both markers "
          f"visible ({fig['frames']} frames); status {summary['status_counts']}")  # fmt: skip
    print(
        "axis  | RMS overall | RMS other axis > 15 deg (n) | RMS otherwise | bias beyond | max | >1 deg"
    )
    for axis in ("yaw", "pitch"):
        a = fig[axis]
        print(f"{axis:5s} | {a['rms']:.4f} | {a['rms_beyond']:.4f} ({a['n_beyond']}) | "
              f"{a['rms_otherwise']:.4f} | {a['bias_beyond']:+.4f} | {a['max']:.3f} | "
              f"{a['over_1deg']}")  # fmt: skip
    ref = summary["reference"]
    print(f"reference roll: {ref.get('roll_method')}, correction {ref.get('roll_correction_deg')}"
          f" +- {ref.get('roll_sd_deg')} deg")  # fmt: skip
    for name, c in summary["cameras"].items():
        print(f"stream {name}: {c['frames']} frames, {c['frames_per_s']} frames/s wall, "
              f"{c['frames_per_cpu_s']} frames/CPU-s")  # fmt: skip
    fig2 = tracking_figures(folder, angles, skip_steps=True)
    print(f"the same without the {fig2['step_frames']} frames next to a step of the true angle "
          "(EGPI flag-point jumps inside a frame interval; the 5 ms late side camera is "
          "interpolated across them):")  # fmt: skip
    for axis in ("yaw", "pitch"):
        a = fig2[axis]
        print(f"{axis:5s} | {a['rms']:.4f} | {a['rms_beyond']:.4f} ({a['n_beyond']}) | "
              f"{a['rms_otherwise']:.4f} | {a['bias_beyond']:+.4f} | {a['max']:.3f} | "
              f"{a['over_1deg']}")  # fmt: skip
    code = 0
    for name, f in (("all frames", fig), ("away from truth steps", fig2)):
        met = all(f[a]["rms"] <= 0.02 and f[a]["rms_beyond"] <= 0.03 for a in ("yaw", "pitch"))
        met &= f["yaw"]["over_1deg"] + f["pitch"]["over_1deg"] == 0
        met &= fig["measured_visible"] >= 0.995 * fig["visible"]
        print(f"targets (RMS <= 0.02 overall, <= 0.03 beyond 15 deg, none > 1 deg, >= 99.5 % "
              f"measured), {name}: {'met' if met else 'MISSED'}")  # fmt: skip
        if name == "all frames" and not met:
            code = 1
    return code


def overlap_speed(video: Path, dictionary: str, marker_id: int, frames: int) -> list[dict]:
    """One stream, decode + marker detection: serial vs decode-ahead thread (1 FFmpeg thread)."""

    cv2.setNumThreads(1)
    rows = []
    for ahead in (0, 8, 0, 8):  # interleaved: the machine may be shared
        det = MarkerDetector(dictionary, marker_id, TrackingConfig())
        t0, c0, n = time.perf_counter(), time.process_time(), 0
        for img in iter_frames(video, ahead=ahead, threads=1):
            det.detect(img)
            n += 1
            if n >= frames:
                break
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        rows.append({"ahead": ahead, "frames": n, "fps_wall": n / wall, "cpu_ms": 1000 * cpu / n})
    return rows


def session_misses(fig: dict) -> list[str]:
    """The accuracy targets of the module doc that ``fig`` (:func:`evaluate`) misses:
    fused RMS <= 0.03 deg, max <= 0.15 deg, no error > 1 deg, >= 99 % of the frames
    with both markers visible measured, every occluded frame flagged (the speed target
    is printed, not judged: it depends on the machine)."""
    out = []
    for axis in ("yaw", "pitch"):
        if not fig[f"fused_{axis}_rms"] <= 0.03:
            out.append(f"{axis} RMS {fig[f'fused_{axis}_rms']:.4f} > 0.03 deg")
        if not fig[f"fused_{axis}_max"] <= 0.15:
            out.append(f"{axis} max {fig[f'fused_{axis}_max']:.4f} > 0.15 deg")
        if fig[f"fused_{axis}_over_1deg"]:
            out.append(f"{axis}: {fig[f'fused_{axis}_over_1deg']} frames > 1 deg")
    if not fig["measured_of_visible"] >= 0.99:
        out.append(f"measured {fig['measured_of_visible']:.4f} of visible < 0.99")
    if fig["occluded_frames"] and not fig["occluded_flagged"] >= 1.0:
        out.append(f"occluded flagged {fig['occluded_flagged']:.3f} < 1")
    return out


def main() -> int:
    """Run the benchmark; 1 when an accuracy target is missed."""
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--quick", action="store_true", help="~25 s session instead of 2 minutes")
    ap.add_argument(
        "--format", choices=("mkv", "mp4"), default="mkv", help="FFV1 lossless or mp4v lossy"
    )
    ap.add_argument("--keep", type=Path, help="keep (or reuse, if it exists) the session here")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument(
        "--subpix",
        action="store_true",
        help="also track with ArUco SUBPIX corners (no edge refinement) for comparison",
    )
    ap.add_argument("--decode", action="store_true", help="also decode-only speed per format")
    ap.add_argument("--decode-frames", type=int, default=200, help="frames for --decode")
    ap.add_argument("--no-track", action="store_true", help="skip tracking (with --decode)")
    ap.add_argument(
        "--cross-axis",
        action="store_true",
        help="reference-roll leak cases (issue 11) instead of the main session",
    )
    ap.add_argument(
        "--before", action="store_true", help="with --cross-axis: also the window-only reference"
    )
    ap.add_argument(
        "--issue-session",
        type=Path,
        metavar="DIR",
        help="the issue's 60 s session (benchmarks/issue_session.py), rendered into DIR once",
    )
    ap.add_argument(
        "--sim",
        action="append",
        metavar="KEY=VALUE",
        help="with --issue-session: override a [simulate] setting of the issue's session "
        "(JSON value, e.g. --sim exposure_s=0.01 --sim encoder_rate_hz=100)",
    )
    args = ap.parse_args()
    if args.cross_axis:
        return cross_axis(args)
    if args.issue_session:
        return issue_session(args.issue_session, args.seed, args.sim)

    over = dict(video_format=args.format, seed=args.seed)
    if args.quick:
        over.update(
            datasets=("yaw+", "pitch-"), cycles=1, cycle_fractions=(1.0,), ramp_s=4.0, occlusions=1
        )
    cfg = preset_config("benchmark", **over)
    folder = args.keep or Path(tempfile.mkdtemp(prefix="bench_tracking_"))
    t0 = time.perf_counter()
    if not (folder / "session.toml").is_file():
        folder.mkdir(parents=True, exist_ok=True)
        build_session(folder, cfg, name="bench", progress=True)
        render_s = time.perf_counter() - t0
    else:
        render_s = float("nan")
    if args.decode:
        print(f"decode-only, {args.decode_frames} frames of top camera, {os.cpu_count()} CPUs:")
        tmp = Path(tempfile.mkdtemp(prefix="bench_decode_"))
        rows = decode_speed(folder / f"top.{args.format}", args.decode_frames, tmp)
        shutil.rmtree(tmp, ignore_errors=True)
        for r in rows:
            print(f"  {r['format']:16s} ahead={r['ahead']} ffmpeg_threads={r['threads']!s:7s} "
                  f"{r['fps_wall']:7.1f} frames/s wall  {r['cpu_ms']:6.2f} CPU ms/frame")  # fmt: skip
        spec = load_session(folder)
        top = next(n for n, c in spec.cameras.items() if c.view == "top")
        print("one stream, decode + detection (1 FFmpeg thread), serial vs decode-ahead:")
        for r in overlap_speed(folder / spec.cameras[top].video, spec.marker.dictionary,
                               spec.cameras[top].marker_id, args.decode_frames):  # fmt: skip
            print(f"  ahead={r['ahead']} {r['fps_wall']:7.1f} frames/s wall  "
                  f"{r['cpu_ms']:6.2f} CPU ms/frame")  # fmt: skip
    if args.no_track:
        return 0
    t1 = time.perf_counter()
    res = track(folder, load_session(folder), TrackingConfig(), progress=True)
    track_s = time.perf_counter() - t1
    fig = evaluate(folder, res["angles"])
    s = res["summary"]
    print(
        f"session: {folder}  format={args.format}  frames={fig['frames']}  "
        f"render {render_s:.1f} s  track {track_s:.1f} s (wall, both streams + fusion)"
    )
    print(f"status counts: {fig['status_counts']}")
    for axis in ("yaw", "pitch"):
        print(
            f"{axis:5s} fused: RMS {fig[f'fused_{axis}_rms']:.4f} deg  max {fig[f'fused_{axis}_max']:.4f} deg  "
            f">1 deg: {fig[f'fused_{axis}_over_1deg']}"
        )
        for cam in ("top", "side"):
            print(
                f"{axis:5s} plain {cam:4s}: RMS {fig[f'plain_{cam}_{axis}_rms']:.3f} deg  "
                f"max {fig[f'plain_{cam}_{axis}_max']:.3f} deg  >1 deg: {fig[f'plain_{cam}_{axis}_over_1deg']}"
            )
    print(
        f"measured / frames with both markers visible: {fig['measured_of_visible']:.4f} "
        f"({fig['visible_frames']} visible); occluded/invisible frames flagged: "
        f"{fig['occluded_flagged']:.3f} of {fig['occluded_frames']}"
    )
    print(
        f"competing minima: {s['competing_minima_frames']}, resolved by continuity: {s['resolved_by_continuity']}"
    )
    for name, c in s["cameras"].items():
        print(
            f"stream {name}: {c['frames']} frames, {c['frames_per_s']} frames/s wall, "
            f"{c['frames_per_cpu_s']} frames/CPU-s ({1000 * c['cpu_seconds'] / c['frames']:.1f} CPU ms/frame, "
            f"decode thread included), ROI hits {c['roi_hits']}, "
            f"edge-refined {c['edge_refined']}"
        )
    if args.subpix:
        res2 = track(folder, load_session(folder), TrackingConfig(corner_refinement="subpix"))
        f2 = evaluate(folder, res2["angles"])
        print("with ArUco SUBPIX corners instead of edge corners:")
        for axis, cam in (("yaw", "top"), ("pitch", "side")):
            print(
                f"  {axis:5s} fused: RMS {f2[f'fused_{axis}_rms']:.4f} max {f2[f'fused_{axis}_max']:.4f} "
                f">1 deg: {f2[f'fused_{axis}_over_1deg']} | plain {cam} (the in-plane camera): "
                f"RMS {f2[f'plain_{cam}_{axis}_rms']:.3f} max {f2[f'plain_{cam}_{axis}_max']:.3f}"
            )
            other = "side" if cam == "top" else "top"
            print(
                f"  {axis:5s} plain {other} (out-of-plane camera): RMS {f2[f'plain_{other}_{axis}_rms']:.3f} "
                f"max {f2[f'plain_{other}_{axis}_max']:.3f} >1 deg: {f2[f'plain_{other}_{axis}_over_1deg']}"
            )
    if args.keep is None:
        shutil.rmtree(folder, ignore_errors=True)
    missed = session_misses(fig)
    print("targets (RMS <= 0.03 deg, max <= 0.15 deg, none > 1 deg, >= 99 % measured, "
          "occluded flagged): " + ("met" if not missed else "MISSED: " + "; ".join(missed)))  # fmt: skip
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main())
