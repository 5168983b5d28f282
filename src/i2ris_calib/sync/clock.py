"""The clock model ``t_ctrl = offset_s + (1 + drift_ppm*1e-6) * t_cam`` and its fits."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

PPM = 1e-6


@dataclass(frozen=True)
class ClockModel:
    """Camera clock -> controller clock (docs/sync.md convention).

    The clock is held relative to recording-local origins (``origin_cam_s``,
    ``origin_ctrl_s``; both 0 unless set by :func:`i2ris_calib.sync.estimate.estimate_clock`):
    ``t_ctrl - origin_ctrl_s = offset_s + (1 + drift_ppm*1e-6) * (t_cam - origin_cam_s)``.
    Epoch-scale clocks (ROS bags: ~1.7e9 s) would otherwise lose float64 precision
    and make the (offset, drift) covariance singular. :meth:`offset_at` and
    :meth:`offset_stderr_at` give the documented offset ``t_ctrl - t_cam`` at any
    camera time, e.g. ``offset_at(0.0)`` for sync.json's ``offset_s``.

    Attributes
    ----------
    offset_s : float
        Local controller time at local camera time 0, s (with zero origins: controller
        time at camera time 0).
    drift_ppm : float
        Rate difference, parts per million (controller seconds per camera second - 1).
    offset_stderr_s, drift_stderr_ppm : float
        Standard errors of ``offset_s`` and ``drift_ppm`` (NaN when not estimated;
        drift stderr is NaN when drift was fixed).
    cov : ndarray, shape (2, 2)
        Covariance of (offset_s, drift_ppm).
    method : str
        ``event``, ``model``, ``xcorr`` or ``event+model`` (``auto``: a coarse event
        combined with the model).
    evidence : dict
        Method-specific evidence (matched edges, profiles), JSON-safe.
    origin_cam_s, origin_ctrl_s : float
        Recording-local origins of the camera and controller clocks, s.
    """

    offset_s: float
    drift_ppm: float = 0.0
    offset_stderr_s: float = float("nan")
    drift_stderr_ppm: float = float("nan")
    cov: np.ndarray | None = None
    method: str = ""
    evidence: dict = field(default_factory=dict)
    origin_cam_s: float = 0.0
    origin_ctrl_s: float = 0.0

    def to_ctrl(self, t_cam_s: np.ndarray) -> np.ndarray:
        """Controller-clock times, s, of camera times ``t_cam_s`` (any shape)."""
        local = np.asarray(t_cam_s, dtype=float) - self.origin_cam_s
        return self.origin_ctrl_s + (self.offset_s + (1.0 + self.drift_ppm * PPM) * local)

    def offset_at(self, t_cam_s: float) -> float:
        """Offset ``t_ctrl - t_cam`` at camera time ``t_cam_s``, s."""
        local = float(t_cam_s) - self.origin_cam_s
        base = self.origin_ctrl_s - self.origin_cam_s
        return float(base + (self.offset_s + self.drift_ppm * PPM * local))

    def offset_stderr_at(self, t_cam_s: float) -> float:
        """Standard error of :meth:`offset_at`, s (uses the covariance)."""
        if self.cov is None:
            return self.offset_stderr_s
        j = np.array([1.0, (float(t_cam_s) - self.origin_cam_s) * PPM])
        return float(np.sqrt(max(j @ self.cov @ j, 0.0)))


def clock_from_offsets(
    t_cam_s: np.ndarray,
    offsets_s: np.ndarray,
    sd_s: np.ndarray,
    fit_drift: bool = True,
    scale: str = "if_larger",
) -> tuple[float, float, np.ndarray, float]:
    """Weighted line ``offset(t) = o + d*1e-6*t`` through local offset estimates.

    Parameters
    ----------
    t_cam_s : ndarray, shape (k,)
        Camera times of the estimates, s.
    offsets_s : ndarray, shape (k,)
        Local offsets ``t_ctrl - t_cam``, s.
    sd_s : ndarray, shape (k,)
        Their standard deviations, s (> 0).
    fit_drift : bool
        Fit the slope; False (or a single point) holds drift at 0.
    scale : {"if_larger", "always"}
        Scale the covariance by the reduced chi-square when it exceeds 1 (default:
        ``sd_s`` are trusted as a floor), or always (``sd_s`` are only relative weights).

    Returns
    -------
    offset_s, drift_ppm : float
    cov : ndarray, shape (2, 2)
        Covariance of (offset_s, drift_ppm); the larger of the propagated and the
        residual-scaled covariance (so scatter beyond the stated sd is not hidden).
    chi2_red : float
        Reduced chi-square of the fit (NaN with no degrees of freedom).
    """
    t = np.asarray(t_cam_s, dtype=float)
    y = np.asarray(offsets_s, dtype=float)
    w = 1.0 / np.asarray(sd_s, dtype=float) ** 2
    fit_drift = fit_drift and t.size >= 2 and np.ptp(t) > 0
    # centre time for conditioning, then shift back
    tc = float(np.average(t, weights=w))
    cols = [np.ones_like(t)] + ([(t - tc) * PPM] if fit_drift else [])
    a = np.column_stack(cols)
    aw = a * np.sqrt(w)[:, None]
    yw = y * np.sqrt(w)
    coef, *_ = np.linalg.lstsq(aw, yw, rcond=None)
    cov_c = np.linalg.inv(aw.T @ aw)
    dof = t.size - a.shape[1]
    resid = yw - aw @ coef
    chi2_red = float(resid @ resid / dof) if dof > 0 else float("nan")
    if dof > 0 and (chi2_red > 1 or scale == "always"):
        cov_c = cov_c * chi2_red
    elif scale == "always":
        cov_c = cov_c * np.nan
    if not fit_drift:
        o_c, d = float(coef[0]), 0.0
        cov = np.array([[cov_c[0, 0], 0.0], [0.0, 0.0]])
        return o_c, d, cov, chi2_red
    o_c, d = float(coef[0]), float(coef[1])
    # offset at t=0: o = o_c - d*PPM*tc ; Jacobian of (o, d) wrt (o_c, d)
    jac = np.array([[1.0, -tc * PPM], [0.0, 1.0]])
    return o_c - d * PPM * tc, d, jac @ cov_c @ jac.T, chi2_red


def clock_model(
    offset_s: float,
    drift_ppm: float,
    cov: np.ndarray,
    method: str,
    evidence: dict,
    drift_fitted: bool,
) -> ClockModel:
    """:class:`ClockModel` with standard errors read from ``cov``."""
    return ClockModel(
        offset_s=float(offset_s),
        drift_ppm=float(drift_ppm),
        offset_stderr_s=float(np.sqrt(max(cov[0, 0], 0.0))),
        drift_stderr_ppm=float(np.sqrt(max(cov[1, 1], 0.0))) if drift_fitted else float("nan"),
        cov=cov,
        method=method,
        evidence=evidence,
    )
