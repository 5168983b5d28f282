"""Fast bounded least-squares refits of an (extended) model on a subset of samples.

The diagnosis fits ~7 candidates per step, each starting from the current fitted
model, so it needs a warm-started local fit rather than the global multi-start
fit of the fitting stage: scipy's trust-region-reflective least squares
(``least_squares(method="trf")``, which honours the declared bounds and reduces
to Levenberg-Marquardt steps in the interior) with a capped number of
evaluations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from i2ris_calib.hysteresis.model import Model, Signals


@dataclass(frozen=True)
class Refit:
    """Result of :func:`refit`.

    Attributes
    ----------
    values : ndarray, shape (p,)
        Fitted parameter vector (fixed entries unchanged).
    sse_deg2 : float
        Sum of squared residuals on the fitted samples (deg^2).
    n_free : int
        Number of parameters that were free.
    nfev : int
        Model evaluations used.
    """

    values: np.ndarray
    sse_deg2: float
    n_free: int
    nfev: int


def _bounds(model: Model) -> tuple[np.ndarray, np.ndarray]:
    lo = np.array([p.lower for p in model.parameters], dtype=float)
    hi = np.array([p.upper for p in model.parameters], dtype=float)
    return lo, hi


def clip_into_bounds(model: Model, values: np.ndarray) -> np.ndarray:
    """``values`` moved strictly inside the declared bounds (for trf starts)."""
    lo, hi = _bounds(model)
    width = np.where(np.isfinite(hi - lo), hi - lo, 1.0)
    eps = 1e-9 * np.maximum(width, 1.0)
    return np.clip(np.asarray(values, float), lo + eps, hi - eps)


def sse(model: Model, signals: Signals, theta: np.ndarray, mask: np.ndarray, values) -> float:
    """Sum of squared residuals (deg^2) of ``model`` at ``values`` on ``mask``."""
    r = model.evaluate(signals, np.asarray(values, float))[mask] - theta[mask]
    s = float(np.dot(r, r))
    return s if np.isfinite(s) else np.inf


def refit(
    model: Model,
    signals: Signals,
    theta: np.ndarray,
    mask: np.ndarray,
    x0: np.ndarray,
    free: np.ndarray | None = None,
    max_nfev: int = 200,
) -> Refit:
    """Least-squares fit of ``model`` to ``theta`` on the samples in ``mask``.

    The model is always evaluated over the whole signal (its hysteresis state
    depends on the full input history); only residuals on ``mask`` count.

    Parameters
    ----------
    model : Model
    signals : Signals
        Shape (n,) each.
    theta : ndarray, shape (n,)
        Measured angle (deg).
    mask : ndarray of bool, shape (n,)
        Samples that enter the cost.
    x0 : ndarray, shape (p,)
        Start vector.
    free : ndarray of bool, shape (p,), optional
        Parameters to fit; default all not declared ``fixed``.
    max_nfev : int
        Cap on model evaluations.
    """
    x0 = clip_into_bounds(model, x0)
    fixed = np.array([p.fixed for p in model.parameters], dtype=bool)
    free = ~fixed if free is None else (np.asarray(free, bool) & ~fixed)
    if not free.any():
        return Refit(x0, sse(model, signals, theta, mask, x0), 0, 1)
    lo, hi = _bounds(model)
    base = x0.copy()
    target = theta[mask]

    def resid(xf: np.ndarray) -> np.ndarray:
        x = base.copy()
        x[free] = xf
        r = model.evaluate(signals, x)[mask] - target
        return np.where(np.isfinite(r), r, 1e6)

    try:
        sol = least_squares(
            resid,
            x0[free],
            bounds=(lo[free], hi[free]),
            method="trf",
            x_scale="jac",
            max_nfev=max_nfev,
            tr_solver="lsmr",
        )
        x = base.copy()
        x[free] = sol.x
        nfev = int(sol.nfev)
    except (ValueError, FloatingPointError):
        x, nfev = x0, 1
    s = sse(model, signals, theta, mask, x)
    s0 = sse(model, signals, theta, mask, x0)
    if s0 < s:
        x, s = x0, s0
    return Refit(x, s, int(free.sum()), nfev)
