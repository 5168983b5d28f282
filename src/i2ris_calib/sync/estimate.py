"""Choose and run a sync method; build the synced table (one row per angle sample).

Entry points: :func:`estimate_clock` (angles table + encoder log -> ClockModel) and
:func:`synced_table` (apply a clock: controller times, interpolated encoders).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd

from i2ris_calib.errors import CalibError
from i2ris_calib.sync.axes import AXES
from i2ris_calib.sync.clock import ClockModel, clock_model
from i2ris_calib.sync.config import SyncConfig
from i2ris_calib.sync.events import clock_from_events
from i2ris_calib.sync.flash import CameraEdge, camera_edges
from i2ris_calib.sync.joint import clock_from_model
from i2ris_calib.sync.log import ENCODER_CHANNELS, EncoderLog
from i2ris_calib.sync.logedges import log_edges
from i2ris_calib.sync.xcorr import AxisSeries, clock_from_xcorr

ANGLE_COLUMNS = ("frame", "time_s", "yaw_deg", "pitch_deg", "status")
SYNCED_COLUMNS = (
    "time_s",
    "enc_yaw",
    "enc_pitch",
    "yaw_deg",
    "pitch_deg",
    "status",
    "frame",
    "time_cam_s",
)


def check_angles(angles: pd.DataFrame, where: str) -> pd.DataFrame:
    """The angles table sorted by time; CalibError on missing columns or a clock reset."""
    missing = [c for c in ANGLE_COLUMNS if c not in angles.columns]
    if missing:
        raise CalibError(
            f"{where}: missing column(s) {', '.join(missing)} (angles.csv is written by "
            "'i2ris-calib track'; see docs/formats.md)"
        )
    t = pd.to_numeric(angles["time_s"], errors="coerce").to_numpy(dtype=float)
    if not np.isfinite(t).all():
        raise CalibError(
            f"{where}: time_s has empty or non-numeric values (fix the tracking output)"
        )
    dt = np.diff(t)
    if (dt < 0).any():
        i = int(np.flatnonzero(dt < 0)[0])
        raise CalibError(
            f"{where}: camera time goes back from {t[i]:.6f} s to {t[i + 1]:.6f} s at row {i + 2} "
            "(camera clock reset: split the recording)"
        )
    return angles.reset_index(drop=True)


def axis_series(angles: pd.DataFrame) -> list[AxisSeries]:
    """Measured frames (status ``measured``, finite angle) of each axis."""
    return _series(angles, whole_history=False)


def frame_series(angles: pd.DataFrame) -> list[AxisSeries]:
    """Every frame of each axis in time order, angle NaN where not measured (``model``).

    The hysteresis model carries state, so the ``model`` method runs it over the whole
    frame history; unmeasured frames only leave the loss. An axis needs >= 8 measured
    frames.
    """
    return _series(angles, whole_history=True)


def _series(angles: pd.DataFrame, whole_history: bool) -> list[AxisSeries]:
    """Per axis with >= 8 measured frames: every frame (NaN angle where not measured)
    when ``whole_history``, else the measured frames only."""
    out = []
    measured = angles["status"].astype(str).to_numpy() == "measured"
    t = angles["time_s"].to_numpy(dtype=float)
    for axis, col, channel in AXES:
        th = pd.to_numeric(angles[col], errors="coerce").to_numpy(dtype=float)
        ok = measured & np.isfinite(th)
        if ok.sum() >= 8:
            if whole_history:
                out.append(AxisSeries(axis, channel, t, np.where(ok, th, np.nan)))
            else:
                out.append(AxisSeries(axis, channel, t[ok], th[ok]))
    return out


def flash_cameras(angles: pd.DataFrame, cfg: SyncConfig) -> list[str]:
    """Cameras with a ``mean_gray_<camera>`` column (restricted to ``cfg.flash_cameras``)."""
    cams = [c[len("mean_gray_") :] for c in angles.columns if c.startswith("mean_gray_")]
    if cfg.flash_cameras:
        unknown = [c for c in cfg.flash_cameras if c not in cams]
        if unknown:
            raise CalibError(
                f"sync.flash_cameras names {', '.join(unknown)} but angles.csv has mean_gray_ "
                f"columns for: {', '.join(cams) or 'none'} (fix sync.flash_cameras)"
            )
        cams = list(cfg.flash_cameras)
    return cams


def video_edges(angles: pd.DataFrame, cfg: SyncConfig) -> list[CameraEdge]:
    """LED edges seen in every flash camera; a camera's own frame times are taken from
    ``time_s_<camera>`` when angles.csv has that column, else from ``time_s``."""
    edges = []
    for cam in flash_cameras(angles, cfg):
        tcol = f"time_s_{cam}" if f"time_s_{cam}" in angles.columns else "time_s"
        t = pd.to_numeric(angles[tcol], errors="coerce").to_numpy(dtype=float)
        g = pd.to_numeric(angles[f"mean_gray_{cam}"], errors="coerce").to_numpy(dtype=float)
        edges += camera_edges(t, g, cam, cfg)
    return edges


def estimate_clock(
    angles: pd.DataFrame, log: EncoderLog, cfg: SyncConfig, fit_config=None
) -> ClockModel:
    """Camera -> controller clock by the configured method.

    ``auto`` uses the sync event when the log has ``sync_flash`` edges and the video
    shows the flash, else the joint hysteresis-model estimate (the reason is recorded
    in ``evidence["auto"]``). ``event`` and ``model`` insist on their method;
    ``xcorr`` is plain cross-correlation (comparison only: biased by hysteresis).

    Every method runs on recording-local times: the first camera time and the first
    log time are subtracted before any arithmetic and put back in the returned clock
    (``origin_cam_s``, ``origin_ctrl_s``) and its evidence. Results therefore do not
    depend on the clocks' epoch (ROS bags stamp ~1.7e9 s: in absolute seconds float64
    keeps only ~0.2 us and the offset/drift covariance is singular).

    Parameters
    ----------
    angles : DataFrame
        angles.csv (see :func:`check_angles`), camera clock, s.
    log : EncoderLog
        Controller clock, s.
    cfg : SyncConfig
        ``offset_guess_s`` is ``t_ctrl - t_cam`` on the absolute clocks.
    fit_config : FitConfig, optional
        For the ``model`` method.
    """
    c0, l0 = time_origins(angles, log)
    log = replace(log, interpolation=cfg.encoder_interpolation)
    try:
        local = _estimate_local(
            shift_angles(angles, c0),
            log.shifted(-l0),
            replace(cfg, offset_guess_s=cfg.offset_guess_s - (l0 - c0)),
            fit_config,
        )
    except CalibError as exc:
        if l0 == c0:
            raise
        raise CalibError(
            f"{exc} [clocks {l0 - c0:.6f} s apart: offsets named here are relative to that]"
        ) from None
    return replace(
        local,
        origin_cam_s=c0,
        origin_ctrl_s=l0,
        evidence=global_evidence(local.evidence, c0, l0),
    )


#: clocks whose first times differ by less than this share one origin (s: a day)
SHARED_ORIGIN_MAX_S = 1e5


def time_origins(angles: pd.DataFrame, log: EncoderLog) -> tuple[float, float]:
    """(camera origin, controller origin), s.

    The camera origin is the first frame time. Clocks on the same epoch (first log
    time within :data:`SHARED_ORIGIN_MAX_S` of it) share it, so local offsets
    ``t_ctrl - t_cam`` (and any message naming one) equal the absolute ones; clocks on
    different epochs (video from 0, log in ROS time) get the first log time.
    """
    cols = [c for c in angles.columns if c == "time_s" or c.startswith("time_s_")]
    t = np.concatenate([pd.to_numeric(angles[c], errors="coerce").to_numpy(float) for c in cols])
    c0 = float(np.nanmin(t)) if np.isfinite(t).any() else 0.0
    l_first = float(log.time_range()[0])
    return c0, (c0 if abs(l_first - c0) < SHARED_ORIGIN_MAX_S else l_first)


def shift_angles(angles: pd.DataFrame, shift_s: float) -> pd.DataFrame:
    """A copy of ``angles`` with every camera time column (time_s, time_s_<cam>) minus ``shift_s``."""
    out = angles.copy()
    for c in out.columns:
        if c == "time_s" or c.startswith("time_s_"):
            out[c] = pd.to_numeric(out[c], errors="coerce").to_numpy(float) - shift_s
    out.attrs = dict(angles.attrs)
    return out


#: evidence keys holding offsets (t_ctrl - t_cam), camera times and controller times
_OFFSET_KEYS = {
    "xcorr_offset_s",
    "prior_offset_at_t_ref_s",
    "offset_at_t_ref_s",
    "coarse_offset_s",
    "global_offset_s",
    "window_offsets_s",
}
_CAM_KEYS = {"t_ref_cam_s", "t_cam_s", "windows_t_cam_s", "span_cam_s"}
_CTRL_KEYS = {"t_ctrl_s"}


def global_evidence(ev, c0: float, l0: float):
    """Evidence of a clock estimated on local times, with times and offsets made absolute.

    Offsets gain ``l0 - c0``, camera times ``c0``, controller times ``l0``; an
    ``offset_s`` beside a ``drift_ppm`` (a clock at local camera time 0) becomes the
    documented offset at camera time 0.
    """
    if isinstance(ev, list):
        return [global_evidence(v, c0, l0) for v in ev]
    if not isinstance(ev, dict):
        return ev

    def add(v, a):
        if isinstance(v, np.ndarray):
            return v + a
        if isinstance(v, list):
            return [x + a for x in v]
        return v + a if isinstance(v, float | int) and not isinstance(v, bool) else v

    out = {}
    for k, v in ev.items():
        if k in _OFFSET_KEYS:
            out[k] = add(v, l0 - c0)
        elif k in _CAM_KEYS:
            out[k] = add(v, c0)
        elif k in _CTRL_KEYS:
            out[k] = add(v, l0)
        elif k == "offset_s" and "drift_ppm" in ev:
            out[k] = float((l0 - c0) + (v - ev["drift_ppm"] * 1e-6 * c0))
        else:
            out[k] = global_evidence(v, c0, l0)
    return out


def _estimate_local(
    angles: pd.DataFrame, log: EncoderLog, cfg: SyncConfig, fit_config=None
) -> ClockModel:
    """:func:`estimate_clock` on times already made recording-local."""
    method = cfg.method
    reason = ""
    if method in ("auto", "event"):
        lg = log_edges(log.flash, cfg.log_edge_at) if log.flash is not None else []
        cam = video_edges(angles, cfg)
        if lg and cam:
            t_frames = angles["time_s"].to_numpy(dtype=float)
            span = (float(np.nanmin(t_frames)), float(np.nanmax(t_frames)))
            event = clock_from_events(cam, lg, cfg, span)
            if method == "auto":
                return refined_event_clock(event, angles, log, cfg, fit_config)
            return event
        reason = (
            "the encoder log has no sync_flash column/topic"
            if log.flash is None
            else "no sync_flash edge in the encoder log"
            if not lg
            else "no flash visible in the video (mean_gray_<camera> columns)"
        )
        if method == "event":
            raise CalibError(
                f"sync.method = 'event' but {reason} (use sync.method = 'model' or 'auto')"
            )
    series = axis_series(angles)
    if not series:
        raise CalibError(
            "sync: no measured angles to synchronise with (every frame flagged by tracking?)"
        )
    if method == "xcorr":
        return clock_from_xcorr(series, log, cfg)
    clock = clock_from_model(frame_series(angles), log, cfg, fit_config)
    if reason:
        clock.evidence["auto"] = f"model method used: {reason}"
    return clock


#: ``auto``: the model's offset more than this many combined sd from the event's is a
#: disagreement, and the event is kept
DISAGREE_SD = 3.0


def largest_clock_sd(clock: ClockModel, t_cam_s: np.ndarray) -> float:
    """Largest sd (s) of the clock's controller time over camera times ``t_cam_s``.

    The variance of ``offset + drift t`` is quadratic in ``t``, so its largest value over
    the recording is at the first or the last frame; the middle is included for a clock
    without drift. An uncertain drift dominates at the ends: a sync event with a precise
    offset in the middle can still be a millisecond off there.
    """
    t = np.asarray(t_cam_s, dtype=float)
    ends = (float(np.min(t)), float(np.mean(t)), float(np.max(t)))
    return max(clock.offset_stderr_at(x) for x in ends)


def refined_event_clock(event: ClockModel, angles, log: EncoderLog, cfg: SyncConfig, fit_config):
    """``auto`` with a coarse sync event: combine it with the hysteresis model.

    When the event clock's standard error somewhere in the recording (the largest of
    its first frame, middle and last frame: an uncertain drift dominates at the ends)
    exceeds ``cfg.auto_refine_stderr_s`` and an axis moves, the model profile is searched
    within the event's +-4 standard errors and the two clocks are combined as
    evidence (:func:`combine_clocks`: the product of their Gaussian likelihoods in
    (offset at the model's reference time, drift); method ``event+model``, both
    inputs in ``evidence["event"]`` / ``evidence["combination"]``). The event clock
    is returned unchanged when the model cannot run, its minimum sits on the window's
    edge, its profile is too flat for a standard error, or the two disagree by more
    than :data:`DISAGREE_SD` combined sd: the combination is never less certain than
    the event, and a model that contradicts the event is not trusted over it.
    """
    series = axis_series(angles)
    t_cam = angles["time_s"].to_numpy(dtype=float)
    t_mid = float(np.mean(t_cam))
    sd = event.offset_stderr_at(t_mid)
    sd_any = largest_clock_sd(event, t_cam)
    if cfg.auto_refine_stderr_s <= 0 or not series or not sd_any > cfg.auto_refine_stderr_s:
        return event
    try:
        model = clock_from_model(frame_series(angles), log, cfg, fit_config, prior=event)
    except CalibError as exc:
        event.evidence["auto"] = f"event kept; model refinement failed: {exc}"
        return event
    t_c = float(model.evidence.get("t_ref_cam_s", t_mid))
    combined, info = combine_clocks(event, model, t_c)
    if combined is None:
        event.evidence["auto"] = f"event kept: {info['reason']}"
        event.evidence["combination"] = info
        return event
    combined.evidence["event"] = {
        "offset_s": event.offset_s,
        "drift_ppm": event.drift_ppm,
        "t_ref_cam_s": t_mid,
        "offset_at_t_ref_s": event.offset_at(t_mid),
        "offset_at_t_ref_stderr_s": sd,
        "drift_stderr_ppm": event.drift_stderr_ppm,
        "evidence": event.evidence,
    }
    combined.evidence["combination"] = info
    combined.evidence["auto"] = (
        f"sync event too coarse (clock sd up to {sd_any * 1e3:.2f} ms > auto_refine_stderr_s): "
        "combined with the hysteresis-model profile searched within its +-4 sd "
        "(product of the two likelihoods)"
    )
    return combined


def _gaussian_at(clock: ClockModel, t_c: float) -> tuple[np.ndarray, np.ndarray]:
    """Mean (offset at ``t_c``, drift) and precision matrix (2, 2) of a clock; a drift
    that was not fitted carries no information (zero precision)."""
    jac = np.array([[1.0, t_c * 1e-6], [0.0, 1.0]])
    cov = jac @ np.asarray(clock.cov, dtype=float) @ jac.T
    mean = np.array([clock.offset_at(t_c), clock.drift_ppm])
    if np.isfinite(clock.drift_stderr_ppm) and cov[1, 1] > 0:
        return mean, np.linalg.inv(cov)
    return mean, np.array([[1.0 / cov[0, 0], 0.0], [0.0, 0.0]])


def combine_clocks(
    event: ClockModel, model: ClockModel, t_c: float
) -> tuple[ClockModel | None, dict]:
    """Product of the event's and the model's clock likelihoods (Gaussian in offset at
    camera time ``t_c`` and drift), or None when they disagree.

    Returns
    -------
    clock : ClockModel or None
        The combined clock (method ``event+model``, the model's evidence), None when
        the model's offset sd is not finite or the offsets at ``t_c`` differ by more
        than :data:`DISAGREE_SD` times the sd of their difference.
    info : dict
        Both offsets at ``t_c`` with their sd, the z of their difference, the reason.
    """
    o_e, s_e = event.offset_at(t_c), event.offset_stderr_at(t_c)
    o_m, s_m = model.offset_at(t_c), model.offset_stderr_at(t_c)
    z = abs(o_m - o_e) / float(np.hypot(s_e, s_m)) if np.isfinite(s_m) else float("nan")
    info = {
        "t_ref_cam_s": t_c,
        "event_offset_at_t_ref_s": o_e,
        "event_offset_at_t_ref_stderr_s": s_e,
        "model_offset_at_t_ref_s": o_m,
        "model_offset_at_t_ref_stderr_s": s_m,
        "model_drift_ppm": model.drift_ppm,
        "model_drift_stderr_ppm": model.drift_stderr_ppm,
        "z": z,
    }
    if not (np.isfinite(s_m) and s_m > 0):
        info["reason"] = "the model profile has no usable curvature (no standard error)"
        return None, info
    if z > DISAGREE_SD:
        info["reason"] = (
            f"the model's offset is {z:.1f} combined sd from the event's (> {DISAGREE_SD:g})"
        )
        return None, info
    m_e, p_e = _gaussian_at(event, t_c)
    m_m, p_m = _gaussian_at(model, t_c)
    prec = p_e + p_m
    if prec[1, 1] > 0:
        cov_c = np.linalg.inv(prec)
        mean = cov_c @ (p_e @ m_e + p_m @ m_m)
        drift_fitted = True
    else:  # neither fitted the drift: offset only, drift held at 0
        cov_c = np.array([[1.0 / prec[0, 0], 0.0], [0.0, 0.0]])
        mean = np.array([cov_c[0, 0] * (p_e[0, 0] * m_e[0] + p_m[0, 0] * m_m[0]), 0.0])
        drift_fitted = False
    back = np.array([[1.0, -t_c * 1e-6], [0.0, 1.0]])
    cov = back @ cov_c @ back.T
    info["reason"] = "combined"
    clock = clock_model(
        mean[0] - mean[1] * 1e-6 * t_c, mean[1], cov, "event+model", dict(model.evidence),
        drift_fitted,
    )  # fmt: skip
    return clock, info


def synced_table(
    angles: pd.DataFrame, clock: ClockModel, log: EncoderLog
) -> tuple[pd.DataFrame, int]:
    """One row per angle sample on the controller clock, encoders interpolated there.

    Rows whose controller time falls outside the encoder log are dropped (returned
    count) rather than extrapolated.

    Returns
    -------
    table : DataFrame
        Columns :data:`SYNCED_COLUMNS`: time_s (controller clock, s), enc_yaw and
        enc_pitch (counts, :meth:`EncoderLog.interpolate`), yaw_deg, pitch_deg (deg, NaN when
        not measured), status, frame, time_cam_s (camera clock, s).
    n_dropped : int
    """
    t_cam = angles["time_s"].to_numpy(dtype=float)
    t_ctrl = clock.to_ctrl(t_cam)
    table = pd.DataFrame(
        {
            "time_s": t_ctrl,
            **{ch: log.interpolate(ch, t_ctrl) for ch in ENCODER_CHANNELS},
            "yaw_deg": pd.to_numeric(angles["yaw_deg"], errors="coerce"),
            "pitch_deg": pd.to_numeric(angles["pitch_deg"], errors="coerce"),
            "status": angles["status"].astype(str),
            "frame": angles["frame"],
            "time_cam_s": t_cam,
        }
    )
    inside = np.isfinite(table["enc_yaw"]) & np.isfinite(table["enc_pitch"])
    return table[inside].reset_index(drop=True), int((~inside).sum())


def check_overlap(n_rows: int, n_dropped: int, clock: ClockModel, log: EncoderLog, t_cam, cfg):
    """CalibError when fewer than ``cfg.min_overlap_frames`` frames fall inside the log."""
    if n_rows >= cfg.min_overlap_frames:
        return
    lo, hi = log.time_range()
    a, b = clock.to_ctrl(np.array([np.min(t_cam), np.max(t_cam)]))
    raise CalibError(
        f"sync: video and encoder log do not overlap: frames map to [{a:.3f}, {b:.3f}] s on the "
        f"controller clock, the log covers [{lo:.3f}, {hi:.3f}] s ({n_rows} frame(s) inside, "
        f"{n_dropped} outside; check that the log belongs to this recording)"
    )
