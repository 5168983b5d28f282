"""What the report shows of the clock synchronisation, derived from a parsed sync.json.

sync.json (docs/sync.md, "Outputs") states the clock ``t_ctrl = offset_s + (1 +
drift_ppm 1e-6) t_cam`` with three standard errors: of ``offset_s`` (at camera time
0), of ``offset_at_t_ref_s`` (at ``t_ref_cam_s``, the middle of the data) and of
``drift_ppm``. The three fix the (offset, drift) covariance, so the stated error of
the clock at every camera time follows (:func:`clock_sd`). Everything here is pure
computation on the parsed JSON; nothing is read from disk.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

PPM = 1e-6


def _num(x: Any) -> float:
    """``x`` as float, NaN when missing or not a number."""
    try:
        return float(x)
    except (TypeError, ValueError):
        return float("nan")


@dataclass(frozen=True)
class ClockLine:
    """One clock as offset ``t_ctrl - t_cam`` = ``offset_ref_s + drift_ppm 1e-6 (t - t_ref_s)``.

    Attributes
    ----------
    label : str
        ``"stated"``, ``"event alone"``, ``"model alone"``.
    t_ref_s : float
        Camera time (s) where ``offset_ref_s`` holds.
    offset_ref_s, offset_ref_sd_s : float
        Offset there (s) and its standard error (s, NaN when not stated).
    drift_ppm, drift_sd_ppm : float
        Drift (ppm) and its standard error (NaN when not fitted).
    cov_s_ppm : float
        Covariance of (offset at ``t_ref_s``, drift) in s x ppm (0 when unknown).
    """

    label: str
    t_ref_s: float
    offset_ref_s: float
    offset_ref_sd_s: float
    drift_ppm: float
    drift_sd_ppm: float = float("nan")
    cov_s_ppm: float = 0.0

    def offset(self, t_cam_s: np.ndarray) -> np.ndarray:
        """Offset ``t_ctrl - t_cam`` (s) at camera times ``t_cam_s`` (s)."""
        dt = np.asarray(t_cam_s, dtype=float) - self.t_ref_s
        return self.offset_ref_s + self.drift_ppm * PPM * dt

    def sd(self, t_cam_s: np.ndarray) -> np.ndarray:
        """Stated standard error (s) of :meth:`offset` at camera times ``t_cam_s``.

        ``var = var_ref + 2 dt cov + dt^2 var_drift`` (``dt = t - t_ref``); a drift
        without a standard error (held, not fitted) adds nothing.
        """
        dt = np.asarray(t_cam_s, dtype=float) - self.t_ref_s
        vd = (self.drift_sd_ppm * PPM) ** 2 if math.isfinite(self.drift_sd_ppm) else 0.0
        var = self.offset_ref_sd_s**2 + 2 * dt * self.cov_s_ppm * PPM + dt**2 * vd
        return np.sqrt(np.maximum(var, 0.0))


def stated_clock(sync: Mapping[str, Any]) -> ClockLine | None:
    """The clock sync.json states, with its covariance recovered; None without an offset.

    The covariance of (offset at ``t_ref``, drift) is solved from the offset's stderr at
    camera time 0 (``offset_stderr_s``): ``var0 = var_ref - 2 t_ref c + t_ref^2 var_d``;
    it is clipped to a valid correlation (|rho| <= 1) and 0 when not recoverable.
    """
    off0, drift = _num(sync.get("offset_s")), _num(sync.get("drift_ppm"))
    if not math.isfinite(off0):
        return None
    drift = drift if math.isfinite(drift) else 0.0
    t_ref = _num(sync.get("t_ref_cam_s"))
    off_ref = _num(sync.get("offset_at_t_ref_s"))
    sd_ref = _num(sync.get("offset_at_t_ref_stderr_s"))
    sd0 = _num(sync.get("offset_stderr_s"))
    sd_d = _num(sync.get("drift_stderr_ppm"))
    if not (math.isfinite(t_ref) and math.isfinite(off_ref)):
        t_ref, off_ref, sd_ref = 0.0, off0, sd0
    if not math.isfinite(sd_ref):
        sd_ref = sd0 if t_ref == 0.0 else float("nan")
    cov = 0.0
    vd = (sd_d * PPM) ** 2 if math.isfinite(sd_d) else 0.0
    if t_ref != 0.0 and math.isfinite(sd0) and math.isfinite(sd_ref) and vd > 0:
        c = (sd_ref**2 + t_ref**2 * vd - sd0**2) / (2 * t_ref)  # s^2 per (s/s)
        bound = sd_ref * math.sqrt(vd)
        cov = float(np.clip(c, -bound, bound)) / PPM
    return ClockLine("stated", t_ref, off_ref, sd_ref, drift, sd_d, cov)


def _line(label: str, rec: Mapping[str, Any], prefix: str = "") -> ClockLine | None:
    t_ref = _num(rec.get("t_ref_cam_s"))
    off = _num(rec.get(f"{prefix}offset_at_t_ref_s"))
    if not (math.isfinite(t_ref) and math.isfinite(off)):
        return None
    drift = _num(rec.get(f"{prefix}drift_ppm"))
    return ClockLine(
        label,
        t_ref,
        off,
        _num(rec.get(f"{prefix}offset_at_t_ref_stderr_s")),
        drift if math.isfinite(drift) else 0.0,
        _num(rec.get(f"{prefix}drift_stderr_ppm")),
    )


@dataclass(frozen=True)
class Edge:
    """One matched flash edge: camera and log times and their residual from the clock.

    ``residual_s = t_ctrl_s - (t_cam_s + offset(t_cam_s))`` of the stated clock, with
    ``sd_s`` combining both times' standard errors.
    """

    camera: str
    kind: str
    t_cam_s: float
    residual_s: float
    sd_s: float


@dataclass(frozen=True)
class ClockView:
    """Everything the clock section draws and tabulates.

    Attributes
    ----------
    method, requested, why : str
        Method used, method asked for, and the reason recorded in ``evidence.auto``
        (or a sentence derived from the method).
    clock : ClockLine
        The stated clock.
    t_range_s : (float, float)
        First and last camera time of the recording (s).
    others : list of ClockLine
        The event's and the model's clocks alone when ``auto`` combined them.
    edges : list of Edge
        Matched flash edges (event methods), empty otherwise.
    n_camera_edges, n_log_edges : int or None
        Edges seen in the video / in the log (event methods).
    z : float
        Event-vs-model difference in combined sd (NaN when not combined).
    profile : (ndarray, ndarray) or None
        The model method's offset profile: offset at ``t_ref`` (s), residual sum of
        squares (deg^2).
    """

    method: str
    requested: str
    why: str
    clock: ClockLine
    t_range_s: tuple[float, float]
    others: list[ClockLine] = field(default_factory=list)
    edges: list[Edge] = field(default_factory=list)
    n_camera_edges: int | None = None
    n_log_edges: int | None = None
    z: float = float("nan")
    profile: tuple[np.ndarray, np.ndarray] | None = None

    def worst_sd(self) -> tuple[float, float]:
        """(largest stated clock sd over the recording (s), camera time where it is).

        The variance is a parabola in time, so its largest value over the recording is
        at one of its ends."""
        t = np.array(self.t_range_s, dtype=float)
        sd = self.clock.sd(t)
        if not np.isfinite(sd).any():
            return float("nan"), float("nan")
        i = int(np.nanargmax(sd))
        return float(sd[i]), float(t[i])


METHOD_WHY = {
    "event": "LED flash edges seen in the video and logged as sync_flash",
    "model": "no usable sync flash: offset from the hysteresis model's fit of each axis",
    "event+model": "a coarse flash event combined with the hysteresis-model profile",
    "xcorr": "plain cross-correlation (biased by hysteresis; comparison only)",
}


def clock_view(sync: Mapping[str, Any]) -> ClockView | None:
    """The :class:`ClockView` of a parsed sync.json; None when it states no clock."""
    clock = stated_clock(sync)
    if clock is None:
        return None
    ev = _mapping(sync.get("evidence")) or {}
    method = str(sync.get("method", "?"))
    requested = str(sync.get("method_requested", method))
    comb, event = _mapping(ev.get("combination")), _mapping(ev.get("event"))
    event_ev = _mapping(event.get("evidence")) if event is not None else None
    event_ev = ev if event_ev is None else event_ev
    n_cam, n_log = event_ev.get("n_camera_edges"), event_ev.get("n_log_edges")
    return ClockView(
        method=method,
        requested=requested,
        why=_method_why(ev, method, requested),
        clock=clock,
        t_range_s=_camera_range(sync, clock),
        others=_other_estimates(event, comb),
        edges=_edges(event_ev, clock),
        n_camera_edges=int(n_cam) if isinstance(n_cam, (int, float)) else None,
        n_log_edges=int(n_log) if isinstance(n_log, (int, float)) else None,
        z=_num(comb.get("z")) if comb is not None else float("nan"),
        profile=_profile(ev.get("profile")),
    )


def _mapping(x) -> Mapping[str, Any] | None:
    """``x`` when it is a mapping (a JSON object), else None."""
    return x if isinstance(x, Mapping) else None


def _method_why(ev: Mapping[str, Any], method: str, requested: str) -> str:
    """Why the clock's method was used: the automatic choice's reason when sync.json
    gives one, else the method's description, prefixed by what was asked for."""
    why = ev.get("auto") if isinstance(ev.get("auto"), str) else ""
    if why:
        return why
    why = METHOD_WHY.get(method, "")
    if requested not in ("auto", method):
        return f"asked for {requested}; {why}"
    return f"requested; {why}" if requested == method else why


def _camera_range(sync: Mapping[str, Any], clock: ClockLine) -> tuple[float, float]:
    """(first, last) camera time (s) of sync.json, else the clock's reference time twice."""
    rng = sync.get("camera_time_range_s")
    if isinstance(rng, list) and len(rng) == 2 and all(math.isfinite(_num(x)) for x in rng):
        return (_num(rng[0]), _num(rng[1]))
    return (clock.t_ref_s, clock.t_ref_s)


def _other_estimates(event, comb) -> list[ClockLine]:
    """The clocks the combination weighed: the event method's alone, the model's alone."""
    lines = [
        _line("event alone", event) if event is not None else None,
        _line("model alone", comb, "model_") if comb is not None else None,
    ]
    return [line for line in lines if line is not None]


def _profile(prof) -> tuple[np.ndarray, np.ndarray] | None:
    """(offsets at t_ref (s), residual sum of squares (deg^2)) of the model method's
    offset profile, shape (k,) each; None when sync.json has fewer than two points."""
    if not isinstance(prof, Mapping):
        return None
    x = np.asarray(prof.get("offset_at_t_ref_s") or [], dtype=float)
    y = np.asarray(prof.get("rss_deg2") or [], dtype=float)
    return (x, y) if x.size >= 2 and x.shape == y.shape else None


def _edges(ev: Mapping[str, Any], clock: ClockLine) -> list[Edge]:
    out = []
    for e in ev.get("edges") or ():
        if not isinstance(e, Mapping):
            continue
        t_cam, t_ctrl = _num(e.get("t_cam_s")), _num(e.get("t_ctrl_s"))
        if not (math.isfinite(t_cam) and math.isfinite(t_ctrl)):
            continue
        sd_cam, sd_ctrl = _num(e.get("t_cam_sd_s")), _num(e.get("t_ctrl_sd_s"))
        sd = math.hypot(*(s if math.isfinite(s) else 0.0 for s in (sd_cam, sd_ctrl)))
        r = t_ctrl - (t_cam + float(clock.offset(np.array(t_cam))))
        out.append(Edge(str(e.get("camera", "")), str(e.get("kind", "")), t_cam, r, sd))
    return out


def angle_rate_p95(time_s: np.ndarray, angle_deg: np.ndarray) -> float:
    """95th percentile of ``|d angle / dt|`` (deg/s) over consecutive measured samples.

    A clock error ``e`` moves a sample by ``e`` in time, i.e. by up to rate x ``e`` in
    angle: this turns the stated clock error into the angle error it can cause.
    NaN with fewer than two consecutive measured samples.
    """
    t = np.asarray(time_s, dtype=float)
    a = np.asarray(angle_deg, dtype=float)
    dt, da = np.diff(t), np.diff(a)
    ok = np.isfinite(da) & (dt > 0)
    if not ok.any():
        return float("nan")
    return float(np.percentile(np.abs(da[ok] / dt[ok]), 95))
