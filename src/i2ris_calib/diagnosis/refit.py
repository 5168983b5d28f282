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

from i2ris_calib.fitting.fit import _analytic_jacobian
from i2ris_calib.model import Model, Signals


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


def exact_jacobian(model: Model, signals: Signals, rows: np.ndarray, cols: np.ndarray):
    """The model's exact Jacobian restricted to ``rows`` and ``cols``, as a function
    of the full parameter vector, or None when the model has none.

    Parameters
    ----------
    model : Model
    signals : Signals
        Shape (n,) each.
    rows : ndarray of int, shape (k,)
        Samples that enter the cost.
    cols : ndarray of int, shape (c,)
        Free parameters, in the order of the fitted vector.

    Returns
    -------
    callable or None
        ``jac(x)`` with ``x`` shape (p,), returning d output / d x[cols] (deg per
        unit) at ``rows``, shape (k, c), non-finite entries set to 0.
    """
    jac_fn = _analytic_jacobian(model)
    if jac_fn is None:
        return None
    if hasattr(model, "exact_jacobian"):  # an EffectModel: only the free columns built

        def some(x):
            return model.exact_jacobian(signals, x, rows=rows, cols=cols)

    else:
        whole = cols.size == len(model.parameters)

        def some(x):
            jac = np.asarray(jac_fn(signals, x, rows=rows), dtype=float)
            return jac if whole else jac[:, cols]

    def jac(x: np.ndarray) -> np.ndarray:
        with np.errstate(over="ignore", invalid="ignore"):
            j = some(x)
        return j if np.isfinite(j.sum()) else np.where(np.isfinite(j), j, 0.0)

    return jac


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
        Cap on model evaluations (the Jacobian's not counted).

    Notes
    -----
    A model with an exact Jacobian (:func:`exact_jacobian`: GPI, EGPI, the
    two-tendon models and effects over them) gives it to the solver; others
    get forward differences, one evaluation per free parameter.
    """
    x0 = clip_into_bounds(model, x0)
    fixed = np.array([p.fixed for p in model.parameters], dtype=bool)
    free = ~fixed if free is None else (np.asarray(free, bool) & ~fixed)
    if not free.any():
        return Refit(x0, sse(model, signals, theta, mask, x0), 0, 1)
    lo, hi = _bounds(model)
    base = x0.copy()
    target = theta[mask]

    def full(xf: np.ndarray) -> np.ndarray:
        x = base.copy()
        x[free] = xf
        return x

    def resid(xf: np.ndarray) -> np.ndarray:
        r = model.evaluate(signals, full(xf))[mask] - target
        return np.where(np.isfinite(r), r, 1e6)

    exact = exact_jacobian(model, signals, np.flatnonzero(mask), np.flatnonzero(free))
    jac = "2-point" if exact is None else (lambda xf: exact(full(xf)))

    try:
        sol = least_squares(
            resid,
            x0[free],
            jac=jac,
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
