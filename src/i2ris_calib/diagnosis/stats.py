"""Statistics of the diagnosis: model scores (RMSE, BIC), the noise
autocovariance and the held-out SSE-reduction z-test that decides whether one
model improves on another.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from i2ris_calib.diagnosis.config import DiagnosisConfig
from i2ris_calib.diagnosis.data import SearchData
from i2ris_calib.diagnosis.results import Comparison, ModelScore
from i2ris_calib.fitting.metrics import information_criteria
from i2ris_calib.hysteresis.effects import CATALOGUE, model_values
from i2ris_calib.model import Model


def n_free_of(model: Model) -> int:
    """Number of free (not fixed) parameters of ``model``."""
    return int(sum(not p.fixed for p in model.parameters))


def score_of(model: Model, values: np.ndarray, d: SearchData, n_free: int) -> ModelScore:
    """Fitted/held-out RMSE (deg) and BIC of ``model`` at ``values`` on ``d``."""
    y = model.evaluate(d.signals, values)
    r = y - d.theta
    rf, rh = r[d.fit], r[d.hold]
    n = max(rf.size, 1)
    sse_f = float(np.dot(rf, rf))
    _, bic = information_criteria(sse_f, n, n_free)
    return ModelScore(
        fit_rmse_deg=float(np.sqrt(sse_f / n)),
        holdout_rmse_deg=float(np.sqrt(np.mean(rh**2))) if rh.size else float("nan"),
        bic=float(bic),
        n_free=int(n_free),
    )


def autocovariance(e: np.ndarray, max_lag: int) -> np.ndarray:
    """Sample autocovariance of ``e`` (shape (n,)) at lags 0..L, Bartlett-tapered.

    ``L`` is the first lag where the autocorrelation drops below 0.1 (at most
    ``max_lag``); the taper ``1 - l/(L+1)`` keeps the implied variance positive
    (Newey-West).
    """
    e = np.asarray(e, float) - np.mean(e)
    n = e.size
    g0 = float(np.dot(e, e) / n) if n else 0.0
    gam = [g0]
    for lag in range(1, min(max_lag, n - 1) + 1):
        g = float(np.dot(e[lag:], e[:-lag]) / n)
        if g0 <= 0 or g / g0 < 0.1:
            break
        gam.append(g)
    L = len(gam) - 1
    return np.array([g * (1 - lag / (L + 1)) for lag, g in enumerate(gam)])


def sse_reduction_z(
    r_before: np.ndarray, delta: np.ndarray, gamma: np.ndarray
) -> tuple[float, float]:
    """z-score and one-sided p-value of the held-out SSE reduction.

    With ``r_b`` the held-out residual of the model before and ``delta`` the
    change of its prediction, ``SSE_b - SSE_a = sum(2 r_b delta - delta^2)``.
    If the model before is adequate, ``r_b`` is noise ``e`` (autocovariance
    ``gamma``) and ``2 sum(e delta)`` has variance ``4 delta' C delta``, so
    ``z = (SSE_b - SSE_a) / (2 sqrt(delta' C delta))`` exceeds the normal
    quantile with at most the nominal probability (its mean is ``-sum delta^2``
    <= 0: the test is conservative).

    Parameters
    ----------
    r_before, delta : ndarray, shape (m,)
        Held-out residual before (deg) and prediction change after - before (deg),
        in time order.
    gamma : ndarray, shape (L+1,)
        Noise autocovariance at lags 0..L (deg^2), from :func:`autocovariance`.
    """
    gain = float(np.sum(2 * r_before * delta - delta**2))
    var = gamma[0] * float(np.dot(delta, delta))
    for lag in range(1, gamma.size):
        var += 2 * gamma[lag] * float(np.dot(delta[lag:], delta[:-lag]))
    if var <= 0:
        return (np.inf if gain > 0 else 0.0), (0.0 if gain > 0 else 1.0)
    z = gain / (2 * np.sqrt(var))
    return float(z), float(stats.norm.sf(z))


def compare(
    before: tuple[Model, ModelScore],
    after: tuple[Model, ModelScore],
    d: SearchData,
    cfg: DiagnosisConfig,
) -> Comparison:
    """Held-out evidence that ``after`` improves on ``before`` (see module doc).

    The noise autocovariance is estimated from the fitted-sample residual of
    ``after`` (the better model's residual is the closer one to pure noise).
    """
    mb, mtb = before
    ma, mta = after
    yb = mb.evaluate(d.signals, model_values(mb))
    ya = ma.evaluate(d.signals, model_values(ma))
    rb, ra = d.theta - yb, d.theta - ya
    gamma = autocovariance(ra[d.fit], max_lag=50)
    z, p = sse_reduction_z(rb[d.hold], (ya - yb)[d.hold], gamma)
    labels = np.unique(d.units[d.units >= 0])
    improved = sum(
        float(np.mean(ra[d.units == lab] ** 2)) < float(np.mean(rb[d.units == lab] ** 2))
        for lab in labels
    )
    rel = 1.0 - mta.holdout_rmse_deg / mtb.holdout_rmse_deg if mtb.holdout_rmse_deg > 0 else 0.0
    dbic = mta.bic - mtb.bic
    sig = bool(rel >= cfg.min_rel_improvement and p < cfg.alpha and dbic <= -cfg.min_delta_bic)
    return Comparison(
        rel_improvement=float(rel),
        z=z,
        p_value=p,
        units_improved=int(improved),
        n_units=int(labels.size),
        delta_bic=float(dbic),
        significant=sig,
    )


#: Effects whose only signature is the input speed: on a recording where the speed is
#: a function of the input level they fit as well as a static (rate-independent) shape
#: (each effect's ``rate`` flag, :class:`~i2ris_calib.hysteresis.effects.Effect`).
RATE_EFFECTS = tuple(name for name, e in CATALOGUE.items() if e.rate)

#: The recording that separates a rate effect from a static shape.
SPEED_EXPERIMENT = (
    "record the same amplitude at two or more speeds (e.g. the same sine at 0.2 and 2 Hz, "
    "or ramps at three speeds to one level): a rate effect changes the loop with the "
    "speed, a static shape does not"
)

#: Pooled within-level spread of the speed (relative to its mean) below which the
#: speed counts as a function of the level (one speed per level on each branch).
SPEED_SPREAD_LIMIT = 0.15


def speed_level_spread(signals, mask: np.ndarray, n_bins: int = 20) -> float:
    """How much the input speed varies at one input level, relative to its mean.

    On each branch (rising, falling input; moving samples in ``mask``), the input
    range is cut into ``n_bins`` levels; the pooled standard deviation of
    ``|dv/dt|`` within a level is divided by the branch's mean speed, and the larger
    of the two branches is returned. Near 0: the speed is a function of the level
    (one-frequency sine, constant-speed triangle), so rate effects cannot be told
    from a static shape. NaN without sample times or without motion.

    Parameters
    ----------
    signals : Signals
        ``v`` and ``t_s``, shape (n,).
    mask : ndarray of bool, shape (n,)
        Samples that count.
    n_bins : int
        Input levels per branch.
    """
    from i2ris_calib.hysteresis.effects import RATE_WINDOW_S, _speed

    if signals.t_s is None:
        return float("nan")
    v = np.asarray(signals.v, float)
    speed = _speed(signals, RATE_WINDOW_S)
    slope = np.gradient(v, np.asarray(signals.t_s, float))
    top = float(np.quantile(speed[mask], 0.95)) if mask.any() else 0.0
    if top <= 0:
        return float("nan")
    moving = mask & (speed > 0.05 * top)
    spreads = []
    for branch in (slope > 0, slope < 0):
        sel = moving & branch
        if sel.sum() < 3 * n_bins:
            continue
        vb, sb = v[sel], speed[sel]
        edges = np.linspace(vb.min(), vb.max(), n_bins + 1)
        idx = np.clip(np.digitize(vb, edges) - 1, 0, n_bins - 1)
        ss, dof = 0.0, 0
        for b in range(n_bins):
            s = sb[idx == b]
            if s.size >= 2:
                ss += float(np.sum((s - s.mean()) ** 2))
                dof += s.size - 1
        if dof:
            spreads.append(np.sqrt(ss / dof) / float(sb.mean()))
    return float(max(spreads)) if spreads else float("nan")


def speed_follows_level(signals, mask: np.ndarray) -> bool:
    """True when the input's speed is a function of its level on both branches
    (:func:`speed_level_spread` below ``SPEED_SPREAD_LIMIT``)."""
    return bool(speed_level_spread(signals, mask) < SPEED_SPREAD_LIMIT)
