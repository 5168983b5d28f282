"""One-line judgements of the tracking and clock stages, from parsed stage outputs.

Each function returns :class:`~i2ris_calib.report.document.Verdict` lines a reader
can act on: ``ok`` (nothing to do), ``warn`` (look at it before using the numbers),
``info`` (what was done). Thresholds are stated in the text.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from i2ris_calib.report.clock import ClockView
from i2ris_calib.report.document import Verdict
from i2ris_calib.report.tables import fmt_pm, fmt_sig

CLOCK_ANGLE_OK_DEG = 0.05
"""A clock whose 2-sd error moves the angle by less than this at the 95th-percentile
angular speed is judged negligible (tracking noise is ~0.01 deg, model errors 0.1-1 deg)."""
EDGE_Z_OK = 3.0
"""Flash edges farther than this many sd from the clock are flagged."""
DETECTION_OK = 0.95
"""Share of measured frames below which the tracking verdict asks for a look."""
ROLL_SD_OK_DEG = 0.05
"""Reference-roll uncertainty above which the session roll fit is not trusted (docs/tracking.md)."""


def _ms(x_s: float) -> str:
    return f"{fmt_sig(x_s * 1e3, 2, pad=True)} ms"


def clock_verdicts(
    view: ClockView, sync: Mapping[str, Any], rate_deg_s: float = float("nan")
) -> list[Verdict]:
    """Method and why, stated error (and the angle error it can cause), flash edges,
    event vs model, axis check, log coverage and encoder glitches.

    Parameters
    ----------
    view : ClockView
        The clock derived from ``sync``.
    sync : mapping
        Parsed sync.json.
    rate_deg_s : float
        95th percentile of the angular speed (deg/s), NaN when unknown.
    """
    out = [Verdict(f"Clock from '{view.method}' (asked: {view.requested}): {view.why}.", "info")]
    out.append(_stated_error_verdict(view, rate_deg_s))
    if view.edges:
        out.append(_flash_edge_verdict(view))
    if math.isfinite(view.z):
        agree = abs(view.z) <= 3
        out.append(
            Verdict(
                "Event and hysteresis-model clocks "
                + (
                    f"agree (differ by {fmt_sig(view.z, 2)} combined sd)."
                    if agree
                    else f"disagree by {fmt_sig(view.z, 2)} combined sd: the event was kept."
                ),
                "ok" if agree else "warn",
            )
        )
    out += _axis_verdict(sync.get("axis_check"))
    out.append(_coverage_verdict(sync))
    return out


def _stated_error_verdict(view: ClockView, rate_deg_s: float) -> Verdict:
    """The stated clock error (ms, 1 and 2 sd) at worst and in the middle and, when the
    95th-percentile angular speed ``rate_deg_s`` (deg/s) is known, the angle error it can
    cause (deg) against :data:`CLOCK_ANGLE_OK_DEG`."""
    worst, t_worst = view.worst_sd()
    mid = view.clock.offset_ref_sd_s
    if not math.isfinite(worst):
        return Verdict("sync.json states no standard error for the clock.", "warn")
    text = (
        f"Stated clock error at most {_ms(worst)} (1 sd; {_ms(2 * worst)} at 2 sd) anywhere "
        f"in the recording (largest at t_cam = {fmt_sig(t_worst, 3)} s), {_ms(mid)} in the "
        "middle"
    )
    status = "info"
    if math.isfinite(rate_deg_s):
        effect = 2 * worst * rate_deg_s
        ok = effect <= CLOCK_ANGLE_OK_DEG
        text += (
            f"; at the 95th-percentile angular speed ({fmt_sig(rate_deg_s, 2)} deg/s) that "
            f"moves a sample by up to {fmt_sig(effect, 2)} deg at 2 sd, "
            + (
                f"negligible (< {CLOCK_ANGLE_OK_DEG} deg)"
                if ok
                else f"above {CLOCK_ANGLE_OK_DEG} deg: clock error shows in the fits"
            )
        )
        status = "ok" if ok else "warn"
    return Verdict(text + ".", status)


def _flash_edge_verdict(view: ClockView) -> Verdict:
    """Matched flash edges: rms residual (ms), largest residual in sd, and how many lie
    beyond :data:`EDGE_Z_OK` sd of the clock."""
    z = np.array([abs(e.residual_s) / e.sd_s if e.sd_s > 0 else np.inf for e in view.edges])
    rms = float(np.sqrt(np.mean([e.residual_s**2 for e in view.edges])))
    far = int((z > EDGE_Z_OK).sum())
    seen = f" of {view.n_camera_edges} seen in the video" if view.n_camera_edges else ""
    text = (
        f"{len(view.edges)} flash edges matched{seen}; residuals rms {_ms(rms)}, largest "
        f"{fmt_sig(float(np.max(z)), 2)} sd"
    )
    if far:
        return Verdict(f"{text}: {far} beyond {EDGE_Z_OK:g} sd of the clock.", "warn")
    return Verdict(f"{text}: all within {EDGE_Z_OK:g} sd of the clock.", "ok")


def _axis_verdict(check: Any) -> list[Verdict]:
    if not isinstance(check, Mapping):
        return []
    parts = []
    for axis, rec in check.items():
        if isinstance(rec, Mapping) and "own" in rec:
            parts.append(
                f"{axis} {fmt_sig(rec.get('own'), 2)} own vs {fmt_sig(rec.get('other'), 2)} other"
            )
    swapped = check.get("swapped_axes") or []
    if swapped:
        return [
            Verdict(
                f"Angle follows the other motor for {', '.join(map(str, swapped))} ({'; '.join(parts)}): "
                "swapped [encoder] columns or camera views.",
                "warn",
            )
        ]
    if not parts:
        return []
    return [
        Verdict(f"Each angle follows its own motor (|step correlation| {'; '.join(parts)}).", "ok")
    ]


def _coverage_verdict(sync: Mapping[str, Any]) -> Verdict:
    dropped = int(sync.get("n_dropped_outside_log") or 0)
    glitches = sync.get("encoder_glitches")
    n_glitch = int(glitches.get("n_samples") or 0) if isinstance(glitches, Mapping) else 0
    n_rows = sync.get("n_rows")
    rows = f"{n_rows} frames synced" if n_rows is not None else "Frames synced"
    if not dropped and not n_glitch:
        return Verdict(f"{rows}; every frame inside the encoder log; no encoder glitches.", "ok")
    parts = []
    if dropped:
        parts.append(f"{dropped} frames outside the encoder log left out (start or end)")
    if n_glitch:
        parts.append(f"{n_glitch} encoder glitch samples replaced by interpolation")
    return Verdict(f"{rows}; {'; '.join(parts)}.", "warn")


def angle_noise_deg(time_s: np.ndarray, angle_deg: np.ndarray) -> float:
    """Frame-to-frame angle noise (deg): robust sd of second differences over three
    consecutive measured frames, divided by sqrt(6) (white noise; the motion's own
    curvature over 2 frames is small at video rates). NaN with too few frames."""
    a = np.asarray(angle_deg, dtype=float)
    d2 = a[2:] - 2 * a[1:-1] + a[:-2]
    d2 = d2[np.isfinite(d2)]
    if d2.size < 10:
        return float("nan")
    mad = float(np.median(np.abs(d2 - np.median(d2))))
    return 1.4826 * mad / math.sqrt(6.0)


def longest_unmeasured(angles: pd.DataFrame) -> tuple[float, float]:
    """(duration s, start time s) of the longest run of consecutive frames not measured."""
    a = angles.sort_values("time_s", kind="stable")
    t = a["time_s"].to_numpy(dtype=float)
    bad = a["status"].astype(str).to_numpy() != "measured"
    best = (0.0, float("nan"))
    if not bad.any():
        return best
    edges = np.flatnonzero(np.diff(np.r_[0, bad.astype(np.int8), 0]))
    dt = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    for a0, b0 in zip(edges[::2], edges[1::2], strict=True):
        dur = float(t[b0 - 1] - t[a0]) + dt
        if dur > best[0]:
            best = (dur, float(t[a0]))
    return best


def tracking_verdicts(
    angles: pd.DataFrame | None, track: Mapping[str, Any] | None
) -> list[Verdict]:
    """Detection, reference roll, lagged camera and view checks, tracker warnings."""
    out: list[Verdict] = []
    if angles is not None and len(angles):
        out.append(_detection_verdict(angles))
    if not isinstance(track, Mapping):
        return out
    out += _roll_verdict(track.get("reference"))
    out += _lagged_verdict(track)
    out += _view_verdict(track.get("view_check"))
    warnings = track.get("warnings") or []
    if warnings:
        out.append(Verdict(f"{len(warnings)} tracker warning(s), listed in the overview.", "warn"))
    return out


def _detection_verdict(angles: pd.DataFrame) -> Verdict:
    """The share of frames measured, the flags of the others and the longest stretch
    without a measurement (angles.csv's ``status``)."""
    status = angles["status"].astype(str)
    share = float((status == "measured").mean())
    dur, start = longest_unmeasured(angles)
    flagged = {s: int(c) for s, c in status[status != "measured"].value_counts().items()}
    what = ", ".join(f"{c} {s}" for s, c in flagged.items()) or "none flagged"
    gap = (
        f"; longest stretch without a measurement {fmt_sig(dur, 2, pad=True)} s from t = "
        f"{fmt_sig(start, 3)} s"
        if dur > 0
        else ""
    )
    return Verdict(
        f"{100 * share:.1f} % of {len(status)} frames measured ({what}){gap}.",
        "ok" if share >= DETECTION_OK else "warn",
    )


def _roll_verdict(ref) -> list[Verdict]:
    """The reference roll correction of track.json's ``reference`` and its uncertainty."""
    if not (isinstance(ref, Mapping) and ref.get("roll_correction_deg") is not None):
        return []
    sd = ref.get("roll_sd_deg")
    ok = sd is not None and float(sd) <= ROLL_SD_OK_DEG
    return [
        Verdict(
            f"Reference roll corrected by {fmt_pm(ref.get('roll_correction_deg'), sd)} deg "
            f"({ref.get('roll_method', '?')} fit over {ref.get('fit_frames', '?')} frames)"
            + ("." if ok else f": uncertainty above {ROLL_SD_OK_DEG} deg, check the roll."),
            "ok" if ok else "warn",
        )
    ]


def _view_verdict(view) -> list[Verdict]:
    """The camera-view check of track.json's ``view_check`` (views as labelled or swapped)."""
    if not (isinstance(view, Mapping) and view.get("verdict")):
        return []
    spread = view.get("rigid_rig_spread_mm") or {}
    ok = str(view.get("verdict")) == "consistent"
    return [
        Verdict(
            f"Camera views: {view.get('verdict')} (rigid-rig spread "
            f"{fmt_sig(spread.get('as_labelled'), 2)} mm as labelled vs "
            f"{fmt_sig(spread.get('swapped'), 2)} mm swapped, {view.get('frames', '?')} frames).",
            "ok" if ok else "warn",
        )
    ]


def _lagged_verdict(track: Mapping[str, Any]) -> list[Verdict]:
    spread = track.get("lagged_camera_spread_deg")
    if not isinstance(spread, Mapping) and "lagged_camera_flagged_frames" not in track:
        return []
    refit = len(track.get("lagged_camera_refit_frames") or [])
    flagged = len(track.get("lagged_camera_flagged_frames") or [])
    spread = spread if isinstance(spread, Mapping) else {}
    if spread.get("median") is None and not refit and not flagged:
        return [
            Verdict(
                "Cameras triggered together: no interpolation in time between them, "
                "no lagged-camera frames.",
                "ok",
            )
        ]
    tol = spread.get("tolerance")
    text = (
        f"Lagged camera: timing uncertainty of the interpolated view median "
        f"{fmt_sig(spread.get('median'), 2)} deg, 99th percentile {fmt_sig(spread.get('p99'), 2)} "
        f"deg (tolerance {fmt_sig(tol, 2)} deg); {refit} frames refitted one-sided, "
        f"{flagged} flagged ambiguous."
    )
    p99 = spread.get("p99")
    ok = p99 is not None and tol is not None and float(p99) <= float(tol)
    return [Verdict(text, "ok" if ok else "warn")]
