"""Offset by cross-correlating the time derivatives of angle and encoder input.

This is the textbook estimator and it is BIASED for this robot: hysteresis makes the
angle lag the input, which the correlation reports as clock offset (measured:
+13 / +25 ms for 2 / 6 deg of backlash). It is used (a) for comparison, as method
``xcorr``, and (b) to place the coarse grid of the joint offset + hysteresis profile.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import correlate, correlation_lags, savgol_filter

from i2ris_calib.errors import CalibError
from i2ris_calib.sync.clock import PPM, ClockModel, clock_from_offsets, clock_model
from i2ris_calib.sync.config import SyncConfig
from i2ris_calib.sync.log import EncoderLog


@dataclass(frozen=True)
class AxisSeries:
    """Measured angle of one axis and the name of its encoder channel.

    Attributes
    ----------
    axis : str
        ``yaw`` or ``pitch``.
    channel : str
        Encoder channel in the log (``enc_yaw`` / ``enc_pitch``).
    t_cam_s : ndarray, shape (n,)
        Frame times (camera clock, s), increasing, measured frames only.
    theta_deg : ndarray, shape (n,)
        Measured angle, deg.
    """

    axis: str
    channel: str
    t_cam_s: np.ndarray
    theta_deg: np.ndarray


def _unit(x: np.ndarray) -> np.ndarray:
    """Zero-mean, unit-norm copy of ``x`` (zeros if constant)."""
    x = x - x.mean()
    n = np.linalg.norm(x)
    return x / n if n > 0 else x


def offset_search_range(
    series: list[AxisSeries], log: EncoderLog, cfg: SyncConfig
) -> tuple[float, float]:
    """Offsets (s) to search: the configured window, else every offset with any overlap."""
    if cfg.offset_search_s > 0:
        return cfg.offset_guess_s - cfg.offset_search_s, cfg.offset_guess_s + cfg.offset_search_s
    lo_log, hi_log = log.time_range()
    t0 = min(s.t_cam_s[0] for s in series)
    t1 = max(s.t_cam_s[-1] for s in series)
    return lo_log - t1, hi_log - t0


def coarse_xcorr_offset(series: list[AxisSeries], log: EncoderLog, cfg: SyncConfig) -> float:
    """Offset (s) at the peak of the summed squared derivative cross-correlations.

    Both signals are resampled at ``cfg.xcorr_rate_hz`` on their own clocks and
    correlated by FFT over the whole search range (:func:`offset_search_range`);
    the peak is refined by a parabola through its neighbours.
    """
    fs = cfg.xcorr_rate_hz
    lo, hi = offset_search_range(series, log, cfg)
    lo_log, hi_log = log.time_range()
    tv = lo_log + np.arange(int((hi_log - lo_log) * fs)) / fs
    score = None
    for s in series:
        tc = s.t_cam_s[0] + np.arange(int((s.t_cam_s[-1] - s.t_cam_s[0]) * fs)) / fs
        if tc.size < 8 or tv.size < 8:
            raise CalibError(
                "sync: too few samples to cross-correlate (recording shorter than 40 ms?)"
            )
        dth = _unit(np.gradient(np.interp(tc, s.t_cam_s, s.theta_deg)))
        dv = _unit(np.gradient(log.interpolate(s.channel, tv)))
        c = correlate(dv, dth, mode="full", method="fft")
        lags = correlation_lags(dv.size, dth.size, mode="full")
        score = c**2 if score is None else score + c**2
        offsets = tv[0] - tc[0] + lags / fs
    inside = (offsets >= lo) & (offsets <= hi)
    if not inside.any():
        raise CalibError(
            f"sync: offset search range [{lo:.3f}, {hi:.3f}] s leaves no overlap between video "
            "and encoder log (check sync.offset_guess_s/offset_search_s and the log's time range)"
        )
    idx = np.flatnonzero(inside)
    k = idx[np.argmax(score[idx])]
    return float(offsets[k] + _parabola_peak(score, k) / fs)


def _parabola_peak(y: np.ndarray, k: int) -> float:
    """Sub-sample position (in samples, relative to ``k``) of the peak through y[k-1..k+1]."""
    if k <= 0 or k >= y.size - 1:
        return 0.0
    a, b, c = y[k - 1], y[k], y[k + 1]
    den = a - 2 * b + c
    return float(0.5 * (a - c) / den) if den < 0 else 0.0


def smooth_derivative(x: np.ndarray, dt_s: float, smooth_s: float) -> np.ndarray:
    """Savitzky-Golay first derivative of uniformly sampled ``x`` (window ``smooth_s``).

    The same symmetric filter is applied to angle and encoder, so it adds no delay
    between them; it only suppresses the noise that differentiation amplifies.
    """
    n = max(int(round(smooth_s / dt_s)) | 1, 5)
    if x.size <= n:
        return np.gradient(x, dt_s)
    return savgol_filter(x, n, 2, deriv=1, delta=dt_s)


def local_xcorr_score(
    series: list[AxisSeries],
    log: EncoderLog,
    offset_s: float,
    drift_ppm: float,
    smooth_s: float,
    window: tuple[float, float] | None = None,
) -> float:
    """Summed squared normalised correlation of d(theta)/dt and d(v)/dt at one clock.

    The angle is resampled on a uniform grid at the median frame interval (gaps
    bridged linearly) and the encoder interpolated at the mapped grid times, so both
    derivatives are taken on the same samples with the same filter
    (:func:`smooth_derivative`). ``window`` restricts to camera times [a, b).
    """
    total = 0.0
    for s in series:
        t = s.t_cam_s
        dt = float(np.median(np.diff(t)))
        a, b = (t[0], t[-1]) if window is None else (max(window[0], t[0]), min(window[1], t[-1]))
        grid = a + np.arange(int(max(b - a, 0.0) / dt)) * dt
        v = log.interpolate(s.channel, offset_s + (1 + drift_ppm * PPM) * grid)
        ok = np.isfinite(v)
        if ok.sum() < 8:
            continue
        grid, v = grid[ok], v[ok]
        th = np.interp(grid, t, s.theta_deg)
        dth = _unit(smooth_derivative(th, dt, smooth_s))
        dv = _unit(smooth_derivative(v, dt, smooth_s))
        total += float(dth @ dv) ** 2
    return total


def refine_xcorr_offset(
    series: list[AxisSeries],
    log: EncoderLog,
    offset0_s: float,
    drift_ppm: float,
    halfwidth_s: float,
    smooth_s: float,
    window: tuple[float, float] | None = None,
    step_s: float = 0.001,
) -> float:
    """Offset (s) maximising :func:`local_xcorr_score` within ``offset0_s +- halfwidth_s``.

    Grid at ``step_s`` then a parabola through the best point and its neighbours.
    """
    grid = offset0_s + np.arange(-halfwidth_s, halfwidth_s + step_s / 2, step_s)
    score = np.array([local_xcorr_score(series, log, o, drift_ppm, smooth_s, window) for o in grid])
    k = int(np.argmax(score))
    return float(grid[k] + _parabola_peak(score, k) * step_s)


def window_edges(series: list[AxisSeries], n: int) -> np.ndarray:
    """``n + 1`` camera times splitting the recording into ``n`` equal windows."""
    t0 = min(s.t_cam_s[0] for s in series)
    t1 = max(s.t_cam_s[-1] for s in series)
    edges = np.linspace(t0, t1, n + 1)
    edges[-1] = np.nextafter(t1, np.inf)
    return edges


def clock_from_xcorr(series: list[AxisSeries], log: EncoderLog, cfg: SyncConfig) -> ClockModel:
    """Plain cross-correlation clock (method ``xcorr``; biased by hysteresis).

    Coarse FFT offset, refined on the frame samples; drift from the same refinement
    in ``cfg.drift_windows`` windows (a line through the window offsets, whose scatter
    gives the standard errors). NOTE: the hysteresis bias depends on the speed in each
    window, so the drift is biased too when speeds differ between windows.
    """
    o0 = coarse_xcorr_offset(series, log, cfg)
    o1 = refine_xcorr_offset(series, log, o0, 0.0, 2.0 / cfg.xcorr_rate_hz, cfg.xcorr_smooth_s)
    n_win = cfg.drift_windows if cfg.estimate_drift else 1
    edges = window_edges(series, n_win)
    t_mid = 0.5 * (edges[:-1] + edges[1:])
    offs = np.array(
        [
            refine_xcorr_offset(series, log, o1, 0.0, 0.05, cfg.xcorr_smooth_s, (a, b))
            for a, b in zip(edges[:-1], edges[1:], strict=True)
        ]
    )
    if n_win >= 3:
        o, d, cov, chi2 = clock_from_offsets(
            t_mid, offs, np.full(n_win, 1e-3), True, scale="always"
        )
        drift_fitted = True
    else:
        o, d, cov = o1, 0.0, np.diag([np.nan, 0.0])
        drift_fitted = False
    evidence = {
        "coarse_offset_s": o0,
        "global_offset_s": o1,
        "windows_t_cam_s": t_mid,
        "window_offsets_s": offs,
        "note": "plain cross-correlation: biased by hysteresis (for comparison only)",
    }
    return clock_model(o, d, cov, "xcorr", evidence, drift_fitted)
