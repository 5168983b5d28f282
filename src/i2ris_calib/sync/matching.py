"""Pairing camera LED edges with logged LED edges (which flash is which)."""

from __future__ import annotations

import numpy as np

from i2ris_calib.errors import CalibError
from i2ris_calib.sync.clock import clock_from_offsets
from i2ris_calib.sync.config import SyncConfig
from i2ris_calib.sync.flash import CameraEdge
from i2ris_calib.sync.logedges import LogEdge

#: a matched pair of edges
EdgePair = tuple[CameraEdge, LogEdge]


def match_edges(cam: list[CameraEdge], log: list[LogEdge], cfg: SyncConfig) -> list[EdgePair]:
    """Pair camera edges with logged edges of the same kind.

    Every (camera edge, log edge) pair of the same kind is tried as the anchor of a
    pure offset; the anchor that matches the most camera edges within
    ``max_edge_residual_s`` (plus the edges' own uncertainty, :func:`_pair_tolerance`)
    wins (ties: smallest RMS residual). A clock is then fitted to the matches (drift
    included) and the matching repeated once with it.

    Raises
    ------
    CalibError
        When two different offsets explain the edges equally well (periodic flashes
        with equal durations and a video covering only part of them).
    """
    if cfg.offset_search_s > 0:
        lo, hi = cfg.offset_guess_s - cfg.offset_search_s, cfg.offset_guess_s + cfg.offset_search_s
    else:
        lo, hi = -np.inf, np.inf
    tol = cfg.max_edge_residual_s
    scored = []
    for c in cam:
        for g in log:
            if c.rising != g.rising or not lo <= g.t_s - c.t_s <= hi:
                continue
            pairs = _pairs_for_offset(cam, log, g.t_s - c.t_s, 0.0, tol)
            res = np.array([gl.t_s - cl.t_s - (g.t_s - c.t_s) for cl, gl in pairs])
            scored.append((len(pairs), float(np.sqrt(np.mean(res**2))), g.t_s - c.t_s))
    if not scored:
        return []
    scored.sort(key=lambda s: (-s[0], s[1]))
    n_best, rms_best, off_best = scored[0]
    rivals = [s for s in scored if abs(s[2] - off_best) > 2 * tol and s[0] == n_best]
    if rivals and rivals[0][1] < 3 * rms_best + 1e-3:
        raise CalibError(
            f"sync flash edges match the log equally well at offsets {off_best:.4f} s and "
            f"{rivals[0][2]:.4f} s (periodic flashes?): set sync.offset_guess_s and "
            "sync.offset_search_s to pick one, or use flashes of distinct durations"
        )
    pairs = _pairs_for_offset(cam, log, off_best, 0.0, tol)
    if len(pairs) >= 2:
        t = np.array([c.t_s for c, _ in pairs])
        off = np.array([g.t_s - c.t_s for c, g in pairs])
        o, d, _, _ = clock_from_offsets(t, off, np.ones_like(t), fit_drift=np.ptp(t) > 1.0)
        pairs = _pairs_for_offset(cam, log, o, d, tol)
    return pairs


def _pairs_for_offset(
    cam: list[CameraEdge], log: list[LogEdge], offset_s: float, drift_ppm: float, tol: float
) -> list[EdgePair]:
    """Nearest same-kind log edge within ``tol`` for each camera edge under a clock."""
    pairs = []
    for c in cam:
        t_ctrl = offset_s + (1 + drift_ppm * 1e-6) * c.t_s
        same = [g for g in log if g.rising == c.rising]
        if not same:
            continue
        g = min(same, key=lambda g: abs(g.t_s - t_ctrl))
        if abs(g.t_s - t_ctrl) <= _pair_tolerance(c, g, tol):
            pairs.append((c, g))
    return pairs


def _pair_tolerance(cam: CameraEdge, log: LogEdge, tol: float) -> float:
    """Largest residual of a matching pair: ``tol`` plus the half-widths of both edges'
    uncertainty intervals (sqrt(3) sd: the half-width of a uniform distribution), so a
    coarse edge (between exposures, slow log) is not rejected for its own quantisation."""
    return tol + np.sqrt(3.0) * (cam.sd_s + log.sd_s)
