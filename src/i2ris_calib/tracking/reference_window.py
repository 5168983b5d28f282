"""Is the tip still in the reference window? (the straight pose every angle is relative to).

``track`` takes yaw = pitch = 0 as the mean pose over the reference window
(``[track] reference_start_s``, ``reference_duration_s``; docs/tracking.md). A lab
recording that starts anywhere may have the tip bending through that window: then
every angle is relative to a pose the tip never held, and a bent reference mixes the
axes (the yaw angle picks up part of the pitch bend). Nothing in the angles themselves
can say which pose is straight, but motion within the window can be seen: this module
measures it so ``track`` can say so instead of returning shifted angles silently.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Tip motion within the reference window (deg, the largest of the two axes' smooth
#: excursions) above which ``track`` warns; never below :data:`NOISE_FACTOR` x the
#: standard error of a window mean, so a noisy tracker's still tip is not flagged
REFERENCE_MOTION_DEG = 0.5
#: Motion must exceed this many standard errors of the window's mean angle
#: (``sd / sqrt(n)``) to count: pure noise gives a fitted peak-to-peak above 12.8
#: ``sd / sqrt(n)`` in 1 of 1000 windows of 3-50 frames (simulated)
NOISE_FACTOR = 15.0


@dataclass(frozen=True)
class WindowMotion:
    """How far the tip moved within the reference window.

    Attributes
    ----------
    yaw_deg, pitch_deg : float
        Peak-to-peak of a quadratic in time fitted to each angle over the window's
        measured frames (deg; a line with 3 frames; NaN with fewer): the smooth motion,
        not the noise.
    noise_sd_deg : float
        Frame-to-frame noise of the angles (deg; the larger axis's, from second
        differences over the whole recording's measured frames, robust to the motion),
        NaN with fewer than 3 measured frames.
    threshold_deg : float
        ``max(REFERENCE_MOTION_DEG, NOISE_FACTOR * noise_sd_deg / sqrt(frames))``.
    frames : int
        Measured frames in the window.
    moving : bool
        The larger of ``yaw_deg``, ``pitch_deg`` exceeds ``threshold_deg``.
    """

    yaw_deg: float
    pitch_deg: float
    noise_sd_deg: float
    threshold_deg: float
    frames: int
    moving: bool


def _smooth_excursion(t: np.ndarray, y: np.ndarray) -> float:
    """Peak-to-peak (deg) over ``t`` of a least-squares polynomial in time (degree 2,
    1 with 3 points); NaN with fewer than 3 points."""
    if t.size < 3:
        return float("nan")
    deg = 2 if t.size >= 4 else 1
    tc = (t - t.mean()) / max(float(np.ptp(t)), 1e-12)
    fit = np.polyval(np.polyfit(tc, y, deg), np.linspace(tc.min(), tc.max(), 101))
    return float(np.ptp(fit))


def _difference_noise(y: np.ndarray) -> float:
    """Frame noise sd (deg) from second differences (a smooth motion cancels):
    ``MAD(d2) * 1.4826 / sqrt(6)``; NaN with fewer than 3 points."""
    if y.size < 3:
        return float("nan")
    d2 = np.diff(y, 2)
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6.0))


def reference_window_motion(
    t_s: np.ndarray, yaw_deg: np.ndarray, pitch_deg: np.ndarray, window: np.ndarray
) -> WindowMotion:
    """The tip's motion within the reference window.

    Parameters
    ----------
    t_s : ndarray, shape (n,)
        Frame times (s).
    yaw_deg, pitch_deg : ndarray, shape (n,)
        Angles relative to the reference (deg; NaN where not measured), the whole
        recording (its noise sets the threshold).
    window : ndarray of bool, shape (n,)
        Frames in the reference window.

    Returns
    -------
    WindowMotion
    """
    t_all = np.asarray(t_s, float)
    yaw_all, pitch_all = np.asarray(yaw_deg, float), np.asarray(pitch_deg, float)
    ok = np.isfinite(yaw_all) & np.isfinite(pitch_all)
    sel = np.asarray(window, bool) & ok
    t, yaw, pitch = t_all[sel], yaw_all[sel], pitch_all[sel]
    moves = (_smooth_excursion(t, yaw), _smooth_excursion(t, pitch))
    noise = max(_difference_noise(yaw_all[ok]), _difference_noise(pitch_all[ok]))
    thr = REFERENCE_MOTION_DEG
    if np.isfinite(noise) and t.size:
        thr = max(thr, NOISE_FACTOR * noise / np.sqrt(t.size))
    moving = bool(np.nanmax(moves) > thr) if np.isfinite(moves).any() else False
    return WindowMotion(moves[0], moves[1], float(noise), float(thr), int(t.size), moving)
