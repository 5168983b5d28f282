"""Levenberg-Marquardt fitting of hysteresis models (Eq24), robust to poor starts.

:func:`fit_model` minimises ``L = sum_k (y[k] - theta[k])^2`` over the free
parameters by Levenberg-Marquardt (``method="lm"``: Moré's algorithm as MINPACK's
``lmder``, :func:`~i2ris_calib.fitting.lm.least_squares_lm`, unbounded, as the paper;
``"trf"``: scipy's bounded trust region),
from several data-driven starts (:mod:`i2ris_calib.hysteresis.start`), keeping the best. A free flag
point ``v_f`` is fitted by a profile search (the output is piecewise constant in
v_f, so finite-difference derivatives are useless): a grid over v_f with the other
parameters fixed, then LM again, repeated. NaN angles leave the loss but the model
always runs over the whole input sequence (the operator state needs every sample).

Speed: a model that defines ``jacobian`` (with the ``evaluate`` it differentiates; GPI,
EGPI, EGPI_C) gives LM its exact Jacobian in one pass instead of one finite-difference
evaluation per free parameter; one that defines ``flag_point_families`` (the paper EGPI)
gives the flag-point profile every candidate v_f from one model run. Both give the
values ``evaluate`` gives (the profile to the last bit), so the fit is the same search.

The fitted result is a new object (:class:`~i2ris_calib.fitting.result.FitResult`); the
input model is never changed. A recording that does not start at rest gets its start
state from :mod:`~i2ris_calib.fitting.prehistory`; how a fit is shown (report, HTML,
plot) is :mod:`~i2ris_calib.fitting.present`.
"""

from __future__ import annotations

import functools
import inspect
import itertools
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import OptimizeResult, least_squares
from threadpoolctl import threadpool_limits

from i2ris_calib._validate import (
    as_1d_bool,
    as_1d_float,
    as_real,
    check_choice,
    check_model,
    check_signals,
    describe,
)
from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.lm import least_squares_lm
from i2ris_calib.fitting.metrics import NAN_METRICS, information_criteria, metrics

# A name imported as itself (`x as x`) is re-exported: the start state and its synthetic
# pre-history moved to fitting/prehistory.py, the result to fitting/result.py (issue 34);
# `from i2ris_calib.fitting.fit import ...` of every name still works.
from i2ris_calib.fitting.prehistory import LEVEL_MARGIN as LEVEL_MARGIN
from i2ris_calib.fitting.prehistory import MAX_PREHISTORY as MAX_PREHISTORY
from i2ris_calib.fitting.prehistory import ORIGIN as ORIGIN
from i2ris_calib.fitting.prehistory import REST_TOLERANCE as REST_TOLERANCE
from i2ris_calib.fitting.prehistory import (
    InitialState,
    _FromLevel,
    opening_cycle,
    prehistory_step,
    signals_start_at_rest,
    state_levels,
    state_own_levels,
    state_text,
)
from i2ris_calib.fitting.prehistory import _head_of as _head_of
from i2ris_calib.fitting.prehistory import _other_first as _other_first
from i2ris_calib.fitting.prehistory import _ramp_padded as _ramp_padded
from i2ris_calib.fitting.prehistory import _ramped as _ramped
from i2ris_calib.fitting.prehistory import _staircase as _staircase
from i2ris_calib.fitting.prehistory import _with_cycle as _with_cycle
from i2ris_calib.fitting.prehistory import innermost as innermost
from i2ris_calib.fitting.prehistory import level_bounds as level_bounds
from i2ris_calib.fitting.prehistory import prehistory_signals as prehistory_signals
from i2ris_calib.fitting.prehistory import reads_other_state as reads_other_state
from i2ris_calib.fitting.prehistory import starts_at_rest as starts_at_rest
from i2ris_calib.fitting.result import (
    CERTIFIED_AT,
    SAME_MINIMUM,
    FitNote,
    FitResult,
    SearchCertificate,
)
from i2ris_calib.fitting.result import NEAR_MINIMUM as NEAR_MINIMUM
from i2ris_calib.fitting.result import _ratio_text as _ratio_text
from i2ris_calib.fitting.result import fit_notices as fit_notices
from i2ris_calib.hysteresis.kernel import ordered_sum
from i2ris_calib.hysteresis.models import as_signals
from i2ris_calib.model import Model, Signals
from i2ris_calib.model import analytic_method as _analytic_jacobian

PROFILE_PARAMS = ("v_f",)
_BIG = 1e6


#: Levels scanned for the initial state before the first fit (then refined by profile).
INITIAL_STATE_GRID = 41


def _method_of(model, method: str):
    """:func:`_analytic_jacobian`, seeing through :class:`_FromLevel`."""
    if isinstance(model, _FromLevel):
        inner = model.jac_inner if method == "jacobian" else model.families_inner
        return None if inner is None else getattr(model, method)
    return _analytic_jacobian(model, method)


class _Counter:
    def __init__(self, model, signals, theta, used, loss="linear", f_scale=1.0):
        self.model, self.signals, self.theta, self.used = model, signals, theta, used
        self.loss, self.f_scale = loss, float(f_scale)
        self.n = 0
        self.jac_fn = _method_of(model, "jacobian")
        self.families_fn = _method_of(model, "flag_point_families")
        names = [p.name for p in model.parameters]
        self.vf_index = names.index("v_f") if "v_f" in names else -1
        self.used_idx = np.flatnonzero(used)
        self.theta_used = theta[self.used_idx]
        # parameters whose Jacobian column is a forward difference of this step (a flag
        # point the output is continuous in: the model's exact column is 0 there)
        inner = model.inner if isinstance(model, _FromLevel) else model
        self.fd_idx = (
            [self.vf_index] if self.vf_index >= 0 and getattr(inner, "CONTINUOUS_FLAG_POINT", False) else []
        )  # fmt: skip
        self.fd_step = 0.5 * prehistory_step(np.asarray(signals.v, dtype=float))

    def cost(self, full: np.ndarray) -> float:
        """Sum of rho(r^2) over the fitted samples (rho as scipy's least_squares)."""
        return self._rho_sum(self.residuals(full))

    def held_cost(self, full: np.ndarray, idx: int):
        """The cost as a function of parameter ``idx`` alone, the others held at
        ``full``. For a model whose flag point only switches between two fixed outputs
        (``flag_point_families``, the paper's EGPI) one model run serves every value;
        for the initial-state level of a model with terms of the other motor's input
        (:meth:`_FromLevel.level_output`) those are computed once; the costs are the
        same to the last bit as :meth:`cost`."""
        if (
            isinstance(self.model, _FromLevel)
            and idx >= len(self.model.parameters) - self.model.n_own
        ):
            # the own levels (the other motor's: the generic cost below)
            output = self.model.level_output(self.signals, full, idx)
            if output is not None:
                return self._output_cost(output)
        if self.families_fn is not None and idx == self.vf_index:
            self.n += 1
            u = self.used_idx
            y1, y2, unloading = (a[u] for a in self.families_fn(self.signals, full))
            vu = np.asarray(self.signals.v)[u]

            def flag_cost(x):
                r = np.where(unloading & (vu <= x), y2, y1) - self.theta_used
                return self._rho_sum(
                    r if np.isfinite(r).all() else np.where(np.isfinite(r), r, _BIG)
                )

            return flag_cost

        def cost(x):
            trial = full.copy()
            trial[idx] = x
            return self.cost(trial)

        return cost

    def _output_cost(self, output):
        """``x -> cost`` of the model output ``output(x)`` (counted as evaluations, the
        residuals as :meth:`residuals` makes them)."""

        def cost(x):
            self.n += 1
            with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                r = output(x)[self.used_idx] - self.theta_used
            return self._rho_sum(r if np.isfinite(r).all() else np.where(np.isfinite(r), r, _BIG))

        return cost

    def _rho_sum(self, r: np.ndarray) -> float:
        z = (r / self.f_scale) ** 2
        if self.loss == "soft_l1":
            z = 2.0 * (np.sqrt(1.0 + z) - 1.0)
        elif self.loss == "huber":
            z = np.where(z <= 1.0, z, 2.0 * np.sqrt(z) - 1.0)
        return float(ordered_sum(np.ascontiguousarray(z, dtype=float)) * self.f_scale**2)

    def residuals(self, full: np.ndarray) -> np.ndarray:
        self.n += 1
        # a trial point may overflow (inf - inf): such residuals are replaced below, so
        # numpy's warning would only reach the user's terminal as noise
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            y = self.model.evaluate(self.signals, full)
            r = y[self.used_idx] - self.theta_used
        return r if np.isfinite(r).all() else np.where(np.isfinite(r), r, _BIG)

    def _with_differences(self, full, jac, cols) -> np.ndarray:
        """``jac`` with the columns of :attr:`fd_idx` replaced by forward differences."""
        order = list(range(jac.shape[1])) if cols is None else [int(c) for c in cols]
        todo = [(order.index(i), i) for i in self.fd_idx if i in order]
        if not todo:
            return jac
        jac = np.array(jac, dtype=float)
        base = self.residuals(full)
        for col, i in todo:
            trial = np.asarray(full, dtype=float).copy()
            trial[i] += self.fd_step
            jac[:, col] = (self.residuals(trial) - base) / self.fd_step
        return jac

    def jacobian(self, full: np.ndarray, cols: np.ndarray | None = None) -> np.ndarray:
        """d residual / d parameters at the fitted samples, shape (n_used, p) (the
        model's exact Jacobian; counted as one evaluation); ``cols``: only those
        columns (the free ones, in that order), shape (n_used, len(cols))."""
        self.n += 1
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):  # as residuals
            if (
                cols is not None
                and isinstance(self.model, _FromLevel)
                and (np.asarray(cols) < len(self.model.parameters) - self.model.levels).all()
            ):
                # the profiled level's zero column is never asked for: not built
                jac = self.model.inner_jacobian(self.signals, full, rows=self.used_idx)
            else:
                jac = self.jac_fn(self.signals, full, rows=self.used_idx)
                if isinstance(self.model, _FromLevel):
                    self.n += 1  # the levels' differences over the opening (about one run)
        if cols is not None and not (
            len(cols) == jac.shape[1] and np.array_equal(cols, np.arange(jac.shape[1]))
        ):
            jac = jac[:, cols]
        if self.fd_idx:
            jac = self._with_differences(full, jac, cols)
        # one sum tells whether every entry is finite (an overflow to inf is only rechecked)
        return jac if np.isfinite(jac.sum()) else np.where(np.isfinite(jac), jac, 0.0)


def _validate(signals: Signals, theta: np.ndarray, n_free: int, used: np.ndarray) -> None:
    v = np.asarray(signals.v, dtype=float)
    if v.ndim != 1 or theta.shape != v.shape:
        raise CalibError(
            f"fit: input has {v.shape} samples but angle has {theta.shape}; give one angle per input sample"
        )
    if not np.all(np.isfinite(v)):
        raise CalibError(
            "fit: the input contains NaN/inf; remove or interpolate those rows before fitting"
        )
    if np.ptp(v) == 0:
        raise CalibError(
            "fit: the input is constant; a hysteresis model needs the input to move (check the axis/column)"
        )
    if used.sum() <= n_free:
        raise CalibError(
            f"fit: only {int(used.sum())} usable samples for {n_free} free parameters; record more data or fix parameters"
        )


#: Relative step of the forward differences of a model without an exact Jacobian
#: (scipy's ``2-point`` rule: sqrt(eps) x max(1, |x|)).
FD_REL_STEP = float(np.sqrt(np.finfo(float).eps))


def _forward_jacobian(fun):
    """``jac(x)``: forward differences of ``fun`` at ``x``, shape (m, n) (scipy's
    ``2-point`` steps, :data:`FD_REL_STEP`; ``n + 1`` evaluations)."""

    def jac(x):
        x = np.asarray(x, dtype=float)
        f0 = fun(x)
        out = np.empty((f0.size, x.size))
        for j in range(x.size):
            h = FD_REL_STEP * max(1.0, abs(x[j])) * (1.0 if x[j] >= 0 else -1.0)
            xj = x.copy()
            xj[j] += h
            out[:, j] = (fun(xj) - f0) / (xj[j] - x[j])
        return out

    return jac


def _lsq(counter, x0_full, free, lower, upper, method, max_nfev, ftol):
    def fun(x):
        full = x0_full.copy()
        full[free] = x
        return counter.residuals(full)

    jac = "2-point"
    if counter.jac_fn is not None:
        # the model's exact Jacobian: one pass instead of one evaluation per free
        # parameter (the finite-difference columns were ~80 % of a fit's time)
        def jac(x):
            full = x0_full.copy()
            full[free] = x
            return counter.jacobian(full, free)

    x0 = x0_full[free]
    if method == "trf":
        lo, hi = lower[free], upper[free]
        x0 = np.clip(x0, lo + 1e-12 * np.abs(lo), hi - 1e-12 * np.abs(hi))
        res = least_squares(
            fun,
            x0,
            jac=jac,
            bounds=(lo, hi),
            method="trf",
            x_scale="jac",
            max_nfev=max_nfev,
            ftol=ftol,
            loss=counter.loss,
            f_scale=counter.f_scale,
        )
    elif method == "lm":
        # every LM run is the project's own (fitting/lm.py), never scipy's MINPACK:
        # scipy's lmder took different steps from the same residuals and Jacobian in
        # different processes (tests/fitting/test_determinism.py)
        jac = jac if callable(jac) else _forward_jacobian(fun)
        res = least_squares_lm(fun, jac, x0, max_nfev=max_nfev, ftol=ftol)
    else:
        raise CalibError(f"fit: unknown method '{method}'; use 'lm' or 'trf'")
    full = x0_full.copy()
    full[free] = res.x
    return full, res


def _profile(counter, full, idx, grid, cost=None):
    """Best value of parameter ``idx`` on ``grid`` with the others held; returns (value, cost).
    ``cost``: :meth:`_Counter.held_cost` of ``full`` and ``idx`` (made here by default)."""
    cost = counter.held_cost(full, idx) if cost is None else cost
    best = (full[idx], cost(full[idx]))
    for g in grid:
        c = cost(g)
        if c < best[1]:
            best = (g, c)
    return best


def _refine_level(counter, full, idx, lower, upper, wide=True):
    """Profile search over the initial-state level ``v_from`` (index ``idx``), the
    others held: ``wide``, ``INITIAL_STATE_GRID`` levels over its whole range (a motor's
    last level also close to its first input, :func:`_near_first`); else 21 levels
    within +-2.5 % of the range around the current one. Never worse."""
    lo, hi = lower[idx], upper[idx]
    if wide:
        grid = np.linspace(lo, hi, INITIAL_STATE_GRID)
        grid = np.concatenate([grid, _near_first(counter.model, counter.signals, idx, lo, hi)])
    else:
        h = 0.025 * (hi - lo)
        grid = np.clip(np.linspace(full[idx] - h, full[idx] + h, 21), lo, hi)
    best, _ = _profile(counter, full, idx, grid)
    full = full.copy()
    full[idx] = best
    return full


def _near_first(model, signals: Signals, idx: int, lo: float, hi: float) -> np.ndarray:
    """Levels close to the first input, for the last level of a motor's pre-history
    (``v_from``, ``other_v_from`` of :class:`_FromLevel`; empty for every other
    parameter): the first input +- the pre-history's step x 1, 2, 4, ... up to the
    wide grid's spacing, within the bounds.

    The last level is the last reversal before the recording; the operators it sets are
    those narrower than its distance from the first input, and a recording that starts
    while the input moves has its last reversal anywhere from a few samples back to a
    loop away. The wide grid (:data:`INITIAL_STATE_GRID` levels) cannot place a reversal
    a few samples back, and the fine one only moves around where the level is (measured
    on agpi_coupled:7 of bench_optimum: the other motor had turned 19 counts before the
    recording, the grid's spacing 361; every start arrived from its far side, the fit
    ended at 1.0010 x the truth's cost; from the reversal 20 counts back, below it)."""
    if not isinstance(model, _FromLevel):
        return np.empty(0)
    n = len(model.parameters)
    if idx == n - 1:
        v0, step = float(np.asarray(signals.v)[0]), model.step
    elif model.n_other and idx == n - model.n_own - 1:
        v0, step = float(np.asarray(signals.v_other)[0]), model.other_step
    else:
        return np.empty(0)
    spacing = (hi - lo) / (INITIAL_STATE_GRID - 1)
    if not (np.isfinite(v0) and step > 0 and spacing > step):
        return np.empty(0)
    d = step * 2.0 ** np.arange(int(np.floor(np.log2(spacing / step))) + 1)
    near = np.concatenate([v0 - d, v0 + d])
    return near[(near >= lo) & (near <= hi)]


def _refine_profiled(counter, full, pidx, v, lower, upper, wide=True):
    """Profile search over each profiled parameter (v_f), the others held.

    ``wide``: a grid over +-20 % of the input range in 1 % steps around the current
    value. Always then: the exact step - the cost only changes where v_f crosses an
    input value of a fitted sample, so every midpoint between consecutive distinct
    fitted input values within +-1 % of the range (and one more on each side, so the
    interval holding the current value is a candidate) is tried, and among equal best
    costs the middle candidate is kept (the centre of the interval the data allow). The
    result is never worse than the current value.
    """
    span = float(np.ptp(v))
    vals = np.unique(v[counter.used])
    for idx in pidx:
        lo, hi = max(lower[idx], v.min()), min(upper[idx], v.max())
        cost = counter.held_cost(full, idx)  # only parameter idx changes below
        if wide:
            grid = np.clip(np.linspace(full[idx] - 0.2 * span, full[idx] + 0.2 * span, 41), lo, hi)
            best, _ = _profile(counter, full, idx, grid, cost)
            full = full.copy()
            full[idx] = best
        # the fitted input values within +-1 % of the range, and one more on each side:
        # the interval holding the current value is always among the candidates
        k0 = int(np.searchsorted(vals, full[idx] - 0.01 * span, "left"))
        k1 = int(np.searchsorted(vals, full[idx] + 0.01 * span, "right"))
        near = vals[max(k0 - 1, 0) : min(k1 + 1, vals.size)]
        if near.size < 2:
            continue
        cands = 0.5 * (near[1:] + near[:-1])
        costs = np.array([cost(c) for c in cands])
        if costs.min() > cost(full[idx]) * (1 + 1e-12):
            continue  # never worse than where it is
        tied = np.flatnonzero(costs <= costs.min() * (1 + 1e-12))
        run = tied[np.concatenate(([0], np.flatnonzero(np.diff(tied) > 1) + 1))[0] :]
        run = run[: np.argmax(np.diff(np.append(run, run[-1] + 2)) > 1) + 1]
        full = full.copy()
        full[idx] = 0.5 * (cands[run[0]] + cands[run[-1]])
    return full


REOPT_STEPS = (-0.04, -0.02, -0.01, -0.005, 0.005, 0.01, 0.02, 0.04)


def _reoptimised_profile(counter, full, pidx, lsq_free, v, lower, upper, how, nfev, ftol):
    """Move each profiled parameter (v_f) to the best of a few nearby values (``REOPT_STEPS``
    x the input range) with the other parameters re-optimised by a short LM at each.

    The held profile of :func:`_refine_profiled` keeps the other parameters fixed, so a
    flag point a little off is held there by the envelope offsets that compensate for
    it (measured on continuous-EGPI truths: v_f 20-200 counts low, cost above the
    truth's). Returns the best parameter vector (the input one when nothing is better).
    """
    span = float(np.ptp(v))
    best_cost, best = counter.cost(full), full
    for idx in pidx:
        base = best.copy()
        for step in REOPT_STEPS:
            trial = base.copy()
            trial[idx] = float(np.clip(base[idx] + step * span, lower[idx], upper[idx]))
            if trial[idx] == base[idx]:
                continue
            cand, _ = _lsq(counter, trial, lsq_free, lower, upper, how, nfev, ftol)
            c = counter.cost(cand)
            if c < best_cost * (1 - 1e-9):  # a real improvement, not rounding
                best_cost, best = c, cand
    return best


def _check_args(model, signals, theta_deg, fit_mask, holdout_mask, starts, method, max_nfev,
                screen_nfev, ftol, loss, f_scale_deg) -> None:  # fmt: skip
    """CalibError naming the argument of :func:`fit_model` on a misuse (the shape and
    finiteness of the data are :func:`_validate`'s, after the masks are combined)."""
    func = "fit_model"
    check_model(func, "model", model, usage="fit_model(model, signals, theta_deg)")
    if isinstance(signals, Signals):
        check_signals(func, "signals", signals)
        n = np.asarray(signals.v).size
    else:
        n = as_1d_float(func, "signals", signals, finite=False).size
    as_1d_float(func, "theta_deg", theta_deg, finite=False)
    for name, mask in (("fit_mask", fit_mask), ("holdout_mask", holdout_mask)):
        if mask is not None:
            as_1d_bool(func, name, mask, n)
    if starts is not None:
        if isinstance(starts, np.ndarray) and starts.ndim == 1:
            raise CalibError(
                f"{func}: starts is one vector; give a list of start vectors, e.g. [x0]"
            )
        if not isinstance(starts, (list, tuple, np.ndarray)):
            raise CalibError(f"{func}: starts is {describe(starts)}; give a list of vectors")
        p = len(model.parameters)
        for i, x0 in enumerate(starts):
            as_1d_float(func, f"starts[{i}]", x0, size=p, finite=False)
    check_choice(func, "method", method, ("lm", "trf"))
    check_choice(func, "loss", loss, ("linear", "soft_l1", "huber"))
    as_real(func, "max_nfev", max_nfev, integer=True, lo=1, none_ok=True)
    as_real(func, "screen_nfev", screen_nfev, integer=True, lo=1)
    as_real(func, "ftol", ftol, lo=0.0, lo_open=True)
    as_real(func, "f_scale_deg", f_scale_deg, lo=0.0, lo_open=True)


def fit_model(*args, **kwargs) -> FitResult:
    # BLAS is limited to one thread for the duration: the Jacobians are tall and thin
    # (n samples x p <= 13), where threads only add overhead, and on a busy 2-core
    # machine OpenBLAS threads made scipy's trf 7x slower (SVD of a 25k x 8 Jacobian:
    # 66 ms instead of 2 ms per iteration). The docstring is _fit_model's.
    with threadpool_limits(limits=1, user_api="blas"):
        res = _fit_model(*args, **kwargs)
    # the first start, for FitResult.parameters (the model's values unless starts given)
    bound = inspect.signature(_fit_model).bind(*args, **kwargs).arguments
    names = [p.name for p in bound["model"].parameters]
    x0 = bound.get("starts") or [[p.value for p in bound["model"].parameters]]
    return replace(res, start=dict(zip(names, map(float, x0[0]), strict=True)))


def _fit_model(
    model: Model,
    signals: Signals | np.ndarray,
    theta_deg: np.ndarray,
    *,
    fit_mask: np.ndarray | None = None,
    holdout_mask: np.ndarray | None = None,
    starts: list[np.ndarray] | None = None,
    method: str = "lm",
    max_nfev: int | None = 300,
    screen_nfev: int = 20,
    ftol: float = 1e-7,
    loss: str = "linear",
    f_scale_deg: float = 0.5,
    nested: bool = True,
    initial_state: str = "auto",
    basin_hops: int | None = None,
) -> FitResult:
    """Fit ``model`` to measured angles by least squares (Eq24).

    Parameters
    ----------
    model : Model
        Model with parameter declarations (values = default start, fixed flags, bounds).
    signals : Signals or ndarray, shape (n,)
        Input (counts); a bare array is taken as ``Signals(v=...)``.
    theta_deg : ndarray, shape (n,)
        Measured angle (deg); NaN samples leave the loss.
    fit_mask, holdout_mask : ndarray of bool, shape (n,), optional
        Samples used in the loss (default: all finite ones not held out) and held-out
        samples (metrics only).
    starts : list of ndarray, shape (p,), optional
        Start vectors (all parameters, model order); default ``[model values]``.
        Use :func:`i2ris_calib.hysteresis.start.start_values` (or ``model.guess``) for
        data-driven starts.
    method : {"lm", "trf"}
        Levenberg-Marquardt (unbounded; an end point outside the bounds is refitted
        bounded by trf from inside them) or bounded trust-region reflective. Either
        way the result is never worse (in cost) than the best start inside the bounds.
    max_nfev : int, optional
        Limit on LM iterations (function evaluations not counting the finite-difference
        Jacobian, scipy >= 1.16) of each LM call of the final run; the result is flagged
        not converged when hit.
    screen_nfev : int
        With several starts, each first gets LM runs limited to this many
        iterations (a model without a flag point: on every k-th fitted sample when
        there are more than :data:`SCREEN_ROWS`); only the best is run to
        convergence, on every fitted sample.
    ftol : float
        Relative cost-reduction tolerance of ``least_squares``.
    loss : {"linear", "soft_l1", "huber"}
        ``"linear"`` is Eq24 (plain least squares). The robust losses down-weight
        residuals beyond ``f_scale_deg`` (e.g. tracking outliers); they need
        ``method="trf"``. Metrics are always Eq25-27 on every sample.
    nested : bool
        For a model that extends another (``model.nested()`` gives the wrapped model
        and the values that switch the extension off, e.g. an effect added by
        :func:`~i2ris_calib.hysteresis.effects.add_effect`): fit the wrapped model
        first (same data and options, the wrapped part of every start) and add its
        fitted values with the extension off as a start. The result is never worse
        than that fit (the fitter never ends worse than a start inside the bounds).
    initial_state : {"auto", "rest"}
        ``"auto"``: a recording that does not start at rest (:func:`starts_at_rest`)
        gets its initial state fitted (:class:`InitialState`, reported in
        ``initial_state``); ``"rest"``: every model starts relaxed at ``v[0]``.
    basin_hops : int, optional
        Most restarts from perturbations of the best end while fewer than
        :data:`CERTIFIED_AT` starts reached the best cost (the global search,
        :func:`_global_search`); default :data:`MAX_HOPS`, fewer when they do not fit
        in :data:`WORK_BUDGET`; 0: a local search (the best screened end polished, no
        restarts: a warm refit).

    Returns
    -------
    FitResult

    Raises
    ------
    CalibError
        A misuse, naming the argument (``model`` not a model, arrays that are not 1-D,
        masks that are not bool of the input's length, starts of the wrong size, an
        unknown method or loss); shape mismatch, non-finite or constant input, fewer
        usable samples than free parameters.
    """
    _check_args(model, signals, theta_deg, fit_mask, holdout_mask, starts, method, max_nfev,
                screen_nfev, ftol, loss, f_scale_deg)  # fmt: skip
    check_choice("fit_model", "initial_state", initial_state, ("auto", "rest"))
    as_real("fit_model", "basin_hops", basin_hops, integer=True, lo=0, none_ok=True)
    s = as_signals(signals)
    v = np.asarray(s.v, dtype=float)
    theta = np.asarray(theta_deg, dtype=float)
    opts = dict(
        fit_mask=fit_mask, holdout_mask=holdout_mask, method=method, max_nfev=max_nfev,
        screen_nfev=screen_nfev, ftol=ftol, initial_state=initial_state, basin_hops=basin_hops,
    )  # fmt: skip
    hold, used = _loss_samples(theta, fit_mask, holdout_mask)
    _validate(s, theta, sum(not p.fixed for p in model.parameters), used)
    _check_loss(loss, method)
    starts = _start_vectors(model, starts)
    # a nested model: its base fitted first, with the extension off, is one more start
    inner_fit = _nested_fit(model, s, theta, starts, opts | dict(loss=loss, f_scale_deg=f_scale_deg)) if nested else None  # fmt: skip
    if inner_fit is not None:
        starts.append(inner_fit[0])
    # a recording that does not start at rest: its initial state is fitted (v_from), with
    # and without the recording's first cycle replayed before it (when it has one)
    level = initial_state == "auto" and not signals_start_at_rest(s, model)
    k = opening_cycle(v) if level else 0
    run = functools.partial(
        _searched, model, s, theta, used, hold, inner_fit, level, opts | dict(loss=loss, f_scale_deg=f_scale_deg)
    )  # fmt: skip
    if k and v.size > LARGE_ROWS:
        # a long recording: one start state, the one whose starts begin lower
        k = k if run(starts, k, probe=True) < run(starts, 0, probe=True) else 0
        out = run(starts, k)
    else:
        out = run(starts, 0)
    if k and out.cycle == 0:
        # the other start state: from the first one's end and from every start
        carried = np.asarray([out.result.params[n] for n in out.names[: len(model.parameters)]])
        other = run([carried, *starts], k, spent=out.work)
        if other.cost < out.cost:
            out = other
    if not level:
        return out.result
    return _without_level(out.result, model, v, out.full, out.cycle, s.v_other, out.n_own)


@dataclass(frozen=True)
class _Searched:
    """One search's outcome: the result (in terms of the searched model, the level last
    when fitted), its cost and end, the search's work and the replayed cycle."""

    result: FitResult
    cost: float
    full: np.ndarray
    names: tuple[str, ...]
    work: float
    cycle: int
    n_own: int = 0


def own_levels(v: np.ndarray, global_search: bool = True) -> int:
    """Own levels of the fitted pre-history (:class:`InitialState`) at most: four
    (``v_turn3``, ``v_turn2``, ``v_turn``, ``v_from``) up to :data:`FOUR_LEVEL_ROWS`
    samples, three up to :data:`LARGE_ROWS`, two (no ``v_turn2``) beyond: a long
    recording's start state weighs little against its many loops, and each level's
    profiles and Jacobian column cost time (measured on bench_speed's 50,000-sample
    coupled recording: the coupled two-tendon GPI 3.8 -> 4.8 s CPU with the third, its
    diagnose 10.8 -> 19.3 s). Two for a local search (``global_search`` False:
    ``basin_hops = 0``, e.g. sync's clock-offset profile): the third level makes the cost
    a rougher function of the other settings (measured on the rendered lab session:
    sync's offset profile lost its curvature, and its model refinement).

    The search itself runs with three; the fourth is tried at its end, over whole
    staircases from its best end (:func:`_one_level_back`), and kept when lower. A short
    recording that starts after loops of shrinking amplitude begins in a staircase of
    as many turning points as the loops its elements still remember, and there that
    opening is a large share of the cost (measured on bench_optimum's maxwell_slip:67,
    mid-loop at 5 Hz, 457 samples, and :65, 500 Hz, 3,123 samples, whose histories need
    four: 1.353x and 1.026x the truth's cost with three levels, 0.945x and 0.994x with
    the fourth).
    """
    n = np.asarray(v).size
    if not global_search or n > LARGE_ROWS:
        return 2
    return 4 if n <= FOUR_LEVEL_ROWS else 3


#: Recordings of up to this many samples get a fourth own level (``v_turn3``,
#: :func:`own_levels`).
FOUR_LEVEL_ROWS = 5_000


#: A recording of more samples than this tries one start state (with or without its
#: first cycle replayed), chosen by the starts' costs (:func:`_fit_model`); shorter
#: ones search both and keep the lower (measured on a 50,000-sample coupled recording:
#: both searches took the coupled two-tendon GPI from 2.5 to 5.9 s); shorter ones also
#: get three own levels (:func:`own_levels`) and the start state's re-search at the end
#: of every global search (:func:`_global_search`, step 5).
LARGE_ROWS = 20_000


def _searched(
    model, s, theta, used, hold, inner_fit, level, opts, starts, cycle, spent=0.0, probe=False
) -> _Searched | float:  # fmt: skip
    """The global search of ``model`` from ``starts`` (model vectors) on the fitted
    samples ``used``; ``level``: after a fitted pre-history (:class:`_FromLevel`, with
    the recording's first ``cycle`` samples replayed); ``spent``: work done before it
    (:data:`WORK_BUDGET`). ``probe``: only the lowest cost of the starts (their levels
    profiled), a float."""
    v = np.asarray(s.v, dtype=float)
    loss, method = opts["loss"], opts["method"]
    max_nfev, basin_hops = opts["max_nfev"], opts["basin_hops"]
    n_own = own_levels(v, basin_hops != 0)
    fitted_model: Model = _FromLevel(model, v, cycle, s.v_other, min(n_own, 3)) if level else model
    search = _Search.of(
        fitted_model, s, theta, used, loss, opts["f_scale_deg"], method, opts["ftol"],
        opts["screen_nfev"],
    )  # fmt: skip
    if level:
        starts = _starts_with_level(search, starts, inner_fit)
    # in-bounds points already reached (starts, screened ends): the result must not be worse
    known = [(search.counter.cost(x0), x0) for x0 in starts]
    if probe:
        return min(c for c, _ in known)
    if loss != "linear":
        plain_opts = {k: x for k, x in opts.items() if k not in ("loss", "f_scale_deg")}
        x_plain = _plain_fit_end(model, s, theta, plain_opts, starts, search)
        known.append((search.counter.cost(x_plain), x_plain))
        starts, steps = [x_plain, *starts], ROBUST_STEPS
    else:
        steps = FIRST_STEPS
    hops = MAX_HOPS if basin_hops is None else int(basin_hops)
    found = _global_search(search, starts, max_nfev, steps, hops, spent)
    known += found.screened
    if level and n_own > 3 and hops > 0:
        fourth = _one_level_back(search, found, known, max_nfev)
        if fourth is not None:
            search, found, known = fourth
            fitted_model = search.counter.model
    (cost, full, res), floor, notes = _floor_checked(search, found, known, max_nfev)
    result = _result(
        fitted_model, s, theta, used, hold, full, res, search.names, search.is_free, search.pidx,
        search.counter.n, len(starts), search.lsq_free, search.uidx,
    )  # fmt: skip
    result = _with_notes(result, search, cost, full, floor, notes)
    result = replace(result, certificate=found.certificate(cost, len(starts)))
    n_lv = fitted_model.n_own if level else 0
    return _Searched(result, cost, full, search.names, _work(search, search), cycle, n_lv)


def _with_level_back(x: np.ndarray, n_own: int) -> np.ndarray:
    """The point ``x`` of a search with ``n_own`` own levels (the last values) with one
    more, earliest, equal to its earliest one: the same pre-history (equal levels add
    nothing, :func:`_ramped`), the same cost to the last bit."""
    x = np.asarray(x, dtype=float)
    at = x.size - n_own
    return np.insert(x, at, x[at])


def _one_level_back(search: _Search, found: _Found, known: list, max_nfev):
    """(the search with a fourth own level (``v_turn3``), what it found, the points
    reached) when this motor's whole staircases (:func:`_staircases`) with four levels,
    from the three-level search's best end, end lower than it; None otherwise.

    A short recording that starts after loops of shrinking amplitude can need a fourth
    turning point (:func:`own_levels`). Searched with four levels from the start, the
    larger space sent other fits astray (measured: bench_optimum's maxwell_slip:119, 0.955
    -> 1.131x the truth's cost); from the three-level search's ends, where the fourth
    level equals the third (the same state, the same cost), the result is never worse
    than theirs. Only this motor's staircases are searched again (the other motor's keep
    three levels: its grid would repeat the three-level search's; measured on
    agpi_coupled:2 of bench_optimum, its chain 14.5 -> 12.9 s CPU, the same end)."""
    fl = search.counter.model
    four = _FromLevel(fl.inner, search.v, fl.cycle, search.counter.signals.v_other, 4)
    c = search.counter
    search4 = _Search.of(four, c.signals, c.theta, c.used, c.loss, c.f_scale, search.method,
                         search.ftol, search.screen_nfev)  # fmt: skip
    n = fl.n_own
    up = functools.partial(_with_level_back, n_own=n)
    found4 = _Found(
        [(e[0], up(e[1]), *e[2:]) for e in found.polished],
        [(cst, up(x)) for cst, x in found.screened],
        list(found.reached),
        found.hops,
        found.cap,
    )
    best, x0 = found4.best()[:2]
    for x in _staircases(search4, x0, best, motors=1, heads=found.heads):
        found4.polished.append(_polished_end(search4, x, found.cap))
    search4.counter.n += c.n
    if not found4.best()[0] < best * (1 - SAME_MINIMUM):
        c.n = search4.counter.n  # its work counted, its ends left
        return None
    b = found4.best()
    if found.cap != max_nfev and b[2] is not None and b[2].status == 0:
        found4.polished.append(_polished_end(search4, b[1], max_nfev))  # run it out
    return search4, found4, [(cst, up(x)) for cst, x in known]


#: Search steps of every start: fine v_f grid, LM, wide v_f grid, LM (short when several
#: starts are screened).
FIRST_STEPS = ("fine", "lm", "wide", "lm")
#: Search steps of the best screened end: LM to convergence, re-optimised v_f profile,
#: fine v_f grid, LM.
POLISH_STEPS = ("lm", "reopt", "fine", "lm")
#: Screening steps of a robust fit: the flag point is profiled with the robust cost too,
#: over the wide grid (outliers pull the least-squares profile's v_f).
ROBUST_STEPS = ("wide", "lm", "fine", "lm")


def _loss_samples(theta, fit_mask, holdout_mask) -> tuple[np.ndarray, np.ndarray]:
    """(held-out samples, samples in the loss), bool arrays of ``theta``'s shape.

    The loss takes every finite angle not held out and (when given) in ``fit_mask``.
    """
    hold = np.zeros(theta.shape, bool) if holdout_mask is None else np.asarray(holdout_mask, bool)
    used = np.isfinite(theta) & ~hold
    if fit_mask is not None:
        used &= np.asarray(fit_mask, bool)
    return hold, used


def lower_optimum(stored_cost: float, cost: float) -> bool:
    """True when ``cost`` is lower than ``stored_cost`` by more than :data:`SAME_MINIMUM`
    (relative): another minimum of the same model on the same data, not the same one
    reached again (the certificate's tolerance). The one rule by which a later stage's
    refit replaces a stored fit."""
    return bool(np.isfinite(cost) and cost < stored_cost * (1.0 - SAME_MINIMUM))


def fit_cost(
    model: Model,
    signals: Signals | np.ndarray,
    theta_deg: np.ndarray,
    *,
    holdout_mask: np.ndarray | None = None,
    fit_mask: np.ndarray | None = None,
    initial_state: InitialState | None = None,
    loss: str = "linear",
    f_scale_deg: float = 0.5,
) -> float:
    """The cost :func:`fit_model` minimises, at ``model``'s values: the sum of
    rho(r^2) over the samples in the loss (every finite angle not held out; rho of
    ``loss``, plain squares for ``"linear"``: :attr:`SearchCertificate.best_cost`), the
    model run after the pre-history of ``initial_state`` (a fit's
    :attr:`FitResult.initial_state`; None: from rest) as :meth:`FitResult.predict` runs
    it. A later stage compares a refit of a stored model with it (:func:`lower_optimum`)."""
    s = as_signals(signals)
    theta = np.asarray(theta_deg, dtype=float)
    _, used = _loss_samples(theta, fit_mask, holdout_mask)
    x = np.array([p.value for p in model.parameters], dtype=float)
    fitted, full = model, x
    if initial_state is not None:
        st = initial_state
        fitted = _FromLevel(model, np.asarray(s.v, dtype=float), st.cycle_samples,
                            s.v_other if st.other_v_from is not None else None,
                            state_own_levels(st))  # fmt: skip
        full = np.append(x, state_levels(st, fitted.levels, fitted.n_own))
    return _Counter(fitted, s, theta, used, loss, f_scale_deg).cost(full)


def fit_from_state(
    model: Model,
    signals: Signals | np.ndarray,
    theta_deg: np.ndarray,
    state: InitialState,
    *,
    method: str = "lm",
    max_nfev: int | None = None,
) -> FitResult:
    """``model``'s parameters refitted from its own values by local least squares (no
    global search, no start-state search), run after the start state ``state`` held.

    The pre-history's levels are those of ``state`` (clipped to the level bounds of
    ``signals``); it ends at the first input of ``signals``, so ``state`` may come from
    a fit of the same recording on another clock (sync's offset profile, where a start
    state searched again at every candidate clock made the cost jump between states).

    Returns
    -------
    FitResult
        As :func:`fit_model`'s, ``initial_state`` the held levels on ``signals``.
    """
    s = as_signals(signals)
    v = np.asarray(s.v, dtype=float)
    v_other = s.v_other if state.other_v_from is not None else None
    lead = _FromLevel(model, v, state.cycle_samples, v_other, state_own_levels(state))
    n = len(model.parameters)
    levels = state_levels(state, lead.levels, lead.n_own)
    held = [
        replace(p, value=float(np.clip(u, p.lower, p.upper)), fixed=True)
        for p, u in zip(lead.parameters[n:], levels, strict=True)
    ]
    lead.parameters = (*lead.parameters[:n], *held)
    x0 = np.array([p.value for p in lead.parameters], dtype=float)
    res = fit_model(lead, s, theta_deg, starts=[x0], method=method, max_nfev=max_nfev,
                    initial_state="rest", basin_hops=0)  # fmt: skip
    full = np.append(np.asarray(res.model.values, dtype=float), [p.value for p in held])
    return _without_level(res, model, v, full, state.cycle_samples, v_other)


def _check_loss(loss: str, method: str) -> None:
    """CalibError for an unknown loss or a robust loss with the (plain) LM method."""
    if loss not in ("linear", "soft_l1", "huber"):
        raise CalibError(f"fit: unknown loss '{loss}'; use linear, soft_l1 or huber")
    if loss != "linear" and method != "trf":
        raise CalibError(
            f"fit: loss '{loss}' needs method 'trf' (MINPACK LM is plain least squares)"
        )


def _start_vectors(model: Model, starts) -> list[np.ndarray]:
    """The start vectors as float arrays (a new list); ``[model values]`` when none given."""
    if not starts:
        return [np.array([p.value for p in model.parameters], dtype=float)]
    return [np.asarray(x0, dtype=float) for x0 in starts]


@dataclass(frozen=True)
class _Search:
    """One fit's search: the cost counter and what every search step needs.

    Attributes
    ----------
    counter : _Counter
        Residuals, Jacobians and costs of the fitted model on the fitted samples.
    v : ndarray, shape (n,)
        The input.
    names : tuple of str
        Parameter names of the fitted model (with ``initial_state.v_from`` last when
        the initial state is fitted).
    lower, upper : ndarray, shape (p,)
        Bounds.
    is_free : ndarray of bool, shape (p,)
        Free parameters.
    pidx : list of int
        Free profiled parameters (v_f).
    uidx : int or None
        Index of the initial-state level ``v_from`` (profiled; ``uidx - 1``, ``uidx - 2``
        and ``uidx - 3`` are the earlier turning points ``v_turn``, ``v_turn2`` and
        ``v_turn3``, as many as :func:`own_levels`), None when it is not fitted.
    lsq_free : ndarray of int
        Free parameters moved by LM / trf (free, neither profiled nor the level).
    method : str
        ``"lm"`` or ``"trf"``.
    ftol : float
        Relative cost-reduction tolerance of ``least_squares``.
    screen_nfev : int
        LM iterations of each call while screening (and of the re-optimised profile).
    """

    counter: _Counter
    v: np.ndarray
    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    is_free: np.ndarray
    pidx: list[int]
    uidx: int | None
    lsq_free: np.ndarray
    method: str
    ftol: float
    screen_nfev: int

    @classmethod
    def of(cls, model, s, theta, used, loss, f_scale_deg, method, ftol, screen_nfev) -> _Search:
        """The search for ``model`` (a :class:`_FromLevel` fits its level too) on the
        samples ``used`` of (``s``, ``theta``)."""
        params = model.parameters
        names = tuple(p.name for p in params)
        level = isinstance(model, _FromLevel)
        is_free = np.array([not p.fixed for p in params])
        uidx = len(names) - 1 if level else None
        pidx = [i for i, nm in enumerate(names) if nm in PROFILE_PARAMS and is_free[i]]
        # the levels (and a flag point the output is continuous in) are LM's too, by
        # finite differences; profiled as well, to explore
        held = [i for i in pidx if i not in counter_fd(model, names)]
        lsq_free = np.flatnonzero(is_free & ~np.isin(np.arange(len(names)), held))
        # the model runs on read-only copies of the inputs: they cannot change during the
        # fit, so the models keep what they derive from them (runs of held samples)
        counter = _Counter(model, _frozen_inputs(s), theta, used, loss, f_scale_deg)
        return cls(
            counter, np.asarray(s.v, dtype=float), names,
            np.array([p.lower for p in params]), np.array([p.upper for p in params]),
            is_free, pidx, uidx, lsq_free, method, ftol, screen_nfev,
        )  # fmt: skip

    def run(
        self, x0, nfev_limit, steps, how=None, stop_above=np.inf
    ) -> tuple[float, np.ndarray, object]:
        """(cost, end point, the last least_squares result or None) of the search
        ``steps`` from ``x0``: ``"lm"`` a least-squares run (``how``: method, default the
        fit's) limited to ``nfev_limit``; ``"wide"`` / ``"fine"`` the profile searches of
        v_f and the level; ``"reopt"`` the re-optimised v_f profile. A model without
        profiled parameters takes one least-squares run. ``stop_above``: the steps
        after the first least-squares run are left out when it ends above this cost."""
        how = self.method if how is None else how
        c, lo, hi = self.counter, self.lower, self.upper
        full, res = np.asarray(x0, dtype=float).copy(), None
        for step in steps if self.pidx or self.uidx is not None else ("lm",):
            if step == "lm" and self.lsq_free.size:
                first = res is None
                full, res = _lsq(c, full, self.lsq_free, lo, hi, how, nfev_limit, self.ftol)
                full = self.levels_inside(full)
                if first and 2.0 * res.cost > stop_above:
                    break  # least_squares' cost is half the counter's
            elif step in ("wide", "fine"):
                full = _refine_profiled(c, full, self.pidx, self.v, lo, hi, wide=step == "wide")
                for i in reversed(self.level_idx):  # v_from, v_turn(2), the other motor's
                    if i == self.uidx - 3 and self.counter.model.n_own > 3:
                        continue  # v_turn3: LM's, the sweeps' and the staircases' only
                    if step == "wide" or i > self.uidx - self.counter.model.n_own:  # other's: wide
                        full = _refine_level(c, full, i, lo, hi, wide=step == "wide")
            elif step == "reopt" and self.lsq_free.size and self.pidx:
                full = _reoptimised_profile(
                    c, full, self.pidx, self.lsq_free, self.v, lo, hi, how, self.screen_nfev,
                    self.ftol,
                )  # fmt: skip
        return c.cost(full), full, res

    def outside(self, full: np.ndarray) -> list[int]:
        """Indices of the LM-fitted parameters of ``full`` outside their bounds (the
        initial-state levels excepted: :meth:`levels_inside` clips them)."""
        levels = self.level_idx
        return [i for i in _outside(full, self.lsq_free, self.lower, self.upper) if i not in levels]

    @property
    def level_idx(self) -> tuple[int, ...]:
        """Indices of the initial-state levels (the other motor's, (v_turn3,) v_turn2, v_turn, v_from;
        empty when the start state is not fitted)."""
        if self.uidx is None:
            return ()
        k = self.counter.model.levels
        return tuple(range(self.uidx - k + 1, self.uidx + 1))

    def without_levels(self) -> _Search:
        """This search with the initial-state levels left to the profile steps (not
        moved by LM)."""
        if self.uidx is None:
            return self
        levels = self.level_idx
        return replace(self, lsq_free=np.array([i for i in self.lsq_free if i not in levels], int))

    def levels_inside(self, full: np.ndarray) -> np.ndarray:
        """``full`` with the initial-state levels clipped into their bounds (plausibility
        limits of where the input came from, not physical ones: LM may step past them
        where the cost is flat, and a bounded refit for them would cost a trf run)."""
        if self.uidx is None:
            return full
        out = np.asarray(full, dtype=float).copy()
        for i in self.level_idx:
            out[i] = min(max(out[i], self.lower[i]), self.upper[i])
        return out


def counter_fd(model, names) -> list[int]:
    """Indices of the profiled parameters of ``model`` that LM moves too (a flag point
    the output is continuous in: :attr:`ContinuousEGPIModel.CONTINUOUS_FLAG_POINT`)."""
    inner = model.inner if isinstance(model, _FromLevel) else model
    if "v_f" in names and getattr(inner, "CONTINUOUS_FLAG_POINT", False):
        return [list(names).index("v_f")]
    return []


def _frozen(a) -> np.ndarray:
    """A read-only float copy of ``a`` (owning its data)."""
    out = np.array(a, dtype=float)
    out.flags.writeable = False
    return out


def _frozen_inputs(s: Signals) -> Signals:
    """``s`` with read-only copies of the input and of the other motor's input."""
    v_other = None if s.v_other is None else _frozen(s.v_other)
    return replace(s, v=_frozen(s.v), v_other=v_other)


def _starts_with_level(search: _Search, starts, inner_fit) -> list[np.ndarray]:
    """``starts`` with the initial-state level appended: every start at the level that
    fits the first start best (scanned once over the whole range); the nested start
    (last, when ``inner_fit`` is given) at its base fit's level."""
    counter, uidx = search.counter, search.uidx
    # the other motor's levels (a model with its state) start at its first value:
    # relaxed there, as without them
    vo = counter.signals.v_other
    own = counter.model.n_own
    other = [float(vo[0])] * counter.model.n_other if counter.model.n_other else []
    first = np.append(starts[0], [*other, *[float(search.v[0])] * own])
    u0 = _refine_level(counter, first, uidx, search.lower, search.upper)[-1]
    u1 = _other_branch_level(search, np.append(starts[0], [*other, *[u0] * own]))[-1]
    st = inner_fit[1].initial_state if inner_fit is not None else None
    u_nested = state_levels(st, own, own) if st else [u0] * own
    # every other start on the other branch: which branch the recording starts on is
    # as much a basin of the cost as any parameter (measured on a two-tendon truth
    # starting mid-loop: 9 starts on one branch ended at 184.5, the other's at 182.1)
    out = [
        np.append(x0, [*other, *[u0] * own] if i % 2 == 0 else [*other, *[u1] * own])
        for i, x0 in enumerate(starts)
    ]
    if inner_fit is not None:
        out[-1][-own:] = u_nested
    return _with_other_levels(search, out) if counter.model.n_other else out


def _with_other_levels(search: _Search, starts: list[np.ndarray]) -> list[np.ndarray]:
    """``starts`` with the other motor's levels, in pairs of starts (so both of this
    motor's branches meet both): relaxed at its first value (as without levels), and at
    the best of :func:`_pair_grid` on the lowest-cost start, a loop's two extremes, as
    the other motor came through its last loop. Where the other motor came from is as
    much a basin of the cost as this motor's branch (measured on agpi_coupled:31 of
    bench_optimum: every start relaxed, the fit ended at 1.025 x the truth's cost; every
    start at the grid's best, at 0.993; agpi_coupled:5 the other way round). Up to
    :data:`LARGE_ROWS` samples (measured on bench_speed's 50,000-sample coupled
    recording: the grid took its fit from 4.0 to 7.2 s CPU, to the same end)."""
    if len(starts) < 3 or search.v.size > LARGE_ROWS:
        return starts  # a warm refit: its start's state; a long recording: its loops
    costs = [search.counter.cost(x) for x in starts]
    best = starts[int(np.argmin(costs))]
    turns, last = _motors_levels(search)[1]
    levels = _pair_grid(search, best, turns, last)[1][[*turns, last]]
    out = [np.asarray(x, dtype=float).copy() for x in starts]
    for x in out[2::4] + out[3::4]:
        x[[*turns, last]] = levels
    return out


def _branch_level(search: _Search, full: np.ndarray, idx: int, v0: float) -> np.ndarray:
    """``full`` with level ``idx`` moved to the best of :data:`INITIAL_STATE_GRID`
    levels on the other side of ``v0`` from where it is, the others held."""
    lo, hi = search.lower[idx], search.upper[idx]
    a, b = (lo, v0) if full[idx] > v0 else (v0 + 1e-9 * max(abs(v0), 1.0), hi)
    if not a < b:
        return full
    grid = np.linspace(a, b, INITIAL_STATE_GRID)
    cost = search.counter.held_cost(full, idx)
    out = full.copy()
    out[idx] = grid[int(np.argmin([cost(u) for u in grid]))]
    return out


def _other_branch_level(search: _Search, full: np.ndarray) -> np.ndarray:
    """``full`` with its initial-state level moved to the best of
    :data:`INITIAL_STATE_GRID` levels on the other side of the first input (the other
    branch: above it a falling branch, at or below it the loading one), the other
    parameters held; ``full`` itself when that side is empty."""
    return _branch_level(search, full, search.uidx, float(search.v[0]))


def _plain_fit_end(model, s, theta, opts, starts, search: _Search) -> np.ndarray:
    """End point (the search's parameter vector) of the converged plain least-squares
    fit from ``starts``, the start of a robust fit; its evaluations are counted.

    Robust fits start from the plain fit (LM, the fitter's own path; outliers also
    bias the data-driven starts), then refine with the robust loss by trf. The plain
    fit's end joins the points the result may not be worse than, so a start that
    scores better in the robust cost is refined too and the lower end wins (never a
    bare restart from it). The plain fit can end in a minimum the outliers made:
    every start is also screened with the robust cost, and the best end polished.
    """
    plain = _fit_model(
        model, s, theta, **(opts | dict(method="lm")), nested=False,
        starts=[x[: len(model.parameters)] for x in starts],
    )  # fmt: skip
    search.counter.n += plain.nfev
    x_plain = np.array([p.value for p in plain.model.parameters], dtype=float)
    if search.uidx is not None:
        k = search.counter.model.levels
        st = plain.initial_state
        own = search.counter.model.n_own
        levels = state_levels(st, k, own) if st is not None else starts[0][-k:]
        x_plain = np.append(x_plain, levels)
    return x_plain


#: Screening runs on at most about this many fitted samples: a fit with more screens
#: its starts on every k-th fitted sample (the models still run over the whole history;
#: only rows leave the cost), the best end is then polished on every sample. Measured
#: on 50,000-sample recordings (37,500 fitted): the coupled two-tendon GPI's screening
#: 1.5x faster (the Jacobian rows and LM's QR of them), the same end.
SCREEN_ROWS = 10_000


def _screening(search: _Search) -> _Search:
    """The search the starts are screened with: ``search`` itself up to
    :data:`SCREEN_ROWS` fitted samples or with a profiled flag point, else the same
    search on every k-th fitted sample (k the smallest step that brings them to at most
    about SCREEN_ROWS), with a counter of its own (its evaluations are added to
    ``search``'s after).

    A flag-point model keeps every sample: its screening is mostly the v_f profile (a
    model run per candidate, as long with fewer rows), and the profile's exact step
    tries the fitted samples' inputs (fewer rows, other candidates; measured on the
    continuous EGPI: another, slower search)."""
    c = search.counter
    k = -(-c.used_idx.size // SCREEN_ROWS)
    if k <= 1 or search.pidx:
        return search
    sub = np.zeros(c.used.shape, bool)
    sub[c.used_idx[::k]] = True
    return replace(search, counter=_Counter(c.model, c.signals, c.theta, sub, c.loss, c.f_scale))


#: A screened start whose first least-squares run ends above this multiple of the best
#: screened end so far is not searched further (measured: the coupled two-tendon GPI's
#: silent-coupling start, 2000x the others'; ends a wide v_f grid still improves are
#: within 1.5x).
SCREEN_STOP_RATIO = 10.0


def _screened_ends(screen: _Search, starts, steps) -> list[np.ndarray]:
    """End points of ``steps`` from every start (LM runs short, ``screen_nfev``), in
    the order of ``starts``; searched from the lowest-cost start up, a start whose first
    least-squares run ends above :data:`SCREEN_STOP_RATIO` x the best end so far is
    left there."""
    c = screen.counter
    order = np.argsort([c.cost(x0) for x0 in starts], kind="stable")
    ends, best = [None] * len(starts), np.inf
    for i in order:
        cost, ends[i], _ = screen.run(starts[i], screen.screen_nfev, steps, None,
                                      SCREEN_STOP_RATIO * best)  # fmt: skip
        best = min(best, cost)
    return ends


#: Most screened ends polished (the lowest first; measured on the README demo's
#: pitch-: the second polished end reaches the best basin).
MAX_POLISHED = 4
#: Screened ends are polished to convergence on every fitted sample, the lowest first:
#: short screening runs rank basins badly (measured on the README demo's pitch-: the
#: nested GPI start screened to 2.7 and polished to 2.5, eight data-driven starts
#: screened to 159 and polished to 0.104). A screened end already within
#: :data:`SAME_MINIMUM` of the best polished cost has reached it and is not polished
#: again. After the first polish, each further polish or restart must fit in
#: :data:`WORK_BUDGET` (:func:`_affordable`).
#:
#: The search's work, in model evaluations x input samples (each evaluation runs the
#: model over the whole input), that further polishes and restarts may bring a fit to:
#: one more is run only when the work so far plus that of the first polish stays
#: within it. Counted, not timed, so a fit is the same on every machine. Measured on
#: 50,000-sample recordings (bench_speed): one continuous-EGPI polish ~1,000
#: evaluations (5e7, ~2 s), an EGPI polish ~300 (1.5e7, ~1 s); a few thousand samples
#: (the README demo) afford every start and :data:`MAX_HOPS` restarts.
WORK_BUDGET = 5e7
#: A screened end above this multiple of the best polished cost is not polished (the
#: coupled two-tendon GPI's silent-coupling start ends ~2000x above the others).
POLISH_STOP_RATIO = 1000.0
#: Most basin-hopping restarts of one fit.
MAX_HOPS = 4
#: Spread of a hop: positive parameters are multiplied by exp(N(0, HOP_SPREAD^2)),
#: the others moved by N(0, HOP_SPREAD^2) x their magnitude.
HOP_SPREAD = 0.7
#: Spread of a hop's flag point (profiled, not moved by LM), as a fraction of the input
#: range (measured on an EGPI truth at 5 Hz: the best basin's v_f 6 % of the range from
#: where the starts put it, beyond the wide profile's reach with the others held).
HOP_FLAG_SPREAD = 0.08
#: Seed of the hops' perturbations (a fit is deterministic).
HOP_SEED = 20261129


@dataclass
class _Found:
    """What :func:`_global_search` found.

    ``polished``: (cost, end, least_squares result, notes) of every polished end (in
    bounds); ``screened``: (cost over every fitted sample, end) of every screened start;
    ``reached``: costs of screened ends not polished because they already were within
    :data:`SAME_MINIMUM` of the best polished cost; ``hops``: restarts run."""

    polished: list
    screened: list
    reached: list
    hops: int
    cap: int | None = None  # the later polishes' LM limit
    #: this motor's lowest three-level staircases (:func:`_best_staircases`), which a
    #: search with a fourth level extends one turning point back (:func:`_one_level_back`)
    heads: list = field(default_factory=list)

    def best(self):
        """(cost, end, result, notes) of the lowest polished end (of equal costs, to
        1e-9, one whose last least-squares run converged)."""
        low = min(e[0] for e in self.polished)
        tied = [e for e in self.polished if e[0] <= low + 1e-9 * abs(low)]
        done = [e for e in tied if e[2] is None or e[2].status > 0]
        return min(done or tied, key=lambda e: e[0])

    def certificate(self, cost: float, n_starts: int) -> SearchCertificate:
        """The certificate of the search for the final ``cost`` (the fit's end, after
        the floor check)."""
        costs = [e[0] for e in self.polished] + list(self.reached)
        tol = cost * (1 + SAME_MINIMUM) + 1e-300
        at_best = sum(c <= tol for c in costs)
        above = [e[0] for e in self.polished if e[0] > tol]
        return SearchCertificate(
            n_starts, len(self.polished), max(at_best, 1), float(cost),
            float(min(above)) if above else float("nan"), self.hops,
        )  # fmt: skip


def _work(search: _Search, screen: _Search) -> float:
    """The search's work so far: model evaluations x input samples."""
    n = search.counter.n + (screen.counter.n if screen is not search else 0)
    return float(n) * search.v.size


def _affordable(search: _Search, screen: _Search, one_polish: float, spent: float = 0.0) -> bool:
    """Whether one more polish (of work ``one_polish``) keeps the search, after the
    work ``spent`` before it (another start state's search), within
    :data:`WORK_BUDGET`."""
    return spent + _work(search, screen) + one_polish <= WORK_BUDGET


def _global_search(search: _Search, starts, max_nfev, steps, hops: int, spent=0.0) -> _Found:
    """The multi-start search with basin hopping (docs/design/fit.md, "The global search").

    1. Every start is screened (:func:`_screened_ends`: short LM runs on
       :func:`_screening`'s samples, the lowest-cost start first).
    2. The lowest screened ends are polished to convergence on every fitted sample and
       brought inside the bounds (:func:`_polished_end`), as many as
       :data:`WORK_BUDGET` allows (at least one); an end already within :data:`SAME_MINIMUM` of the
       best polished cost has reached it (not polished again); ends above
       :data:`POLISH_STOP_RATIO` x it are left.
    2b. A flag-point model (EGPI): the starts whose screened end lies far from the
       best end's flag point are screened again at it, the lowest polished
       (:func:`_flag_point_carried`).
    3. When the best end has parameters on a bound, one restart with them at their
       typical start value (:func:`_released`): a bound that an interior start beats
       is a search failure.
    4. While fewer than :data:`CERTIFIED_AT` starts reached the best cost, restarts
       from perturbations of the best end (:func:`_hop`; every other one with the
       initial state on the other branch, :func:`_other_branch_level`, when it is
       fitted), each screened, then polished
       unless it ends above :data:`POLISH_STOP_RATIO` x the best; at most ``hops``
       restarts in all (steps 3 and 4), within :data:`WORK_BUDGET`.
    5. A fitted start state: the best end's levels searched again
       (:func:`_levels_researched`) on every recording of at most :data:`LARGE_ROWS`
       samples, and on a longer one when a polish is cheap (1/20 of
       :data:`WORK_BUDGET`) and fits in the budget. Not by the budget alone: a 500 Hz
       two-motor recording of 6,500-20,000 samples spends it on its first polishes, and
       its two motors' staircases are what a coupled fit there misses (bench_optimum's
       mid-loop agpi_coupled cases at 500 Hz, 44 of seeds 0-199: 7 misses, up to 3.0x
       the truth's cost, with the budget's gate; 2 without it, 1.008x and 1.010x, none
       new; their chains' CPU 920 -> 1953 s). Lifted for the coupled kind alone, its
       chain's uncoupled fit moved and two coupled fits failed (agpi_coupled:108 1.025x,
       :156 1.086x). On 216 mid-loop cases at 500 Hz of gpi, egpi, egpi_c, agpi,
       bouc_wen and maxwell_slip no fit ended 0.1 % lower or higher, at 1.2-2.0x their
       CPU. Longer recordings keep the budget's gate (bench_speed's 50,000-sample fits:
       their start state weighs little against their many loops).
    """
    screen = _screening(search)
    ends = _screened_ends(screen, starts, steps)
    screened = [(search.counter.cost(x), x) for x in ends]
    found = _Found([], screened, [], 0)
    one, cap = 0.0, max_nfev  # the work of the first polish; the later ones' LM limit
    for c, x in sorted(screened, key=lambda e: e[0]):
        if found.polished:
            b = found.best()[0]
            if c <= b * (1 + SAME_MINIMUM):
                found.reached.append(c)
                continue
            if (
                len(found.polished) >= (MAX_POLISHED if hops > 0 else 1)
                or c > _stop_ratio(one) * b
                or not _affordable(search, screen, one, spent)
            ):
                break
        before, n0 = _work(search, screen), search.counter.n
        found.polished.append(_polished_end(search, x, cap))
        if not one:
            one = _work(search, screen) - before
            cap = _later_cap(max_nfev, search.counter.n - n0)
    if search.pidx and hops > 0:
        _flag_point_carried(search, screen, starts, found, steps, (one, cap, spent))
    rng = np.random.default_rng(HOP_SEED)
    ref = np.median(np.abs(np.asarray(starts, dtype=float)), axis=0)
    released = _released(search, found.best()[1], np.median(np.asarray(starts, float), axis=0))
    if released is not None and hops > 0 and _affordable(search, screen, one, spent):
        found.hops += 1
        _, x, _ = screen.run(released, screen.screen_nfev, steps)
        found.polished.append(_polished_end(search, x, cap))
    while (
        found.hops < hops
        and found.certificate(found.best()[0], len(starts)).at_best < CERTIFIED_AT
        and _affordable(search, screen, one, spent)
    ):
        found.hops += 1
        b = found.best()
        x = _hop(search, b[1], ref, rng)
        if search.uidx is not None and found.hops % 2 == 1:
            x = _other_branch_level(search, x)
        _, x, _ = screen.run(x, screen.screen_nfev, steps)
        if search.counter.cost(x) <= _stop_ratio(one) * b[0]:
            found.polished.append(_polished_end(search, x, cap))
    if (
        search.uidx is not None
        and hops > 0
        and (  # step 5
            search.v.size <= LARGE_ROWS
            or (one <= WORK_BUDGET / 20 and _affordable(search, screen, one, spent))
        )
    ):
        _levels_researched(search, found, cap)
    found.cap = cap
    best = found.best()
    if cap is not None and cap != max_nfev and best[2] is not None and best[2].status == 0:
        # the best end came from a polish cut at the later ones' limit: run it out
        found.polished.append(_polished_end(search, best[1], max_nfev))
    if screen is not search:
        search.counter.n += screen.counter.n
    return found


#: A screened end whose flag point lies more than this fraction of the input range from
#: the best polished end's is screened again from its start at that flag point
#: (:func:`_flag_point_carried`).
FLAG_CARRY_GAP = 0.02


def _flag_point_carried(
    search: _Search, screen: _Search, starts, found: _Found, steps, budget
) -> None:
    """The starts screened again at the best polished end's flag point, the lowest end
    polished (appended to ``found.polished``) unless it has reached the best cost.

    The flag point splits the cost into basins: a start whose v_f estimate lies far
    from the best one's stays there through the v_f profiles while the other
    parameters fit around it, so its shape (sigma, r1, rn, kappa) is never tried where
    the flag point belongs (measured: egpi:5 of bench_optimum, every data-driven start
    stuck near v_f 3,870 at 20x the truth's cost, the nested GPI start found v_f 3,004
    in another shape basin, 1.109x). ``budget``: (the first polish's work, the later
    polishes' LM limit, work spent before this search). Only starts whose screened end
    lies more than :data:`FLAG_CARRY_GAP` of the input range from the best v_f are
    screened again, within :data:`WORK_BUDGET`."""
    one, cap, spent = budget
    b_cost, b_full = found.best()[:2]
    pidx, gap = search.pidx, FLAG_CARRY_GAP * float(np.ptp(search.v))
    carried = []
    for (_, end), x0 in zip(found.screened[: len(starts)], starts, strict=True):
        if np.all(np.abs(end[pidx] - b_full[pidx]) <= gap):
            continue
        x = np.asarray(x0, dtype=float).copy()
        x[pidx] = b_full[pidx]
        carried.append(x)
    if not carried or not _affordable(search, screen, one, spent):
        return
    ends = _screened_ends(screen, carried, steps)
    c, x = min(((search.counter.cost(e), e) for e in ends), key=lambda e: e[0])
    found.screened.append((c, x))
    if b_cost * (1 - SAME_MINIMUM) <= c <= b_cost * (1 + SAME_MINIMUM):
        found.reached.append(c)
    elif c <= _stop_ratio(one) * b_cost and _affordable(search, screen, one, spent):
        found.polished.append(_polished_end(search, x, cap))


#: A start state shifted one turning point back (:func:`_levels_researched`) is
#: polished when its cost, the other parameters held, is within this multiple of the
#: best end's (measured: maxwell_slip:4 of bench_optimum, 10.4 with them held, 9.03
#: polished, against the best end's 14.7).
STATE_POLISH_RATIO = 3.0
#: Most sweeps of the start state's levels in :func:`_levels_researched`.
LEVEL_SWEEPS = 3


def _level_sweeps(search: _Search, full: np.ndarray) -> tuple[float, np.ndarray]:
    """(cost, point): ``full`` with the start state's levels searched together, the other
    parameters held: sweeps of profile searches over every level in turn (the whole
    range, then around the best), until a sweep gains less than :data:`SAME_MINIMUM`
    (at most :data:`LEVEL_SWEEPS`)."""
    c, lo, hi = search.counter, search.lower, search.upper
    cost = c.cost(full)
    for _ in range(LEVEL_SWEEPS):
        before = cost
        for i in reversed(search.level_idx):
            full = _refine_level(c, full, i, lo, hi, wide=True)
            full = _refine_level(c, full, i, lo, hi, wide=False)
        cost = c.cost(full)
        if cost >= before * (1 - SAME_MINIMUM):
            break
    return cost, full


def _levels_researched(search: _Search, found: _Found, cap) -> None:
    """The best end's start state searched again, the model's parameters held, and the
    end polished from there when that lowers its cost (appended to ``found.polished``).

    The levels of a staircase pre-history (:class:`InitialState`) interact: one level
    profiled at a time from where the starts put them can stop short of a turning point
    the recording's state needs. Two moves from the best end: sweeps over every level
    (:func:`_level_sweeps`; for a model with the other motor's state, then
    :func:`_pair_grid` over its last two turning points, swept again when lower), and the
    same sweeps after the own levels shifted one
    turning point back (``v_turn2, v_turn, v_from`` <- ``v_turn, v_from, new``: a newer, smaller loop
    inside the last one, the wiping-out staircase grown by one step; ``new`` the best
    level, and the best on the other side of ``v[0]``), polished when within
    :data:`STATE_POLISH_RATIO` of the best cost (the other parameters move with the
    state); the other motor's levels (hysteretic coupling) shifted the same way, its new
    last level on the other side of its first input (measured: agpi_coupled:33 of
    bench_optimum, 1.195 -> 0.947 x the truth's cost)."""
    cost0, x0 = found.best()[:2]
    cost, x = _level_sweeps(search, x0)
    if search.counter.model.n_other:  # the other motor's two extremes together
        grid_cost, grid_x = _pair_grid(search, x, *_motors_levels(search)[1])
        if grid_cost < cost * (1 - SAME_MINIMUM):
            cost, x = _level_sweeps(search, grid_x)
    if cost < cost0 * (1 - SAME_MINIMUM):
        found.polished.append(_polished_end(search, x, cap))
    own = list(search.level_idx[-search.counter.model.n_own :])
    shifted = np.asarray(x0, dtype=float).copy()
    shifted[own[:-1]] = x0[own[1:]]
    # the new turning point: the best over the whole range, and the best on the other
    # side of v[0] from the last one (a reversal; the other parameters are held, so
    # the first may keep the old state)
    lo, hi = search.lower, search.upper
    tried = []
    for new in (_refine_level(search.counter, shifted, own[-1], lo, hi),
                _other_branch_level(search, shifted)):  # fmt: skip
        cost, x = _level_sweeps(search, new)
        if cost < STATE_POLISH_RATIO * cost0 and not any(np.array_equal(x, t) for t in tried):
            tried.append(x)
            found.polished.append(_polished_end(search, x, cap))
    for x in _staircases(search, x0, cost0, heads=found.heads):
        if not any(np.array_equal(x, t) for t in tried):
            tried.append(x)
            found.polished.append(_polished_end(search, x, cap))
    n_other = search.counter.model.n_other
    if n_other:  # the other motor's levels shifted the same way
        oth = list(search.level_idx[:n_other])
        shifted = np.asarray(x0, dtype=float).copy()
        shifted[oth[:-1]] = x0[oth[1:]]
        vo0 = float(np.asarray(search.counter.signals.v_other, dtype=float)[0])
        cost, x = _level_sweeps(search, _branch_level(search, shifted, oth[-1], vo0))
        if cost < STATE_POLISH_RATIO * cost0:
            found.polished.append(_polished_end(search, x, cap))


#: Levels per motor of the staircase grid (:func:`_staircases`), the recording's own
#: extremes and the rest added.
STAIRCASE_GRID = 13
#: Distinct staircases of the grid run by LM per motor (:func:`_best_staircases`), the
#: LM evaluations of each, and the most start states polished (:func:`_staircases`).
STAIRCASE_SCREENED = 24
STAIRCASE_NFEV = 8
STAIRCASE_BEST = 3


def _staircases(
    search: _Search, x0: np.ndarray, cost0: float, motors: int | None = None, heads=None
) -> list[np.ndarray]:
    """Start states to polish found over whole staircases (up to :data:`STAIRCASE_BEST`;
    ``x0``: the best end, ``cost0`` its cost): the lowest of the grid's staircases with
    the model's parameters held at ``x0``, then the lowest ends of short LM runs
    (:data:`STAIRCASE_NFEV` evaluations, the parameters and the levels together) from
    every staircase the grid kept, each within :data:`STATE_POLISH_RATIO` of ``cost0``.

    The grid (:func:`_best_staircases`) runs for each motor whose pre-history is fitted
    (this one's; then the other's, for a model with its state, at this one's lowest),
    scored on the samples the start state moves (:meth:`_FromLevel._opening`).

    Why: the levels are searched one at a time elsewhere (profiles, sweeps, shifts), but
    a history of loops of changing amplitude leaves a staircase whose turning points
    must move together, and the model's parameters with them. With the parameters
    fitted to another state the right staircase can score worse than that state
    (measured on maxwell_slip:95 of bench_optimum: the truth's turning points 1.7x the
    best end's cost, the parameters held; 0.89x after 5 LM evaluations), so the
    staircases are judged after a short LM run, not by their held cost alone. On the
    mid-loop cases of seeds 0-199 the misses went from 7 to 3 of 64 (maxwell_slip), 1 to
    0 of 72 (agpi) and 9 to 7 of 98 (agpi_coupled)."""
    c = search.counter
    model = c.model
    head, m = model._opening(c.signals)
    hc = _Counter(model, head, c.theta[:m], c.used[:m], c.loss, c.f_scale)
    x = np.asarray(x0, dtype=float)
    points = []
    for i, (turns, last) in enumerate(_motors_levels(search)[:motors]):
        found = _best_staircases(search, hc, x, [*turns, last], i == 0, heads if i == 0 else None)
        points += found
        if found:
            x = found[0]
    c.n += hc.n
    # each screened as the starts are (a short LM run, the parameters move with the
    # state): the lowest ends are polished
    held = sorted(((c.cost(p), p) for p in points), key=lambda e: e[0])
    ends = sorted((search.run(p, STAIRCASE_NFEV, ("lm",))[:2] for _, p in held), key=lambda e: e[0])
    held = [(cost, p) for cost, p in held if cost < STATE_POLISH_RATIO * cost0]
    out = [p for _, p in held[:1]]
    for cost, e in ends:
        if len(out) < STAIRCASE_BEST and cost < STATE_POLISH_RATIO * cost0:
            out.append(e)
    return out


def _best_staircases(
    search: _Search, hc: _Counter, x: np.ndarray, idx: list[int], own: bool, heads=None
):
    """Up to :data:`STAIRCASE_SCREENED` distinct staircases of lowest cost on ``hc``'s
    samples, lowest first: ``x`` with the levels ``idx`` (one motor's, earliest first)
    set to a pre-history from rest that reverses at each level on its way to the
    motor's first input.

    The earlier levels take :data:`STAIRCASE_GRID` values over their bounds, the motor's
    lowest and highest input and the rest (a level at the rest drops a turning point);
    the last (the innermost reversal, to which the cost is most sensitive) the wide
    profile's grid (:data:`INITIAL_STATE_GRID` and :func:`_near_first`). ``heads``: a
    list that a three-level grid fills with its :data:`STAIRCASE_HEADS` lowest
    staircases and that a four-level one extends one turning point back, the earliest
    level over the coarse values (the whole product would be 16x the three-level grid's
    evaluations; the three-turn staircases are the three-level search's). Pre-histories
    that leave the same state (:func:`_wiped`) are scored once; a staircase is kept
    only when its cost differs from every kept one's (an equal cost: the same state, a
    turn the model's sides wiped out) and it lies at least a grid step from each in some
    level (near copies of one sharp minimum would fill the list). The
    :data:`STAIRCASE_REFINED` lowest are then refined (:func:`_refined_staircase`).
    Measured on agpi:149 of bench_optimum, whose history turned at 5,926 (250 counts
    from the grid's nearest value) and whose lowest grid staircases were one state many
    times over: with the refinement alone 1.035x the truth's cost, with the equal-cost
    rule too 0.987x.

    Returned: the refined staircases first, then every kept one as the grid found it
    (the refined ones' origins too). A refined staircase is lower with the parameters
    held, which is not the staircase the short LM runs of :func:`_staircases` end lowest
    from (measured on maxwell_slip:95 of bench_optimum, mid-loop at 5 Hz: from the
    refined ones alone the fit ended at 1.046x the truth's cost, with their origins too at
    0.936x; over the 64 mid-loop maxwell_slip cases of seeds 0-199 no other fit moved,
    147.8 -> 155.2 s CPU)."""
    s = search.counter.signals
    u = np.asarray(s.v if own else s.v_other, dtype=float)
    lo, hi, v0 = search.lower[idx[0]], search.upper[idx[0]], float(u[0])
    coarse = np.unique(np.clip(np.concatenate(
        [np.linspace(lo, hi, STAIRCASE_GRID), [u.min(), u.max(), ORIGIN]]), lo, hi))  # fmt: skip
    fine = np.unique(np.concatenate([
        np.linspace(lo, hi, INITIAL_STATE_GRID), _near_first(hc.model, s, idx[-1], lo, hi),
        coarse]))  # fmt: skip
    seen: set = set()
    if len(idx) <= 3:
        scored = _grid_scored(hc, x, idx, itertools.product(*[coarse] * (len(idx) - 1), fine),
                              v0, seen)  # fmt: skip
        if heads is not None and len(idx) == 3:  # for a search with a fourth level
            heads[:] = [t[idx].copy() for _, t in scored[:STAIRCASE_HEADS]]
    else:  # a three-level search's lowest staircases one turning point back
        earlier = coarse[coarse != ORIGIN]  # at the rest: a three-turn staircase again
        scored = _grid_scored(hc, x, idx, ((a, *h) for h in heads or () for a in earlier), v0, seen)
    # the lowest of distinct staircases: each at least a grid step from those taken in
    # some level (the cost is sharp in the levels: near copies of one staircase would
    # fill the list)
    gap = (hi - lo) / (STAIRCASE_GRID - 1)
    taken: list[np.ndarray] = []
    costs: set[float] = set()
    for cost, t in scored:
        if cost not in costs and all(np.max(np.abs(t[idx] - q[idx])) >= gap for q in taken):
            taken.append(t)
            costs.add(cost)  # an equal cost: the same state (a turn another wiped out)
            if len(taken) == STAIRCASE_SCREENED:
                break
    refined = [_refined_staircase(search, hc, t, idx, gap) for t in taken[:STAIRCASE_REFINED]]
    return refined + taken  # the refined ones and, each as found, every one kept


#: Staircases of a three-level grid extended one turning point back, for four levels
#: (:func:`_best_staircases`).
STAIRCASE_HEADS = 48


def _grid_scored(hc: _Counter, x: np.ndarray, idx: list[int], combos, v0: float, seen: set):
    """[(cost on ``hc``'s samples, point)] lowest first: ``x`` with the levels ``idx``
    at every staircase of ``combos`` (earliest first; leading :data:`ORIGIN` values drop
    turning points) that reverses at every level from the rest to ``v0``, one per state
    left (:func:`_wiped`; ``seen`` the states already scored, updated)."""
    scored = []
    for combo in combos:
        path = list(combo)
        while path and path[0] == ORIGIN:
            path.pop(0)  # fewer turning points: the rest held longer
        turns = [ORIGIN, *path, v0]
        if any(
            (b - a) * (c_ - b) >= 0 for a, b, c_ in zip(turns, turns[1:], turns[2:], strict=False)
        ):
            continue  # not a reversal at every level (from the rest on)
        key = _wiped(turns)
        if key in seen:
            continue
        seen.add(key)
        trial = np.asarray(x, dtype=float).copy()
        trial[idx] = [ORIGIN] * (len(idx) - len(path)) + path
        scored.append((hc.cost(trial), trial))
    scored.sort(key=lambda e: e[0])
    return scored


#: Staircases of the grid refined together (:func:`_refined_staircase`), and its rounds.
STAIRCASE_REFINED = 4
STAIRCASE_ROUNDS = 3


def _refined_staircase(search, hc: _Counter, x: np.ndarray, idx: list[int], gap: float):
    """``x`` with its levels ``idx`` moved together to the best point of a local grid on
    ``hc``'s samples: each level at -1/2, -1/4, 0, 1/4, 1/2 of ``gap`` from where it is,
    the step halved each round that finds nothing lower (:data:`STAIRCASE_ROUNDS`
    rounds). The grid's staircases lie up to half a step from a sharp minimum; the
    levels of a staircase interact, so they move together: the three latest on the
    whole grid, an earlier one alone (:func:`_staircase_moves`)."""
    lo, hi = search.lower[idx], search.upper[idx]
    best = (hc.cost(x), np.asarray(x, dtype=float))
    h = gap / 2
    moves = _staircase_moves(len(idx))
    for _ in range(STAIRCASE_ROUNDS):
        centre = best[1]
        for d in moves:
            if any(d):
                trial = centre.copy()
                trial[idx] = np.clip(centre[idx] + h * np.asarray(d), lo, hi)
                cost = hc.cost(trial)
                if cost < best[0]:
                    best = (cost, trial)
        if best[1] is centre:
            h /= 2
    return best[1]


def _staircase_moves(k: int) -> list[tuple[float, ...]]:
    """Moves (in half-steps of :func:`_refined_staircase`'s grid, earliest level first)
    of ``k`` levels: every combination of -1, -1/2, 0, 1/2, 1 of the three latest (the
    turning points the cost is sharpest in), each earlier one alone (a fourth level on
    the whole grid would take 625 evaluations a round instead of 125)."""
    steps = (-1.0, -0.5, 0.0, 0.5, 1.0)
    late = min(k, 3)
    moves = [(0.0,) * (k - late) + d for d in itertools.product(steps, repeat=late)]
    for i in range(k - late):
        moves += [tuple(u if j == i else 0.0 for j in range(k)) for u in steps if u]
    return moves


def _wiped(turns: list[float]) -> tuple[float, ...]:
    """The turning points ``turns`` (the last the first input) without those a later
    excursion wiped out: a reversal pair (a, b) followed by a point beyond a (the
    state a play operator keeps; the rest before them is never wiped). Two
    pre-histories with the same result leave the same state."""
    out: list[float] = []
    for x in turns:
        out.append(x)
        while len(out) >= 4 and (out[-1] - out[-3]) * (out[-3] - out[-4]) >= 0 \
                and abs(out[-1] - out[-2]) >= abs(out[-3] - out[-2]):  # fmt: skip
            del out[-3:-1]
    return tuple(out)


#: Levels per axis of the grid over a motor's last two turning points (:func:`_pair_grid`).
PAIR_GRID = 13


def _motors_levels(search: _Search) -> list[tuple[list[int], int]]:
    """([indices of the earlier turning points], index of the last level) of each motor
    whose pre-history is fitted: this one's, and the other motor's for a model with a
    state of its input."""
    model = search.counter.model
    own = list(search.level_idx[-model.n_own :])
    out = [(own[:-1], own[-1])]
    if model.n_other:
        oth = list(search.level_idx[: model.n_other])
        out.append((oth[:-1], oth[-1]))
    return out


def _pair_grid(search: _Search, full: np.ndarray, turns: list[int], last: int):
    """(cost, point): ``full`` at the best of a :data:`PAIR_GRID` x :data:`PAIR_GRID`
    grid (the bounds included) over one motor's pre-history of two reversals, relaxed
    at a level (every index of ``turns``) and ramping to another (``last``), the other
    parameters held (``full`` itself when no grid point is lower).

    The levels are profiled one at a time elsewhere; a motor's last two reversals
    interact (the order of a loop's two extremes is the branch it starts on), so one
    level moved alone can keep a loop that needs both moved (measured on
    agpi_coupled:5 of bench_optimum, the other motor from its first value via the lower
    bound, 1.013 x the truth's cost; the loop's two extremes, its own history, 1.000).

    With three levels (``turns`` two), the grid's best loop is then also tried one
    turning point back, relaxed at its first extreme, ramping to its second and to a
    last reversal profiled over the whole range and close to the first input
    (:func:`_near_first`): a motor still moving when the recording starts came through
    its last loop and turned a little before the first sample, which a last level on
    the loop's far side (arriving the other way) cannot stand for (measured on
    agpi_coupled:7 of bench_optimum: the other motor had turned 19 counts before the
    recording; from the grid's loop alone the fit ended at 1.0010 x the truth's cost,
    with the reversal at 0.998).
    """
    c = search.counter
    best = (c.cost(full), np.asarray(full, dtype=float))
    lo, hi = search.lower, search.upper
    for a in np.linspace(lo[turns[0]], hi[turns[0]], PAIR_GRID):
        for b in np.linspace(lo[last], hi[last], PAIR_GRID):
            trial = np.asarray(full, dtype=float).copy()
            trial[turns] = a
            trial[last] = b
            cost = c.cost(trial)
            if cost < best[0]:
                best = (cost, trial)
    if len(turns) > 1:
        # the grid's loop, then a last reversal anywhere (close to the first input too:
        # :func:`_near_first`): the loop's extremes one turning point back
        trial = best[1].copy()
        trial[turns[-1]] = trial[last]
        trial = _refine_level(c, trial, last, lo, hi)
        cost = c.cost(trial)
        if cost < best[0]:
            best = (cost, trial)
    return best


#: Later polishes (after the first) run LM for at most this multiple of the first
#: polish's evaluations (at least :data:`MIN_LATER_NFEV`): a poor end's bounded refit
#: can take hundreds of iterations (measured on a 50,000-sample coupled recording: a
#: screened end 188x above the best took 530 iterations, 13 s, to end 3x above it);
#: a later end that becomes the best is then run out to the fit's own limit.
LATER_NFEV_RATIO = 2.0
MIN_LATER_NFEV = 50


def _stop_ratio(first_polish_work: float) -> float:
    """How far above the best polished cost a screened end may be and still be
    polished: :data:`POLISH_STOP_RATIO` while a polish is cheap (its work at most
    1/20 of :data:`WORK_BUDGET`: up to ~10,000 samples), else
    :data:`SCREEN_STOP_RATIO` (a long recording's poor ends are left)."""
    return POLISH_STOP_RATIO if first_polish_work <= WORK_BUDGET / 20 else SCREEN_STOP_RATIO


def _later_cap(max_nfev, first_evals: int):
    """The LM limit of the polishes after the first (:data:`LATER_NFEV_RATIO`)."""
    cap = max(MIN_LATER_NFEV, int(LATER_NFEV_RATIO * first_evals))
    return cap if max_nfev is None else min(max_nfev, cap)


def _released(search: _Search, x: np.ndarray, typical: np.ndarray) -> np.ndarray | None:
    """A restart from the end ``x`` with every LM-fitted parameter that sits on a bound
    moved to its ``typical`` start value (the starts' median), or None when none sits on
    a bound (or the typical value is on it too).

    A parameter on a bound is either a constrained optimum (the cost falls towards the
    bound) or a local minimum's accident: an interior start that reaches a lower cost
    is a search failure, not a fact about the data (measured on the README demo's
    pitch+: kappa at its bound 100 with cost 6.4, the interior basin kappa 4.1 at 0.55).
    """
    levels = search.level_idx
    at = [
        int(i) for i in search.lsq_free
        if i not in levels  # a level on its bound: the input came from far, no accident
        if _on_bound(x[i], search.lower[i], search.upper[i])
        and not _on_bound(typical[i], search.lower[i], search.upper[i])
        and search.lower[i] < typical[i] < search.upper[i]
    ]  # fmt: skip
    if not at:
        return None
    out = np.asarray(x, dtype=float).copy()
    out[at] = typical[at]
    return out


def _hop(search: _Search, x: np.ndarray, ref: np.ndarray, rng) -> np.ndarray:
    """A restart near the end ``x``: every LM-fitted parameter perturbed
    (:data:`HOP_SPREAD`; a positive one by a log-normal factor on at least 5 % of its
    typical magnitude ``ref``, so one at a zero bound moves too), kept inside its bounds;
    a profiled flag point moved by :data:`HOP_FLAG_SPREAD` of the input range."""
    out = np.asarray(x, dtype=float).copy()
    for i in search.lsq_free:
        lo, hi = search.lower[i], search.upper[i]
        if lo >= 0:
            val = max(out[i], 0.05 * ref[i]) * np.exp(rng.normal(0.0, HOP_SPREAD))
        else:
            val = out[i] + rng.normal(0.0, HOP_SPREAD) * max(abs(out[i]), ref[i], 1e-12)
        out[i] = min(max(val, lo), hi)
    span = float(np.ptp(search.v))
    for i in search.pidx:  # the flag point: moved by HOP_FLAG_SPREAD of the input range
        if i not in search.lsq_free:
            val = out[i] + rng.normal(0.0, HOP_FLAG_SPREAD) * span
            out[i] = min(max(val, search.lower[i], float(search.v.min())), search.upper[i])
    return out


def _polished_end(search: _Search, x: np.ndarray, max_nfev):
    """(cost, end, least_squares result or None, notes) of the screened end ``x``
    polished by :data:`POLISH_STEPS` with LM runs to convergence and brought inside the
    bounds (a :class:`FitNote` ``"left_bounds"`` when that needed a bounded refit).

    Without a profiled flag point, an unbounded end outside the bounds goes to the
    bounded refit as it is (an unbounded polish would only be clipped back; measured on
    the coupled two-tendon GPI: the same end, 2.6 s less). A flag-point model's polish
    re-optimises v_f with the other parameters (``"reopt"``) first (measured without it:
    continuous EGPI fits 2 % higher in cost). An unbounded LM end outside the bounds is
    refitted bounded (:func:`_bounded_polish`) from it brought into them
    (:func:`_into_bounds`; measured: ends far better than trf from a better-scoring
    start)."""
    if search.outside(x) and not search.pidx:
        cost, full, res = search.counter.cost(x), x, None
    else:
        cost, full, res = search.run(x, max_nfev, POLISH_STEPS)
    left = search.outside(full)
    if not left:
        return cost, full, res, ()
    # the bounded refit holds the initial-state levels for LM (profiled in its steps):
    # measured on a 50,000-sample coupled recording, with them free the held LM runs
    # took 300 iterations each (34 s) to a cost above the unbounded end's
    bounded = search.without_levels()
    start = _into_bounds(bounded, full, left, max_nfev)
    (cost, full, res), how = _bounded_polish(bounded, start, max_nfev)
    if bounded is not search and res is not None:  # the covariance's columns: every LM one
        res = OptimizeResult(res, jac=_jacobian_at(search.counter, full, search.lsq_free))
    names = search.names
    note = FitNote(
        "left_bounds",
        f"LM left the bounds ({', '.join(names[i] for i in left)}); refitted bounded ({how})",
        tuple(names[i] for i in left),
    )
    return cost, full, res, (note,)


def _jacobian_at(counter: _Counter, full: np.ndarray, free) -> np.ndarray:
    """The residuals' Jacobian over the parameters ``free`` at ``full``: the model's
    own (:meth:`_Counter.jacobian`), else forward differences (as least_squares'
    "2-point")."""
    if counter.jac_fn is not None:
        return counter.jacobian(full, free)
    base = counter.residuals(full)
    cols = []
    for i in free:
        h = np.sqrt(np.finfo(float).eps) * max(1.0, abs(float(full[i])))
        trial = np.asarray(full, dtype=float).copy()
        trial[i] += h
        cols.append((counter.residuals(trial) - base) / h)
    return np.stack(cols, axis=1) if cols else np.zeros((base.size, 0))


#: An end within this relative cost of the floor (the lowest start or screened point)
#: has reached it: the least-squares solvers' rounding (measured: a trf polish of a
#: three-level start state ending 1.2e-9 above the screened point it started from).
FLOOR_RTOL = 1e-8


def _floor_checked(search: _Search, found: _Found, known, max_nfev):
    """((cost, end, least_squares result), floor, notes): the best polished end, no
    worse than a point already reached.

    ``floor``: the lowest-cost point of ``known`` inside the bounds (None: none). An end
    worse than the floor is refitted bounded from the floor (trf only accepts steps that
    lower the cost, so it cannot end worse than it). ``notes``: :class:`FitNote` of the
    best end's bounded refit and of this one.
    """
    cost, full, res, notes = found.best()
    notes = list(notes)
    inside = [(c, x) for c, x in known if np.isfinite(c) and not search.outside(x)]
    floor = min(inside, key=lambda c: c[0]) if inside else None
    if floor is not None and not cost <= floor[0] * (1 + FLOOR_RTOL):
        cost, full, res = search.run(floor[1], max_nfev, POLISH_STEPS, "trf")
        notes.append(
            FitNote(
                "refit_from_start",
                f"ended worse than a start/screened point (cost {floor[0]:.4g}); refitted bounded (trf) from it",
            )
        )
    return (cost, full, res), floor, notes


def _pushed_out(search: _Search, full: np.ndarray) -> tuple[list[int], np.ndarray]:
    """(the LM-fitted parameters of ``full`` (inside the bounds) on a bound that the cost
    pushes outward (its gradient points out of the bounds there), the Jacobian of those
    parameters' columns at ``full``)."""
    c, lo, hi, free = search.counter, search.lower, search.upper, search.lsq_free
    jac = c.jacobian(full, free)
    half_grad = jac.T @ c.residuals(full)
    out = [
        int(i)
        for i, g in zip(free, half_grad, strict=True)
        if (full[i] <= lo[i] and g > 0) or (full[i] >= hi[i] and g < 0)
    ]
    return out, jac


def _bounded_polish(search: _Search, x0: np.ndarray, max_nfev):
    """((cost, end, least_squares result), how) of the bounded polish
    (:data:`POLISH_STEPS`) from ``x0`` (inside the bounds); ``how``: ``"trf"`` or
    ``"LM, <names> held at a bound"`` (the method that gave the end, for the fit's note).

    Active set first: the parameters on a bound that the cost pushes outward are held
    there and the others polished by (unbounded) LM. Its end is taken when it is inside
    the bounds and the held ones are still pushed outward (a bounded minimum, as trf's
    end; the result's Jacobian then has every LM-fitted column, for the covariance);
    still inside but one of them pulled in: trf from that end. A held LM that pushes
    other parameters out of their bounds holds those at the bounds they crossed too and
    runs again from there (:func:`_held_lm`); still outside (or above ``x0``'s cost):
    trf from ``x0`` (as without the active set; measured on the two-tendon GPI and the
    coupled model of a 50,000-sample coupled recording, seed 202: the two-tendon GPI
    one more held run of 22 evaluations instead of trf's 156, 4.5 -> 2.0 s, a 1e-4 lower
    cost). trf approaches a bound by ever shorter steps (measured
    on the coupled two-tendon GPI, a coupling side's sigma at 0: 35 Jacobians for 1e-4
    of the cost, where the held LM took 25 to the same end). A model with a profiled
    flag point goes to trf at once (measured on the continuous EGPI: the active set's
    end mostly left the bounds again, its time lost).
    """
    if search.counter.jac_fn is None or search.method != "lm" or search.pidx:
        return search.run(x0, max_nfev, POLISH_STEPS, "trf"), "trf"
    held, _ = _pushed_out(search, x0)
    cost, end, res, held = _held_lm(search, x0, held, max_nfev)
    if search.outside(end) or not cost <= search.counter.cost(x0):
        return search.run(x0, max_nfev, POLISH_STEPS, "trf"), "trf"
    still, jac = _pushed_out(search, end)
    if res is None or not set(held) <= set(still):
        return search.run(end, max_nfev, POLISH_STEPS, "trf"), "trf"
    how = f"LM, {', '.join(search.names[i] for i in held)} held at a bound" if held else "LM"
    return (cost, end, OptimizeResult(res, jac=jac)), how


def _held_lm(search: _Search, x0: np.ndarray, held: list[int], max_nfev):
    """(cost, end, least_squares result, the held parameters) of :data:`POLISH_STEPS`
    by LM from ``x0`` over the LM-fitted parameters not in ``held`` (held where ``x0``
    has them); when the end leaves the bounds, the parameters that left are held at the
    bounds they crossed too and the rest refitted from the clipped end, up to
    :data:`INTO_BOUNDS_ROUNDS` runs in all (the last end returned, inside the bounds or
    not)."""
    held, start = list(held), x0
    for _ in range(INTO_BOUNDS_ROUNDS):
        others = np.array([i for i in search.lsq_free if i not in held], dtype=int)
        cost, end, res = replace(search, lsq_free=others).run(start, max_nfev, POLISH_STEPS, "lm")
        escaped = search.outside(end)
        if not escaped or others.size == len(escaped):
            break
        held += escaped
        start = np.clip(end, search.lower, search.upper)
    return cost, end, res, held


#: An LM end outside the bounds whose clipping multiplies the cost by more than this
#: is brought back by LM over the other parameters before the bounded refit
#: (:func:`_into_bounds`); measured ratios: 1.1-1.7 on GPI, EGPI_C and the two-tendon
#: GPI (clipping alone is the better trf start there), 275 on the coupled one.
CLIP_COST_RATIO = 2.0
#: Largest number of held LM runs in :func:`_into_bounds` (each holds the parameters the
#: one before pushed out of their bounds).
INTO_BOUNDS_ROUNDS = 3


def _into_bounds(search: _Search, full: np.ndarray, left: list[int], max_nfev) -> np.ndarray:
    """Start of the bounded refit of an LM end ``full`` with the parameters ``left``
    outside their bounds: ``full`` clipped into the bounds; when clipping costs more
    than :data:`CLIP_COST_RATIO` x the end's cost, the other parameters then re-fitted
    by LM with those held at their bounds, if that ends inside the bounds (LM never
    ends above its start).

    Clipping alone can cost much of the fit (measured on the coupled two-tendon GPI:
    cost x275, and trf took ~100 iterations, each with an SVD of the Jacobian, back); the
    held LM brings it back in fewer, cheaper iterations, so the bounded refit starts
    near its end. The refit is the same trf search from a point no worse than the
    clipped one. When the held LM pushes other parameters out of their bounds, they are
    held at those bounds too and the rest refitted from there, up to
    :data:`INTO_BOUNDS_ROUNDS` LM runs (measured on a 50,000-sample coupled recording:
    the coupling's ``sigma_cn`` and ``r1_cn`` left with the first three held, the
    bounded refit then fell back to trf from the clipped point: 7.4 -> 5.7 s, the same
    cost to 1e-4). A model with a profiled flag point starts its bounded refit (trf) at
    the clipped point (measured on the continuous EGPI, 50,000 samples: the held LM took
    230 evaluations to a start that trf left anyway, 6.35 -> 4.52 s, the same RMSE; three
    held runs led trf to a 2 % higher RMSE).
    """
    clipped = np.clip(full, search.lower, search.upper)
    c = search.counter
    if search.pidx or not c.cost(clipped) > CLIP_COST_RATIO * c.cost(full):
        return clipped
    held, at = clipped, list(left)
    for _ in range(INTO_BOUNDS_ROUNDS):
        others = np.array([i for i in search.lsq_free if i not in at], dtype=int)
        if others.size == 0:
            return clipped
        held, _ = _lsq(c, held, others, search.lower, search.upper, "lm", max_nfev, search.ftol)
        escaped = search.outside(held)
        if not escaped:
            break
        at += escaped  # held at the bounds they crossed, the rest refitted from there
        held = np.clip(held, search.lower, search.upper)
    if search.outside(held) or not c.cost(held) <= c.cost(clipped):
        return clipped
    return held


def _shown(x: float, search: _Search, name: str) -> str:
    """``x`` as the bound it sits on when within 1e-6 of it ("0", not "6.7e-10")."""
    i = search.names.index(name)
    for b in (search.lower[i], search.upper[i]):
        if _on_bound(x, b, b):
            return f"{b:.6g}"
    return f"{x:.6g}"


def _with_notes(result: FitResult, search: _Search, cost, full, floor, notes) -> FitResult:
    """``result`` with the fitter's notes: not converged when still worse than the
    ``floor`` (``"not_a_minimum"``), NaN standard errors for parameters a bounded
    refit left on a bound (``"at_bound"``), every note appended to the message."""
    notes = list(notes)
    names = search.names
    if floor is not None and not cost <= floor[0] * (1 + FLOOR_RTOL):
        result = replace(result, converged=False)
        notes.append(
            FitNote(
                "not_a_minimum",
                f"NOT a minimum: cost {cost:.4g} above that of a start ({floor[0]:.4g})",
            )
        )
    refitted = any(n.code == "left_bounds" for n in notes)
    at_bound = (
        [names[i] for i in search.lsq_free if _on_bound(full[i], search.lower[i], search.upper[i])]
        if refitted
        else []
    )
    if at_bound:
        notes.append(FitNote("at_bound", f"at the bound: {', '.join(at_bound)}", tuple(at_bound)))
    stderr = result.stderr | dict.fromkeys(at_bound, float("nan"))
    reasons = result.stderr_reasons | {
        nm: (
            f"at its bound ({_shown(full[names.index(nm)], search, nm)}): the lowest cost "
            "found has it there (a constrained optimum, not a lack of data); the covariance "
            "does not apply at a bound"
        )
        for nm in at_bound
    }
    message = result.message + "".join(f" [{n.text}]" for n in notes)
    return replace(
        result, message=message, stderr=stderr, notes=tuple(notes), stderr_reasons=reasons
    )


def _nested_fit(model, s, theta, starts, opts) -> tuple[np.ndarray, FitResult] | None:
    """(start vector, fit of the wrapped model) for a model with ``nested()``: the
    wrapped model fitted with the same options from the wrapped part of every start,
    followed by the values that switch the extension off; None for other models."""
    nested = getattr(model, "nested", None)
    if not callable(nested):
        return None
    inner, tail = nested()
    m = len(inner.parameters)
    try:
        res = _fit_model(inner, s, theta, starts=[x[:m] for x in starts], **opts)
    except CalibError:
        return None
    x = np.concatenate([[p.value for p in res.model.parameters], np.asarray(tail, float)])
    return x, res


def _without_level(
    result: FitResult, model: Model, v: np.ndarray, full: np.ndarray, cycle: int = 0,
    v_other=None, n_own: int = 3,
) -> FitResult:  # fmt: skip
    """``result`` of a :class:`_FromLevel` fit in terms of ``model``: the levels
    (v_turn2, v_turn, v_from, the other motor's) and the replayed ``cycle`` leave the parameters
    for :attr:`FitResult.initial_state`."""
    own = [float(x) for x in full[-n_own:]]
    ut3, ut2, ut, u = own[0], own[max(-3, -n_own)], own[-2], own[-1]
    p = len(model.parameters)
    names = tuple(pp.name for pp in model.parameters)
    st = _FromLevel(model, v, cycle, v_other, n_own)
    sig = Signals(
        v=np.asarray(v, float), v_other=None if v_other is None else np.asarray(v_other, float)
    )
    n_pre = st.prehistory(sig, full[-st.levels :])[1]
    other = {}
    if st.n_other:
        o_lv = [float(x) for x in full[-st.levels : -n_own]]
        o_turn2, o_turn, o_from = [o_lv[0]] * (3 - len(o_lv)) + o_lv
        vo0 = float(np.asarray(v_other, float)[0])
        other = dict(
            other_v_turn=None if o_turn == o_from else o_turn, other_v_from=o_from, v0_other=vo0,
            other_v_turn2=None if o_turn2 == o_turn else o_turn2,
        )  # fmt: skip
    state = InitialState(
        u,
        int(n_pre),
        float(v[0]),
        "",
        int(cycle),
        None if ut == u else ut,
        **other,
        v_turn2=None if ut2 == ut else ut2,
        v_turn3=None if ut3 == ut2 else ut3,
    )
    return replace(
        result,
        params={k: result.params[k] for k in names},
        stderr={k: result.stderr[k] for k in names},
        stderr_reasons={k: r for k, r in result.stderr_reasons.items() if k in names},
        covariance=result.covariance[:p, :p],
        free=tuple(k for k in result.free if k in names),
        initial_state=replace(state, text=state_text(state)),
    )


def _on_bound(x: float, lo: float, hi: float) -> bool:
    """True when ``x`` sits on (within 1e-6 relative of) ``lo`` or ``hi``; an infinite
    bound is never reached."""

    def near(b: float) -> bool:
        return bool(np.isfinite(b)) and abs(x - b) <= 1e-6 * (1 + abs(b))

    return near(lo) or near(hi)


#: The optimiser's stop (``least_squares`` status codes, also :mod:`.lm`'s) in plain
#: words: what fit.json's ``message``, the tables and :meth:`FitResult.fit_report` say.
PLAIN_MESSAGES = {
    -1: "the optimiser refused its input",
    0: "the evaluation limit (max_nfev) was reached before the cost settled",
    1: "no downhill direction left (gradient ~ 0)",
    2: "the cost stopped decreasing",
    3: "the parameters stopped changing",
    4: "the cost and the parameters stopped changing",
}


def plain_message(res) -> str:
    """The optimiser's stop in plain words (:data:`PLAIN_MESSAGES` by ``res.status``;
    its own message for another status)."""
    return PLAIN_MESSAGES.get(getattr(res, "status", None), str(getattr(res, "message", "")))


def _outside(full, free, lower, upper) -> list[int]:
    """Indices of free parameters outside their bounds."""
    return [int(i) for i in free if not lower[i] <= full[i] <= upper[i]]


def _result(
    model, s, theta, used, hold, full, res, names, is_free, pidx, nfev, n_starts, lsq_idx,
    uidx=None,
) -> FitResult:  # fmt: skip
    fitted = model.with_values(full)
    y = model.evaluate(s, full)
    resid = y - theta
    n = int(used.sum())
    k = int(is_free.sum())
    rss = float(np.sum(resid[used] ** 2))
    cov, stderr, reasons = _covariance(res, names, lsq_idx, n, k, rss)
    for i in (i for i in pidx if i not in set(int(j) for j in lsq_idx)):
        stderr[names[i]] = float("nan")
        reasons[names[i]] = (
            "profiled: the output steps in it (piecewise constant), so it has no "
            "derivative and no covariance; it is placed at the centre of the best interval"
        )
    if uidx is not None:
        for i in range(uidx - model.levels + 1, uidx + 1):
            stderr[names[i]] = float("nan")
    converged = bool(np.isfinite(rss)) and (res is None or res.status > 0)
    message = "profile search only" if res is None else plain_message(res)
    outside = [
        p.name
        for p, x in zip(model.parameters, full, strict=True)
        if not p.fixed and not p.lower <= x <= p.upper
    ]
    if outside:
        message += f" [outside bounds: {', '.join(outside)}; use method 'trf' for a bounded fit]"
    aic, bic = information_criteria(rss, n, k)
    return FitResult(
        model=fitted,
        params=dict(zip(names, map(float, full), strict=True)),
        stderr=stderr,
        covariance=cov,
        residuals=resid,
        metrics=metrics(theta, y, used),
        holdout_metrics=metrics(theta, y, hold) if hold.any() else NAN_METRICS,
        aic=aic,
        bic=bic,
        converged=converged,
        message=message,
        nfev=int(nfev),
        n_samples=n,
        free=tuple(names[i] for i in np.flatnonzero(is_free)),
        starts_tried=n_starts,
        extra={"outside_bounds": outside},
        stderr_reasons=reasons,
    )


def _covariance(res, names, lsq_idx, n: int, k: int, rss: float):
    """(covariance (p, p), stderr by name, reasons by name) of the least-squares
    parameters ``lsq_idx`` from the final Jacobian ``res.jac`` (``n`` fitted samples,
    ``k`` free parameters, residual sum of squares ``rss``): the pseudo-inverse of the
    column-scaled ``J^T J`` times ``rss / (n - k)``; a parameter in the Jacobian's null
    space (unidentified by these data) gets NaN and a reason. Parameters outside
    ``lsq_idx`` keep stderr 0 (fixed) until the caller says otherwise."""
    p = len(names)
    cov = np.zeros((p, p))
    stderr = dict.fromkeys(names, 0.0)
    reasons: dict[str, str] = {}
    lsq_idx = [int(i) for i in lsq_idx]
    if lsq_idx and n <= k:
        for i in lsq_idx:
            stderr[names[i]] = float("nan")
            reasons[names[i]] = f"{n} fitted samples for {k} free parameters: no residual variance"
    if res is None or not lsq_idx or n <= k:
        return cov, stderr, reasons
    J = np.asarray(res.jac, dtype=float)
    s2 = rss / (n - k)
    # pseudo-inverse of the column-scaled J^T J (p x p, cheap) by eigen-decomposition
    norm = np.linalg.norm(J, axis=0)
    d = np.where(norm > 0, 1.0 / np.where(norm > 0, norm, 1.0), 0.0)
    evals, evecs = np.linalg.eigh((J * d).T @ (J * d))
    ok = evals > max(evals.max(), 0.0) * 1e-12
    c = d[:, None] * ((evecs[:, ok] / evals[ok]) @ evecs[:, ok].T) * d[None, :] * s2
    for a, ia in enumerate(lsq_idx):
        for b, ib in enumerate(lsq_idx):
            cov[ia, ib] = c[a, b]
    # parameters in the Jacobian's null space (unidentified by these data) get NaN
    unidentified = (np.abs(evecs[:, ~ok]) > 0.1).any(axis=1)
    for a, ia in enumerate(lsq_idx):
        stderr[names[ia]] = float("nan") if unidentified[a] else float(np.sqrt(max(c[a, a], 0.0)))
    reasons |= _unidentified_reasons(norm, evecs[:, ~ok], [names[i] for i in lsq_idx])
    return cov, stderr, reasons


def _unidentified_reasons(norm: np.ndarray, null: np.ndarray, names: list[str]) -> dict[str, str]:
    """Why each parameter in the Jacobian's null space has no standard error.

    Parameters
    ----------
    norm : ndarray, shape (q,)
        Norm of each Jacobian column (0: the output does not depend on it).
    null : ndarray, shape (q, m)
        Null-space directions of the column-scaled J^T J.
    names : list of str
        Parameter names of the columns.
    """
    out = {}
    for a, nm in enumerate(names):
        if norm[a] == 0:
            out[nm] = "no effect on the fitted samples: the output does not change with it"
            continue
        dirs = [j for j in range(null.shape[1]) if abs(null[a, j]) > 0.1]
        if not dirs:
            continue
        with_ = sorted(
            {names[b] for j in dirs for b in range(len(names)) if b != a and abs(null[b, j]) > 0.1}
        )
        out[nm] = (
            "not identified: these data cannot tell it apart from "
            + (", ".join(with_) if with_ else "a constant")
            + " (singular covariance: changing them together leaves the output the same)"
        )
    return out


# fit_model shows _fit_model's docstring and signature (inspect.signature follows __wrapped__)
functools.update_wrapper(fit_model, _fit_model, assigned=("__doc__", "__annotations__"))
