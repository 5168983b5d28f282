"""Clock sync from a sync event: LED flash edges in the video matched to the log.

The controller switches an LED that both microscopes see and logs it as
``sync_flash``. The stages, one module each:

- :mod:`i2ris_calib.sync.flash`: edges seen by a camera (``CameraEdge``), with
  sub-frame times from partly lit frames;
- :mod:`i2ris_calib.sync.logedges`: edges of the logged LED state (``LogEdge``);
- :mod:`i2ris_calib.sync.matching`: which camera edge belongs to which logged edge;
- :mod:`i2ris_calib.sync.posterior`: the posterior of (offset, drift) given the frames;
- this module: :func:`clock_from_events`, the whole estimate and its evidence.
"""

from __future__ import annotations

import numpy as np

from i2ris_calib.errors import CalibError
from i2ris_calib.sync.clock import ClockModel, clock_from_offsets, clock_model
from i2ris_calib.sync.config import SyncConfig
from i2ris_calib.sync.flash import CameraEdge, edge_given_exposure
from i2ris_calib.sync.logedges import LogEdge
from i2ris_calib.sync.matching import match_edges
from i2ris_calib.sync.posterior import posterior_clock


def clock_from_events(
    cam: list[CameraEdge],
    log: list[LogEdge],
    cfg: SyncConfig,
    span_s: tuple[float, float] | None = None,
) -> ClockModel:
    """Offset and drift from LED edges matched between video and encoder log.

    A weighted line through the per-edge times (:func:`clock_from_offsets`) gives a
    start; the estimate is then the posterior mean of (offset, drift) given every
    matched frame's brightness (:func:`posterior_clock`), which intersects the
    interval constraints of all edges instead of averaging their midpoints. With
    ``cfg.exposure_s = 0`` the exposure is unknown and marginalised. When the edges
    disagree more than the noise allows (misfit above its degrees of freedom: one per
    logged edge less the fitted parameters) the likelihood is tempered by that ratio,
    as least squares scales a covariance by the reduced chi-square.
    Drift is fitted when the matched edges span at least ``cfg.min_drift_span_s``;
    otherwise it is held at 0 ppm (stderr NaN). ``cfg.event_likelihood`` and
    ``cfg.event_estimate``: see :func:`posterior_clock`; ``span_s`` (camera clock, s:
    the first and last frame; default the matched edges' span) is the span over
    which the ``midrange`` estimate minimises the worst-case clock error.

    Raises
    ------
    CalibError
        No camera edge matches a logged edge.
    """
    pairs = match_edges(cam, log, cfg)
    if not pairs:
        raise CalibError(
            f"sync flash: {len(cam)} edge(s) in the video and {len(log)} in the encoder log, "
            "but none match (check sync.frame_time_ref/exposure_s, or use sync.method = 'model')"
        )
    t, off, sd = _pair_offsets(pairs)
    fit_drift = bool(np.ptp(t) >= cfg.min_drift_span_s)
    o0, d0, cov0, chi2 = clock_from_offsets(t, off, sd, fit_drift=fit_drift)
    t_c, centre, halfwidth = _search_box(t, sd, o0, d0, cov0)
    if span_s is None:
        span_s = (float(np.min(t)), float(np.max(t)))
    mean, cov_c, p_exposure, misfit, temper = _tempered_posterior(
        pairs, t_c, centre, halfwidth, fit_drift, cfg, span_s
    )
    jac = np.array([[1.0, -t_c * 1e-6], [0.0, 1.0]])
    o, d, cov = mean[0] - mean[1] * 1e-6 * t_c, mean[1], jac @ cov_c @ jac.T
    pairs = [(edge_given_exposure(c, p_exposure), g) for c, g in pairs]
    evidence = {
        "n_camera_edges": len(cam),
        "n_log_edges": len(log),
        "n_matched": len(pairs),
        "drift_fitted": fit_drift,
        "line_fit": {"offset_s": o0, "drift_ppm": d0, "chi2_reduced": chi2},
        "exposure": exposure_evidence(pairs[0][0].exposures_s, p_exposure, cfg.exposure_s),
        "misfit": misfit,
        "likelihood_temper": temper,
        "likelihood": cfg.event_likelihood,
        "estimate": cfg.event_estimate,
        "span_cam_s": list(span_s),
        "edges": _edge_residual_rows(pairs, o, d),
    }
    return clock_model(o, d, cov, "event", evidence, fit_drift)


def _pair_offsets(
    pairs: list[tuple[CameraEdge, LogEdge]],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Camera time, clock offset and its sd of each matched edge pair.

    Returns
    -------
    t, off, sd : ndarray, shape (n_pairs,)
        Camera-clock edge time (s), controller minus camera time (s), and the
        combined sd of the two edge times (s).
    """
    t = np.array([c.t_s for c, _ in pairs])
    off = np.array([g.t_s - c.t_s for c, g in pairs])
    sd = np.array([np.hypot(c.sd_s, g.sd_s) for c, g in pairs])
    return t, off, sd


def _search_box(
    t: np.ndarray, sd: np.ndarray, o0: float, d0: float, cov0: np.ndarray
) -> tuple[float, tuple[float, float], tuple[float, float]]:
    """Centre and half-widths of the posterior grid from the weighted line fit.

    Parameters
    ----------
    t, sd : ndarray, shape (n_pairs,)
        Camera-clock edge times and their offset sd (s).
    o0, d0 : float
        Line-fit offset at camera time 0 (s) and drift (ppm).
    cov0 : ndarray, shape (2, 2)
        Covariance of (o0, d0) (s^2, s ppm, ppm^2).

    Returns
    -------
    t_c : float
        Weighted mean edge time (camera clock, s), where offset and drift decorrelate.
    centre : tuple of float
        (offset at ``t_c`` (s), drift (ppm)).
    halfwidth : tuple of float
        Half-widths of the grid: 5 sd, at least 1 ms and 5 ppm.
    """
    t_c = float(np.average(t, weights=1 / sd**2))
    centre = (o0 + d0 * 1e-6 * t_c, d0)
    j = np.array([1.0, t_c * 1e-6])
    sd_c = float(np.sqrt(j @ cov0 @ j))
    halfwidth = (5 * max(sd_c, 2e-4), 5 * max(np.sqrt(cov0[1, 1]), 1.0))
    return t_c, centre, halfwidth


def _tempered_posterior(
    pairs: list[tuple[CameraEdge, LogEdge]],
    t_c: float,
    centre: tuple[float, float],
    halfwidth: tuple[float, float],
    fit_drift: bool,
    cfg: SyncConfig,
    span_s: tuple[float, float],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
    """Posterior of (offset at ``t_c``, drift), tempered when the edges disagree.

    Returns
    -------
    mean : ndarray, shape (2,)
        (offset at ``t_c`` (s), drift (ppm)).
    cov_c : ndarray, shape (2, 2)
        Its covariance.
    p_exposure : ndarray, shape (n_exposures,)
        Posterior weight of each exposure candidate.
    misfit : float
        Misfit of the untempered posterior (chi-square-like).
    temper : float
        Likelihood temper, >= 1 (misfit over its degrees of freedom).
    """
    opts = {
        "mode": cfg.event_likelihood,
        "span_s": span_s if cfg.event_estimate == "midrange" else None,
    }
    mean, cov_c, p_exposure, misfit = posterior_clock(
        pairs, t_c, centre, halfwidth, fit_drift, **opts
    )
    n_groups = len({id(g) for _, g in pairs})
    temper = max(1.0, misfit / max(n_groups - (2 if fit_drift else 1), 1))
    if temper > 1.0:  # edges disagree beyond the grey noise (e.g. saturated bright pixels)
        mean, cov_c, p_exposure, _ = posterior_clock(
            pairs, t_c, tuple(mean), halfwidth, fit_drift, temper=temper, **opts
        )
    return mean, cov_c, p_exposure, misfit, temper


def _edge_residual_rows(pairs: list[tuple[CameraEdge, LogEdge]], o: float, d: float) -> list[dict]:
    """JSON rows of the matched edges with their residual from the fitted clock.

    ``o`` is the offset at camera time 0 (s), ``d`` the drift (ppm); ``residual_s``
    is the controller edge time less the clock's prediction (s).
    """
    t, off, _ = _pair_offsets(pairs)
    resid = off - (o + d * 1e-6 * t)
    return [
        {
            "camera": c.camera,
            "kind": "on" if c.rising else "off",
            "t_cam_s": c.t_s,
            "t_cam_sd_s": c.sd_s,
            "t_ctrl_s": g.t_s,
            "t_ctrl_sd_s": g.sd_s,
            "residual_s": float(r),
        }
        for (c, g), r in zip(pairs, resid, strict=True)
    ]


def exposure_evidence(exposures_s, weights: np.ndarray, configured_s: float) -> dict:
    """JSON summary of the exposure: configured, or the posterior over the candidates."""
    e = np.asarray(exposures_s, dtype=float)
    mean = float(weights @ e)
    return {
        "configured_s": configured_s,
        "mean_s": mean,
        "sd_s": float(np.sqrt(max(weights @ (e - mean) ** 2, 0.0))),
        "candidates_s": e.tolist(),
        "posterior": weights.tolist(),
    }
