"""``i2ris-calib track``: both videos -> per-frame pitch/yaw with status (docs/tracking.md).

Each camera stream is decoded and detected in its own process (OpenCV releases the
GIL too, but processes also parallelise the Python glue); the fusion then runs on
the corner arrays. Outputs: ``angles.csv`` and ``track.json`` in ``--out`` (default
``SESSION/track``), written atomically.
"""

from __future__ import annotations

import multiprocessing as mp
import time
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import typer
from rich.progress import Progress

from i2ris_calib.errors import CalibError
from i2ris_calib.io.atomic import write_csv, write_json
from i2ris_calib.io.camera_yaml import read_camera_yaml
from i2ris_calib.io.outputs import claim_output_dir, output_dir, output_lock
from i2ris_calib.io.provenance import provenance
from i2ris_calib.io.session import check_cameras, load_session, session_file
from i2ris_calib.io.timestamps import read_timestamps
from i2ris_calib.io.video import header_frame_count, input_files, iter_frames
from i2ris_calib.io.workers import quiet_pool
from i2ris_calib.session import CameraSpec, SessionSpec
from i2ris_calib.tracking import fuse as fz
from i2ris_calib.tracking.config import TrackingConfig
from i2ris_calib.tracking.detect import MarkerDetector, aruco_dictionary, touches_border
from i2ris_calib.tracking.geometry import face_corner_points_tip
from i2ris_calib.tracking.pose import (
    CameraIntrinsics,
    ippe_candidates,
    tip_pose_from_marker,
    weak_perspective_intrinsics,
)
from i2ris_calib.tracking.reference_window import WindowMotion, reference_window_motion
from i2ris_calib.tracking.timing import (
    LAGGED_SPREAD_DEG,
    REFIT_MIN_PX,
    adopt_lagged_alternatives,
    interp_weight,
    lagged_check,
    nearest_frame_gray,
    nearest_time,
    one_sided_corners,
    refit_lagged_frames,
    resample_corners,
)

#: The files ``track`` writes in its output folder.
OUTPUTS = ("angles.csv", "track.json")


@dataclass
class StreamResult:
    """Raw per-frame detections of one camera (arrays over decoded frames)."""

    corners: np.ndarray  # (n, 4, 2) px as detected (distorted), NaN if not found
    mean_gray: np.ndarray  # (n,)
    border: np.ndarray  # (n,) bool: marker touches the image border
    other_ids: dict  # id -> count of frames where it was seen instead
    shape: tuple[int, int]
    roi_hits: int
    edge_refined: int
    seconds: float
    cpu_seconds: float


def track_session(session: Path, out: Path | None, config) -> Path:
    """Track a session folder and write angles.csv + track.json; returns the out folder.

    ``out`` (default ``SESSION/track``) is checked before any work (io/outputs.py).
    """
    session = Path(session)
    spec = load_session(session)
    cfg: TrackingConfig = config.track
    out = Path(out) if out is not None else session / "track"
    inputs = [session / "session.toml"] + [  # an image-sequence video: each of its images
        f
        for n, c in spec.cameras.items()
        for f in input_files(session_file(session, c.video, f"video of camera '{n}'"))
    ]
    inputs += [
        session_file(session, c.timestamps, f"timestamps of camera '{n}'")
        for n, c in spec.cameras.items()
    ]
    claim_output_dir(out, "track", [session, *inputs], OUTPUTS)
    with output_lock(out, command="track"):  # one track at a time into ``out``
        result = track(session, spec, cfg, progress=True)
        summary = {**result["summary"], "provenance": provenance(inputs, cfg)}
        for line in track_warnings(summary):
            typer.echo(f"warning: {line}", err=True)
        with output_dir(out, "track", [session, *inputs], OUTPUTS) as tmp:
            write_csv(tmp / "angles.csv", result["angles"], "%.6f")
            write_json(tmp / "track.json", summary)
        return out


def track_warnings(summary: dict) -> list[str]:
    """Plain warnings for the terminal (also kept in track.json under ``warnings``)."""
    out = []
    for name, cam in summary["cameras"].items():
        g = cam.get("gaps", {})
        if g.get("count"):
            out.append(
                f"camera '{name}' dropped about {g['missing_frames']} frame(s) in {g['count']} "
                f"gap(s), longest {g['longest_s']:.3f} s (frames inside gaps over "
                "max_interp_gap_s are not_found, never interpolated)"
            )
        if g.get("backward_frames"):
            out.append(
                f"camera '{name}': {g['backward_frames']} frame(s) have a timestamp that goes "
                f"backwards (first: frame {g['first_backward_frame']}) and were rejected (status "
                "rejected, no angles; sync leaves them out); check the camera clock export"
            )
    motion = summary.get("reference", {}).get("window_motion") or {}
    if motion.get("moving"):
        lo, hi = motion["window_s"]
        out.append(
            f"the tip moves within the reference window {lo:g}-{hi:g} s (yaw "
            f"{motion['yaw_deg']:.2f}, pitch {motion['pitch_deg']:.2f} deg): every angle is "
            "relative to a pose it did not hold, and a bent reference mixes the axes; set "
            "[track] reference_start_s and reference_duration_s to a hold at the straight pose "
            "(docs/tracking.md)"
        )
    if summary.get("view_check", {}).get("verdict") == "inconclusive":
        out.append(
            "the top/side view labels could not be verified (the tip turned too little); "
            "check that yaw follows the yaw motor"
        )
    summary["warnings"] = out
    return out


def track(session: Path, spec: SessionSpec, cfg: TrackingConfig, progress: bool = False) -> dict:
    """Run detection and fusion; returns ``{"angles": DataFrame, "summary": dict}``."""
    names = list(spec.cameras)
    if len(names) != 2:
        raise CalibError(
            f"{session / 'session.toml'}: tracking needs exactly two cameras, found {len(names)} "
            "([cameras.<name>] tables, see docs/session.md)"
        )
    cams: dict[str, CameraSpec] = spec.cameras
    views = [cams[n].view for n in names]
    if sorted(views) != ["side", "top"]:
        raise CalibError(
            f'{session / "session.toml"}: the cameras need view = "top" and "side" (got {views})'
        )
    check_cameras(session, spec)  # one video, timestamp file or marker id for both: refused
    times = {
        n: read_timestamps(session_file(session, cams[n].timestamps, f"timestamps of camera '{n}'"))
        for n in names
    }
    videos = {n: session_file(session, cams[n].video, f"video of camera '{n}'") for n in names}
    for n in names:  # every input that can be checked is checked before decoding
        check_calibration(session, n, cams[n])
    streams = run_streams(videos, spec, cfg, progress)
    for n in names:
        check_stream(n, videos[n], times[n], streams[n], cams[n], spec)
    intr = {n: intrinsics(session, cams[n], streams[n].shape, cfg) for n in names}
    result = fuse_session(names, cams, times, streams, intr, spec, cfg)
    check = result["summary"]["view_check"]
    if check["verdict"] == "swapped":
        top = next(n for n in names if cams[n].view == "top")
        side = next(n for n in names if cams[n].view == "side")
        spread = check["rigid_rig_spread_mm"]
        raise CalibError(
            f"{session / 'session.toml'}: the view labels look swapped: camera '{top}' "
            f'(view = "top") sees the side face and camera \'{side}\' (view = "side") the '
            "top face (the cube centre seen by both cameras moves "
            f"{spread['as_labelled']:.3f} mm as labelled, {spread['swapped']:.4f} mm swapped; "
            f'yaw and pitch would come out exchanged): set view = "side" in [cameras.{top}] '
            f'and view = "top" in [cameras.{side}]'
        )
    return result


# ----------------------------------------------------------------------------- inputs
def check_calibration(session: Path, name: str, cam: CameraSpec) -> None:
    """A pinhole camera's calibration file exists and parses (before any decoding)."""
    if cam.model != "pinhole":
        return
    if not cam.calibration:
        raise CalibError(
            f'{session / "session.toml"} [cameras.{name}]: model = "pinhole" but no '
            'calibration file (set calibration = "<camera>.yaml" or use model = "weak_perspective")'
        )
    read_camera_yaml(session_file(session, cam.calibration, f"calibration of camera '{name}'"))


def intrinsics(
    session: Path, cam: CameraSpec, shape: tuple[int, int], cfg: TrackingConfig
) -> CameraIntrinsics:
    """Camera model of one camera: pinhole from its calibration file, or weak perspective."""
    h, w = shape
    if cam.model == "weak_perspective":
        return weak_perspective_intrinsics(w, h, cfg.weak_perspective_focal_px)
    if not cam.calibration:
        raise CalibError(
            f"{session / 'session.toml'}: camera with video '{cam.video}' has model = \"pinhole\" but no "
            'calibration file (set calibration = "<camera>.yaml" or use model = "weak_perspective")'
        )
    K, dist, cw, ch = read_camera_yaml(session_file(session, cam.calibration, "calibration"))
    if cw and ch and (cw, ch) != (w, h):
        raise CalibError(
            f"{cam.calibration}: calibrated for {cw}x{ch} but the video '{cam.video}' is {w}x{h} "
            "(recalibrate at the recording resolution)"
        )
    return CameraIntrinsics(K, dist, w, h, "pinhole")


# ----------------------------------------------------------------------------- streams
_COUNTER = None


def _init_worker(counter) -> None:
    global _COUNTER
    _COUNTER = counter


def detect_stream(
    video: Path,
    dictionary: str,
    marker_id: int,
    cfg: TrackingConfig,
    margin_ratio: float | None = None,
) -> StreamResult:
    """Decode one video and detect its marker in every frame (runs in a worker)."""
    cv2.setNumThreads(1)
    det = MarkerDetector(dictionary, marker_id, cfg, margin_ratio)
    corners, gray, border, others = [], [], [], {}
    shape, roi_hits, edge_refined, t0 = (0, 0), 0, 0, time.perf_counter()
    c0 = time.process_time()
    for k, img in enumerate(iter_frames(video)):
        shape = img.shape[:2]
        d = det.detect(img)
        gray.append(cv2.mean(img)[0])
        for i in d.other_ids:
            others[i] = others.get(i, 0) + 1
        if d.corners is None:
            corners.append(np.full((4, 2), np.nan))
            border.append(False)
        else:
            corners.append(d.corners)
            border.append(touches_border(d.corners, shape))
            roi_hits += d.used_roi
            edge_refined += d.edge_refined
        if _COUNTER is not None and k % 20 == 19:
            with _COUNTER.get_lock():
                _COUNTER.value += 20
    return StreamResult(np.array(corners).reshape(-1, 4, 2), np.array(gray), np.array(border, bool), others,
                        shape, roi_hits, edge_refined, time.perf_counter() - t0,
                        time.process_time() - c0)  # fmt: skip


def run_streams(videos: dict, spec: SessionSpec, cfg: TrackingConfig, progress: bool) -> dict:
    """Detect in every camera stream, in parallel processes when ``cfg.workers > 1``."""
    aruco_dictionary(spec.marker.dictionary)  # fail early on a bad name
    total = sum(max(header_frame_count(v), 1) for v in videos.values())
    margin = (spec.marker.cube_size_mm - spec.marker.marker_size_mm) / (
        2 * spec.marker.marker_size_mm
    )
    jobs = {
        n: (v, spec.marker.dictionary, spec.cameras[n].marker_id, cfg, margin)
        for n, v in videos.items()
    }
    if cfg.workers <= 1:
        return {n: detect_stream(*a) for n, a in jobs.items()}
    ctx = mp.get_context("spawn")  # fork can deadlock on inherited OpenCV threads
    counter = ctx.Value("l", 0)
    work = [(detect_stream, *a) for a in jobs.values()]
    with quiet_pool(min(cfg.workers, len(jobs)), ctx, work, _init_worker, (counter,)) as futs:
        with Progress(disable=not progress, transient=True) as bar:
            task = bar.add_task("tracking markers", total=total)
            while not all(f.done() for f in futs):
                bar.update(task, completed=counter.value)
                time.sleep(0.2)
        return {n: f.result() for n, f in zip(jobs, futs, strict=True)}


def check_stream(
    name: str, video: Path, ts: pd.DataFrame, s: StreamResult, cam: CameraSpec, spec: SessionSpec
) -> None:
    """One-line errors for a truncated video, a wrong id or dictionary."""
    n = len(s.corners)
    if n != len(ts):
        raise CalibError(
            f"{video.name}: {n} decodable frames but {len(ts)} rows in {cam.timestamps} "
            "(truncated/corrupt video or wrong timestamp file; they must match one row per frame)"
        )
    if not np.isfinite(s.corners).any():
        others = {c.marker_id: other for other, c in spec.cameras.items() if other != name}
        most = max(sorted(s.other_ids), key=s.other_ids.get, default=None)
        if most in others:  # setting marker_id = most would track one face twice
            other = others[most]
            raise CalibError(
                f"{video.name}: marker id {cam.marker_id} of camera '{name}' never found, but "
                f"id {most} of camera '{other}' was: [cameras.{name}] video '{cam.video}' "
                f"films the {other} camera's face (a copy of its video, or the two cameras' "
                f"videos are swapped); set video and timestamps of [cameras.{name}] in "
                f"session.toml to the files the {name} camera recorded (or, if it is the "
                "marker ids that are swapped, swap the two marker_id values)"
            )
        if s.other_ids:
            seen = ", ".join(str(i) for i in sorted(s.other_ids))
            raise CalibError(
                f"{video.name}: marker id {cam.marker_id} never found, but ids {seen} of "
                f"{spec.marker.dictionary} were (set marker_id of camera '{name}' in session.toml)"
            )
        raise CalibError(
            f"{video.name}: no {spec.marker.dictionary} marker found in any frame "
            "(wrong dictionary in session.toml [marker], or the marker is not in view)"
        )


# ----------------------------------------------------------------------------- fusion
def _view(
    corners_raw: np.ndarray, intr: CameraIntrinsics, view: str, spec: SessionSpec
) -> fz.ViewData:
    """Undistorted corners and IPPE candidates of one camera at the fused frames."""
    c = intr.undistort(corners_raw)
    n = len(c)
    R = np.full((n, 2, 3, 3), np.nan)
    t = np.full((n, 2, 3), np.nan)
    for k in np.flatnonzero(np.isfinite(c).all(axis=(1, 2))):
        Rm, tm, _ = ippe_candidates(c[k], intr.K, spec.marker.marker_size_mm)
        for j in range(2):
            R[k, j], t[k, j] = tip_pose_from_marker(view, Rm[j], tm[j], spec.marker.cube_size_mm)
    X = face_corner_points_tip(view, spec.marker.marker_size_mm, spec.marker.cube_size_mm)
    return fz.ViewData(c, intr.K, X, R, t)


def fuse_session(names, cams, times, streams, intr, spec: SessionSpec, cfg: TrackingConfig) -> dict:
    """Fused angles table and summary from the per-camera detections."""
    a_name, b_name = names if cams[names[0]].view == "top" else names[::-1]
    ta = times[a_name]
    tb = times[b_name]
    t = ta["time_s"].to_numpy()
    ca = _usable(streams[a_name], ta)
    cb_src = _usable(streams[b_name], tb)
    keep_b = tb["valid"].to_numpy()
    cb = resample_corners(tb["time_s"].to_numpy()[keep_b], cb_src[keep_b], t, cfg)
    va = _view(ca, intr[a_name], cams[a_name].view, spec)
    vb = _view(cb, intr[b_name], cams[b_name].view, spec)
    if not (va.ok & vb.ok).any():
        raise CalibError("no frame time where both markers are measured: cannot fuse the two views")
    res = fz.fuse_views(va, vb, t, cfg)
    views = view_check(res, ca, cb, intr[a_name], intr[b_name], t, spec, cfg)
    status = res.status.copy()
    status[~ta["valid"].to_numpy()] = fz.REJECTED
    ref = reference_mask(t, cfg)
    refit, res_ref = _session_reference(replace(res, status=status), va, vb, ref, t, cfg)
    fused = np.isin(res.status, (fz.MEASURED, fz.REJECTED)) & ta["valid"].to_numpy()
    second = _SecondCamera(
        tb["time_s"].to_numpy()[keep_b], cb_src[keep_b], intr[b_name], cams[b_name].view
    )
    lag = _lagged_camera_fit(res_ref, status, va, second, fused, t, refit.M, spec, cfg)
    res, status, M = lag.res, lag.status, refit.M
    ang = fz.relative_angles(res.Q, M)
    ang[status != fz.MEASURED] = np.nan
    df = _angles_table(ta, tb, (a_name, b_name), (va, vb), streams, res, status, ang, ref, cfg)
    summary = _summary(df, res, streams, names, M, ref, cfg)
    summary["reference"].update(reference_record(refit))
    summary["reference"]["window_motion"] = window_motion_record(
        reference_window_motion(t, ang[:, 0], ang[:, 1], ref), cfg
    )
    summary.update(_lagged_record(lag, ta["frame"].to_numpy()))
    for n in names:
        summary["cameras"][n]["gaps"] = frame_gaps(times[n], cfg)
    summary["view_check"] = views
    return {"angles": df, "summary": summary}


def _angles_table(ta, tb, names, views, streams, res, status, ang, ref, cfg) -> pd.DataFrame:
    """angles.csv's table on the first camera's frames (docs/formats.md): fused angles
    (deg) and status, reprojection error, each camera's mean grey level (and the second
    camera's own frame time when it differs), which camera found its marker, and with
    ``cfg.plain`` each view's own angles."""
    (a_name, b_name), (va, vb) = names, views
    t = ta["time_s"].to_numpy()
    df = pd.DataFrame({"frame": ta["frame"].to_numpy(), "time_s": t, "yaw_deg": ang[:, 0],
                       "pitch_deg": ang[:, 1], "status": status, "reproj_err_px": res.rms_px,
                       "roll_deg": ang[:, 2]})  # fmt: skip
    df[f"mean_gray_{a_name}"] = streams[a_name].mean_gray
    gray_b, time_b = nearest_frame_gray(tb["time_s"].to_numpy(), streams[b_name].mean_gray, t, cfg)
    df[f"mean_gray_{b_name}"] = gray_b
    if np.nanmax(np.abs(time_b - t), initial=0.0) > cfg.same_frame_tol_s:
        df[f"time_s_{b_name}"] = time_b  # the grey level's own frame time (sync flash edges)
    df[f"found_{a_name}"] = va.ok.astype(int)
    df[f"found_{b_name}"] = vb.ok.astype(int)
    if cfg.plain:
        for name, v in ((a_name, va), (b_name, vb)):
            pa = plain_angles(v, ref)
            df[f"yaw_plain_{name}_deg"] = pa[:, 0]
            df[f"pitch_plain_{name}_deg"] = pa[:, 1]
    return df


def _session_reference(res: fz.FusionResult, va, vb, ref: np.ndarray, t: np.ndarray, cfg):
    """:func:`~i2ris_calib.tracking.fuse.fit_reference`'s ``(ReferenceFit, FusionResult)``;
    a CalibError saying how to move the reference window when it has no measured frame."""
    try:
        return fz.fit_reference(res, va, vb, ref, t, cfg)
    except ValueError:
        raise CalibError(
            f"no measured frame in the reference window ({cfg.reference_start_s}-"
            f"{cfg.reference_start_s + cfg.reference_duration_s} s after the first frame); move "
            "[track] reference_start_s to a time where the tip is straight and both markers are visible"
        ) from None


@dataclass(frozen=True)
class _SecondCamera:
    """The second camera's usable detections at its own frame times."""

    time_s: np.ndarray  # (m,)
    corners: np.ndarray  # (m, 4, 2) px as detected
    intr: CameraIntrinsics
    view: str


@dataclass(frozen=True)
class _LaggedFit:
    """The fusion after the frames of a second camera not triggered with the first were
    refitted, checked and flagged (:func:`~i2ris_calib.tracking.timing.lagged_check`);
    frame lists are indices into the fused frames, all empty when the cameras are
    triggered together."""

    res: fz.FusionResult
    status: np.ndarray  # (n,) final status, the flagged frames ambiguous
    refit_frames: np.ndarray
    one_side_frames: np.ndarray
    flagged_frames: np.ndarray
    spread_deg: np.ndarray  # (n,) NaN where not checked


def _one_sided_views(
    b: _SecondCamera, frames: np.ndarray, t: np.ndarray, spec: SessionSpec, cfg
) -> list[fz.ViewData]:
    """The second camera's views at ``frames`` (mask or indices into ``t``) from its
    corners extrapolated from the frames before and from the frames after."""
    alts = []
    for side in ("before", "after"):
        c_alt = np.full((len(t), 4, 2), np.nan)
        c_alt[frames] = one_sided_corners(b.time_s, b.corners, t[frames], side, cfg)
        alts.append(_view(c_alt, b.intr, b.view, spec))
    return alts


def _lagged_camera_fit(
    res: fz.FusionResult, status: np.ndarray, va: fz.ViewData, b: _SecondCamera,
    fused: np.ndarray, t: np.ndarray, M: np.ndarray, spec: SessionSpec, cfg: TrackingConfig,
) -> _LaggedFit:  # fmt: skip
    """:class:`_LaggedFit` of the fusion ``res`` (``status``: its status with the invalid
    first-camera frames rejected)."""
    none = np.zeros(0, dtype=int)
    lagged = np.nanmax(np.abs(nearest_time(b.time_s, t) - t), initial=0.0)
    if not (lagged > cfg.same_frame_tol_s and res.t_a is not None and res.t_b is not None):
        return _LaggedFit(res, status, none, none, none, np.full(len(t), np.nan))
    sel = fused & (np.nan_to_num(res.rms_px) > REFIT_MIN_PX)  # every candidate is here
    res, refit_frames = refit_lagged_frames(
        res, va, _one_sided_views(b, sel, t, spec, cfg), fused, cfg
    )
    status = res.status.copy()
    check = np.flatnonzero(status == fz.MEASURED)
    check = np.setdiff1d(check, refit_frames)  # refitted: chosen by the first camera
    alts = _one_sided_views(b, check, t, spec, cfg)
    lag = lagged_check(res, va, alts, interp_weight(b.time_s, t), M, check, cfg)
    res, adopted = adopt_lagged_alternatives(res, lag)
    flagged = np.flatnonzero(np.nan_to_num(lag.spread_deg) > LAGGED_SPREAD_DEG)
    status[flagged] = fz.AMBIGUOUS
    return _LaggedFit(res, status, refit_frames, adopted, flagged, lag.spread_deg)


def _lagged_record(lag: _LaggedFit, frame: np.ndarray) -> dict:
    """The ``lagged_camera_*`` entries of track.json (``frame``: the fused frames' numbers)."""
    spread = lag.spread_deg
    return {
        "lagged_camera_refit_frames": [int(k) for k in frame[lag.refit_frames]],
        "lagged_camera_one_side_frames": [int(k) for k in frame[lag.one_side_frames]],
        "lagged_camera_flagged_frames": [int(k) for k in frame[lag.flagged_frames]],
        "lagged_camera_spread_deg": {
            "median": _num(np.nanmedian(spread)) if np.isfinite(spread).any() else None,
            "p99": _num(np.nanpercentile(spread, 99)) if np.isfinite(spread).any() else None,
            "tolerance": LAGGED_SPREAD_DEG,
        },
    }


def view_check(
    res: fz.FusionResult, ca, cb, intr_a, intr_b, t: np.ndarray, spec: SessionSpec, cfg
) -> dict:
    """Do the ``view`` labels fit the geometry? Compares both labellings (docs/tracking.md).

    Under (near-)orthographic projection a swapped top/side pair is fitted just as
    well (a mirror image of the true motion: yaw and pitch exchanged, sign-flipped),
    but the cube centre that both cameras see then moves along their common sideways
    axis by up to the cube size (:func:`~i2ris_calib.tracking.fuse.common_axis_positions`).
    The swapped labelling is fused on up to 400 measured frames and both spreads are
    compared. Returns the ``view_check`` record of track.json; ``verdict`` is
    ``consistent``, ``swapped`` (refused by :func:`track`) or ``inconclusive``.
    """
    ok = np.flatnonzero(res.status == fz.MEASURED)
    sub = ok[np.linspace(0, ok.size - 1, min(400, ok.size)).astype(int)] if ok.size else ok
    given = fz.rigid_rig_spread_mm(res)
    swapped = float("nan")
    if sub.size >= 10:
        va = _view(ca[sub], intr_a, "side", spec)
        vb = _view(cb[sub], intr_b, "top", spec)
        try:
            alt = fz.fuse_views(va, vb, t[sub], cfg)
            swapped = fz.rigid_rig_spread_mm(alt)
        except ValueError:
            pass
    verdict = fz.view_verdict(given, swapped, spec.marker.cube_size_mm)
    return {"rigid_rig_spread_mm": {"as_labelled": _num(given), "swapped": _num(swapped)},
            "frames": int(sub.size), "verdict": verdict}  # fmt: skip


def _num(x: float):
    return round(float(x), 6) if np.isfinite(x) else None


def frame_gaps(ts: pd.DataFrame, cfg: TrackingConfig) -> dict:
    """Dropped frames of one camera, from its time steps (``gaps`` in track.json).

    Frames whose timestamp goes backwards (``valid`` false, :func:`read_timestamps`)
    are counted apart (``backward_frames``, ``first_backward_frame``): they are in the
    video, so the hole they leave among the valid times is no dropped frame. Frames
    were dropped where the frame slots a stretch of time spans (in median frame
    intervals) outnumber the video's rows in it, for good: a stretch around rejected
    rows is taken as a whole (a late time and the rows after it that look backwards
    cancel), and an excess that later comes back is jitter. ``count`` gaps hold
    ``missing_frames`` such frames. Gaps longer than ``max_interp_gap_s`` in the side
    camera (``over_max_interp_gap``, whatever their cause) leave the top frames inside
    them ``not_found`` (never interpolated).
    """
    valid = ts["valid"].to_numpy()
    back = ts["frame"].to_numpy()[~valid]
    backward = {
        "backward_frames": int(back.size),
        "first_backward_frame": int(back[0]) if back.size else None,
    }
    rows = np.flatnonzero(valid)
    t = ts["time_s"].to_numpy()[valid]
    dt = np.diff(t)
    if dt.size == 0:
        return {"count": 0, "missing_frames": 0, "longest_s": 0.0, "over_max_interp_gap": 0,
                **backward}  # fmt: skip
    step = float(np.median(dt))
    holey = np.diff(rows) > 1  # rejected rows between two valid ones
    joined = holey.copy()  # such a step and its neighbours are taken as one stretch
    joined[1:] |= holey[:-1]
    joined[:-1] |= holey[1:]
    inside = np.zeros(rows.size, bool)
    inside[1:-1] = joined[:-1] & joined[1:]
    ends = np.flatnonzero(~inside)  # valid rows that bound the stretches
    lost = np.round(np.diff(t[ends]) / step) - np.diff(rows[ends])  # slots minus rows
    total = np.concatenate([[0.0], np.cumsum(lost)])
    for_good = np.minimum.accumulate(total[::-1])[::-1]  # an excess that comes back: jitter
    dropped = np.diff(for_good)
    gap = dropped > 0
    longest = np.maximum.reduceat(dt, ends[:-1])  # the longest time step of each stretch
    return {
        "count": int(gap.sum()),
        "missing_frames": int(dropped[gap].sum()),
        "longest_s": round(float(longest[gap].max()), 6) if gap.any() else 0.0,
        "over_max_interp_gap": int(np.sum(dt > cfg.max_interp_gap_s)),
        "frame_interval_s": round(step, 6),
        **backward,
    }


def _usable(s: StreamResult, ts: pd.DataFrame) -> np.ndarray:
    """Detected corners with border-touching markers and out-of-order frames removed."""
    c = s.corners.copy()
    c[s.border] = np.nan
    c[~ts["valid"].to_numpy()] = np.nan
    return c


def reference_record(refit: fz.ReferenceFit) -> dict:
    """How the reference roll was set (the ``reference`` record of track.json)."""
    return {"roll_method": refit.method, "roll_correction_deg": _num(refit.roll_correction_deg),
            "roll_sd_deg": _num(refit.roll_sd_deg),
            "camera_rotation_change_deg": _num(refit.camera_rotation_change_deg),
            "fit_frames": refit.frames, "window_measured_frames": refit.window_frames}  # fmt: skip


def window_motion_record(m: WindowMotion, cfg: TrackingConfig) -> dict:
    """The tip's motion within the reference window (track.json ``reference.window_motion``,
    deg; :func:`~i2ris_calib.tracking.reference_window.reference_window_motion`)."""
    return {
        "window_s": [cfg.reference_start_s, cfg.reference_start_s + cfg.reference_duration_s],
        "yaw_deg": _num(m.yaw_deg), "pitch_deg": _num(m.pitch_deg),
        "noise_sd_deg": _num(m.noise_sd_deg), "threshold_deg": _num(m.threshold_deg),
        "frames": m.frames, "moving": m.moving,
    }  # fmt: skip


def reference_mask(t: np.ndarray, cfg: TrackingConfig) -> np.ndarray:
    """Frames inside the reference window (relative to the first frame), shape (n,)."""
    rel = t - t[0]
    return (rel >= cfg.reference_start_s) & (
        rel <= cfg.reference_start_s + cfg.reference_duration_s
    )


def plain_angles(v: fz.ViewData, ref: np.ndarray) -> np.ndarray:
    """Single-camera angles from the top-ranked IPPE solution, no fusion (comparison)."""
    Q = v.R_ct[:, 0]
    ok = np.isfinite(Q).all(axis=(1, 2))
    out = np.full((len(Q), 3), np.nan)
    if not (ok & ref).any():
        return out
    M = fz.reference_rotation(Q, ref & ok)
    out[ok] = fz.relative_angles(Q[ok], M)
    return out


def _summary(df: pd.DataFrame, res: fz.FusionResult, streams: dict, names, M, ref, cfg) -> dict:
    counts = df["status"].value_counts().to_dict()
    n = len(df)
    rms = df.loc[df["status"] == fz.MEASURED, "reproj_err_px"]
    per_cam = {
        n_: {"frames": len(s.corners), "found": int(np.isfinite(s.corners).all(axis=(1, 2)).sum()),
             "touching_border": int(s.border.sum()), "roi_hits": int(s.roi_hits),
             "edge_refined": int(s.edge_refined),
             "other_ids_seen": {str(k): v for k, v in s.other_ids.items()},
             "seconds": round(s.seconds, 3),
             "frames_per_s": round(len(s.corners) / max(s.seconds, 1e-9), 1),
             "cpu_seconds": round(s.cpu_seconds, 3),
             "frames_per_cpu_s": round(len(s.corners) / max(s.cpu_seconds, 1e-9), 1)}
        for n_, s in streams.items()
    }  # fmt: skip
    return {
        "schema": "i2ris-calib.track/1",
        "frames": n,
        "status_counts": {k: int(counts.get(k, 0)) for k in (fz.MEASURED, fz.NOT_FOUND, fz.AMBIGUOUS, fz.REJECTED)},
        "detection_rate": float((df["status"] == fz.MEASURED).mean()) if n else 0.0,
        "reproj_err_px": {"median": float(rms.median()) if len(rms) else None,
                          "p95": float(rms.quantile(0.95)) if len(rms) else None,
                          "max": float(rms.max()) if len(rms) else None},
        "competing_minima_frames": res.n_competing,
        "resolved_by_continuity": res.n_by_continuity,
        "camera_rotation_b_from_a": res.R_ba,
        "reference": {"frames": int(ref.sum()), "tip_to_top_camera": M},
        "cameras": per_cam,
        "conventions": "docs/tracking.md: R_BT = Rz(yaw) Ry(pitch) Rx(roll) relative to the reference pose",
    }  # fmt: skip
