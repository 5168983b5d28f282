"""Error metrics exactly as the paper's Eq25-27, and the Gaussian information criteria."""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np


@dataclass(frozen=True)
class Metrics:
    """Fit quality (Eq25-27).

    Attributes
    ----------
    rmse_deg : float
        Root-mean-square error (deg), Eq25.
    nrmse_pct : float
        RMSE / (max(theta) - min(theta)) * 100 (%), Eq26.
    max_abs_err_deg : float
        MAXIMUM absolute error (deg); the paper calls it MAE, Eq27.
    n_samples : int
        Number of finite samples the metrics were computed on.
    explained_variance : float
        ``1 - sum(err^2) / sum((theta - mean theta)^2)``: the share of the angle's
        variance the model explains (1 perfect, 0 no better than a constant, NaN when
        the angle is constant). Not in the paper; a fit can have a small RMSE and
        explain nothing (an angle column of noise around a constant).
    p99_abs_err_deg : float
        99th percentile of the absolute error (deg): beside the RMSE and the maximum,
        so one sample (an onset, a tracking glitch) can be told from a general misfit.
    rmse_without_worst_deg : float
        The RMSE with the single worst sample left out (deg).
    """

    rmse_deg: float
    nrmse_pct: float
    max_abs_err_deg: float
    n_samples: int = 0
    explained_variance: float = float("nan")
    p99_abs_err_deg: float = float("nan")
    rmse_without_worst_deg: float = float("nan")

    def as_dict(self) -> dict[str, float]:
        """``{"rmse_deg", "nrmse_pct", "max_abs_err_deg", "explained_variance",
        "p99_abs_err_deg", "rmse_without_worst_deg"}`` (fit.json)."""
        d = asdict(self)
        d.pop("n_samples")
        return d


NAN_METRICS = Metrics(float("nan"), float("nan"), float("nan"), 0)


def metrics(
    theta_deg: np.ndarray, predicted_deg: np.ndarray, mask: np.ndarray | None = None
) -> Metrics:
    """RMSE, NRMSE and max |error| (Eq25-27) over samples where both are finite.

    Parameters
    ----------
    theta_deg, predicted_deg : ndarray, shape (n,)
        Measured and modelled angle (deg).
    mask : ndarray of bool, shape (n,), optional
        Restrict to these samples (e.g. the held-out cycles).

    Returns
    -------
    Metrics
        All NaN (n_samples = 0) when no sample is usable; NRMSE is NaN when the
        measured range is zero.
    """
    theta = np.asarray(theta_deg, dtype=float)
    pred = np.asarray(predicted_deg, dtype=float)
    ok = np.isfinite(theta) & np.isfinite(pred)
    if mask is not None:
        ok &= np.asarray(mask, dtype=bool)
    if not ok.any():
        return NAN_METRICS
    err = pred[ok] - theta[ok]
    rmse = float(np.sqrt(np.mean(err**2)))
    span = float(theta[ok].max() - theta[ok].min())
    nrmse = rmse / span * 100.0 if span > 0 else float("nan")
    tss = float(np.sum((theta[ok] - theta[ok].mean()) ** 2))
    ev = 1.0 - float(np.sum(err**2)) / tss if tss > 0 else float("nan")
    a = np.abs(err)
    rest = np.delete(err, int(np.argmax(a)))
    without = float(np.sqrt(np.mean(rest**2))) if rest.size else float("nan")
    p99 = float(np.percentile(a, 99.0))
    return Metrics(rmse, nrmse, float(a.max()), int(ok.sum()), ev, p99, without)


def information_criteria(rss: float, n: int, k: int) -> tuple[float, float]:
    """Gaussian AIC and BIC of a least-squares fit.

    ``AIC = n ln(RSS/n) + 2k`` and ``BIC = n ln(RSS/n) + k ln n`` (the constant terms
    of the Gaussian log-likelihood dropped, so only differences between fits on the
    same samples mean anything).

    Parameters
    ----------
    rss : float
        Residual sum of squares over the fitted samples (deg^2). A zero RSS is taken
        as 1e-300 so the criteria stay finite.
    n : int
        Number of fitted samples (> 0).
    k : int
        Number of free parameters.

    Returns
    -------
    aic, bic : float
    """
    ln = n * np.log(max(float(rss), 1e-300) / n)
    return float(ln + 2 * k), float(ln + k * np.log(n))
