"""Exact likelihood of an LED edge time from the lit fractions of the frames around it.

A frame exposed over ``[s, e]`` (length ``E``) sees the fraction
``clip((e - u) / E, 0, 1)`` of an LED-on edge at time ``u`` (``(u - s) / E`` for an
LED-off edge). With Gaussian noise on the observed fractions the misfit
``sse(u) = sum_j ((f_j(u) - obs_j) / sd_j)^2`` is piecewise quadratic in ``u``: it
changes form only at exposure starts and ends. Between two such breakpoints every
frame is either constant (0 or 1) or linear in ``u``, so ``sse`` is
``a (u - m)^2 + q`` there (``a = 0``: constant, the edge lies between exposures).
Keeping it in that form makes the likelihood exact at any resolution: no time grid,
however short the exposure or small the noise.

Two operations are used by the clock estimate (:mod:`i2ris_calib.sync.posterior`):

- :func:`edge_moments`: the evidence ``Z = integral exp(-sse/2) du`` (flat prior on the
  edge time) and the mean and variance of the edge time. A partly lit frame gives a
  narrow Gaussian; an edge between exposures a flat (uniform) stretch as wide as the
  gap, dropped frames included;
- :func:`window_min_sse`: the smallest ``sse`` over an interval of edge times (the
  interval a logged edge maps to under a candidate clock), i.e. the profile over the
  edge's unknown position inside that interval.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import erf, erfcx

_REF = {"start": 0.0, "middle": 0.5, "end": 1.0}
_SQRT_PI = float(np.sqrt(np.pi))
TIME_FLOOR_S = 1e-5  # smallest standard deviation given to any edge time, s


@dataclass(frozen=True)
class SsePieces:
    """``sse(u) = a (u - m)^2 + q`` on ``[p0, p1]``; constant beyond the first/last piece.

    All arrays have shape (P,); ``a == 0`` marks a constant piece (``m`` unused).
    """

    p0: np.ndarray
    p1: np.ndarray
    a: np.ndarray
    m: np.ndarray
    q: np.ndarray

    def minimum(self) -> float:
        """Smallest ``sse`` over all edge times."""
        u = np.clip(self.m, self.p0, self.p1)
        return float(np.min(self.a * (u - self.m) ** 2 + self.q))


def exposure_windows(t_s: np.ndarray, exposure_s, ref: str) -> tuple[np.ndarray, np.ndarray]:
    """(start, end) of each frame's exposure, s, from timestamps and where they sit in it.

    ``exposure_s`` is a float or an array broadcastable to ``t_s``."""
    start = np.asarray(t_s, dtype=float) - _REF[ref] * exposure_s
    return start, start + exposure_s


def sse_pieces(
    t_s: np.ndarray,
    frac: np.ndarray,
    frac_sd: np.ndarray | float,
    exposure_s: float,
    ref: str,
    rising: bool,
) -> SsePieces:
    """Piecewise-quadratic misfit of one LED edge's frames as a function of its time.

    Parameters
    ----------
    t_s : ndarray, shape (k,)
        Frame timestamps (camera clock, s); frames of several cameras may be mixed
        (they share the camera clock and hence the edge time).
    frac : ndarray, shape (k,)
        Observed lit fractions ``(grey - dark) / (bright - dark)``.
    frac_sd : float or ndarray, shape (k,)
        Standard deviation of each fraction.
    exposure_s : float or ndarray, shape (k,)
        Exposure time, s (> 0), or one per frame (cameras with different exposures).
    ref : {"start", "middle", "end"}
        Where in its exposure a frame's timestamp lies.
    rising : bool
        LED-on (True) or LED-off (False) edge.
    """
    f = np.asarray(frac, dtype=float)
    w = 1.0 / np.broadcast_to(np.asarray(frac_sd, dtype=float), f.shape) ** 2
    exposure = np.broadcast_to(np.asarray(exposure_s, dtype=float), f.shape)
    start, end = exposure_windows(t_s, exposure, ref)
    bp = np.unique(np.concatenate([start, end]))
    p0, p1 = bp[:-1], bp[1:]
    mid = 0.5 * (p0 + p1)[:, None]
    inside = (start < mid) & (mid < end)  # (P, k): frame partly lit for edges in the piece
    edge_before = mid <= start  # the edge precedes the exposure
    full = edge_before if rising else ~edge_before  # constant frames: fully lit or dark
    beta = (-1.0 if rising else 1.0) / exposure  # lit fraction = alpha + beta u
    alpha = (end if rising else -start) / exposure
    lin = np.where(inside, w, 0.0)
    a = lin @ beta**2
    b = 2.0 * (lin @ (beta * (alpha - f)))
    c = lin @ (alpha - f) ** 2 + np.where(inside, 0.0, w * (full - f) ** 2).sum(axis=1)
    quad = a > 0
    a_safe = np.where(quad, a, 1.0)
    m = np.where(quad, -b / (2 * a_safe), p0)
    q = np.where(quad, c - b**2 / (4 * a_safe), c)
    return SsePieces(p0, p1, np.where(quad, a, 0.0), m, q)


def window_min_sse(pc: SsePieces, u_lo: np.ndarray, u_hi: np.ndarray) -> np.ndarray:
    """Smallest ``sse`` over each interval ``[u_lo, u_hi]`` of edge times, shape (G,).

    Intervals reaching beyond the pieces use the constant value outside them.
    """
    lo, hi = pc.p0[0], pc.p1[-1]
    ua = np.clip(np.asarray(u_lo, dtype=float), lo, hi)[:, None]
    ub = np.clip(np.asarray(u_hi, dtype=float), lo, hi)[:, None]
    a = np.maximum(pc.p0, ua)
    b = np.minimum(pc.p1, ub)
    u = np.clip(pc.m, a, b)
    val = np.where(a <= b, pc.a * (u - pc.m) ** 2 + pc.q, np.inf)
    return val.min(axis=1)


def edge_moments(pc: SsePieces) -> tuple[float, float, float]:
    """Log evidence and posterior mean and variance of the edge time (flat prior).

    Returns
    -------
    log_z : float
        ``log integral exp(-sse(u)/2) du`` over the pieces, s (up to a constant that
        is the same for every exposure, so exposures can be compared with it).
    mean_s, var_s2 : float
        Mean and variance of ``u`` under the density ``exp(-sse/2)``.
    """
    s0 = pc.minimum()
    r = 0.5 * (pc.p0[0] + pc.p1[-1])  # reference time: moments about it stay well conditioned
    i0, i1, i2 = _piece_integrals(pc, s0, r)
    z0 = float(i0.sum())
    mean = float(i1.sum()) / z0
    var = max(float(i2.sum()) / z0 - mean**2, 0.0)
    return -0.5 * s0 + np.log(z0), r + mean, var


def _piece_integrals(pc: SsePieces, s0: float, r: float):
    """Integrals of ``w``, ``(u - r) w``, ``(u - r)^2 w`` over each piece, ``w = exp(-(sse - s0)/2)``."""
    p0, p1, a, m, q = pc.p0, pc.p1, pc.a, pc.m, pc.q
    quad = a > 0
    # constant pieces
    c = np.exp(-0.5 * np.maximum(q - s0, 0.0))  # constant pieces: q >= s0
    x0, x1 = p0 - r, p1 - r
    c0, c1, c2 = c * (x1 - x0), c * (x1**2 - x0**2) / 2, c * (x1**3 - x0**3) / 3
    # Gaussian pieces: w = exp(-(q - s0)/2 - k^2 (u - m)^2), k^2 = a/2
    k = np.sqrt(np.where(quad, a, 1.0) / 2.0)
    za, zb = k * (p0 - m), k * (p1 - m)
    ea = np.exp(np.minimum(-0.5 * (q - s0) - za**2, 0.0))  # w at the piece ends (<= 1)
    eb = np.exp(np.minimum(-0.5 * (q - s0) - zb**2, 0.0))
    scale = _SQRT_PI / (2 * k)
    g0 = np.where(
        za > 0,
        scale * (ea * erfcx(np.abs(za)) - eb * erfcx(np.abs(zb))),
        np.where(
            zb < 0,
            scale * (eb * erfcx(np.abs(zb)) - ea * erfcx(np.abs(za))),
            scale * np.exp(np.minimum(-0.5 * (q - s0), 0.0)) * (erf(zb) - erf(za)),
        ),
    )
    g0 = np.maximum(g0, 0.0)
    gx = (ea - eb) / (2 * k**2)  # integral of (u - m) w
    gxx = (g0 - ((p1 - m) * eb - (p0 - m) * ea)) / (2 * k**2)  # integral of (u - m)^2 w
    d = m - r
    g1, g2 = d * g0 + gx, d**2 * g0 + 2 * d * gx + gxx
    return (np.where(quad, g0, c0), np.where(quad, g1, c1), np.where(quad, g2, c2))


def window_log_prob(pc: SsePieces, u_lo: np.ndarray, u_hi: np.ndarray) -> np.ndarray:
    """Log posterior probability that the edge lies in each ``[u_lo, u_hi]``, shape (G,).

    ``log(integral over the window of exp(-sse/2) / integral over all pieces)``, flat
    prior on the edge time within the frames' span (the pieces): the interval-censored
    likelihood of a logged edge known only to lie in a log interval, convolved with
    the camera's timing error. Exact (piecewise Gaussian integrals); a window that
    misses every likely time gets the log of its tail mass, evaluated relative to the
    window's own smallest misfit so that it never underflows to ``-inf``.
    """
    s_all = pc.minimum()
    r = 0.5 * (pc.p0[0] + pc.p1[-1])
    log_z = np.log(float(_piece_integrals(pc, s_all, r)[0].sum()))
    lo, hi = pc.p0[0], pc.p1[-1]
    ua = np.clip(np.asarray(u_lo, dtype=float), lo, hi)[:, None]
    ub = np.clip(np.asarray(u_hi, dtype=float), lo, hi)[:, None]
    s_win = window_min_sse(pc, ua[:, 0], ub[:, 0])  # (G,)
    a = np.minimum(np.maximum(pc.p0, ua), pc.p1)
    b = np.maximum(np.minimum(pc.p1, ub), a)
    clipped = SsePieces(a, b, pc.a, pc.m, pc.q)
    s0 = np.where(np.isfinite(s_win), s_win, s_all)[:, None]
    i0 = _piece_integrals(clipped, s0, r)[0].sum(axis=1)
    # a window outside the frames' span (zero width after clipping): constant misfit there
    i0 = np.where(i0 > 0, i0, 1e-12)
    return -0.5 * (s0[:, 0] - s_all) + np.log(i0) - log_z
