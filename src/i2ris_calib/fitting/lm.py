"""Levenberg-Marquardt for tall problems: Moré's trust-region LM with the step solved
from the normal equations.

MINPACK's ``lmder`` (scipy's ``least_squares(method="lm")``) factors the m x n Jacobian
by an unblocked Householder QR every iteration, 2 m n^2 flops. On a 50,000-sample
recording (37,500 fitted rows, 25 free parameters) that is ~10 ms per iteration, as
long as the model's own Jacobian, and half of a fit's time. This module runs the same
algorithm (Moré 1978, as ``lmder`` with ``mode=1``: scaling by the running maximum of
the column norms, the same trust-region radius updates, step acceptance and
termination tests, ``factor = 100``) but solves each step from J^T J (one BLAS product,
m n^2 / 2 flops, ~1.5 ms there) and its eigen-decomposition (n x n). The LM parameter is
found by the same safeguarded Newton iteration as MINPACK's ``lmpar``; with the
eigenvalues it costs O(n) per trial value.

Forming J^T J squares the condition number of the scaled Jacobian, so a step comes from
the normal equations only while the scaled J^T J's eigenvalues span at most 1e10
(:data:`NORMAL_MIN_EIGEN_RATIO`, a step accurate to ~1e-6); a worse-conditioned or
rank-deficient iteration takes its step from a QR of the Jacobian and the SVD of its R
(as accurate as MINPACK's QR; directions of singular values below ``n eps`` of the
largest are dropped, as ``lmpar`` does for a singular R), and a Jacobian whose J^T J
overflows hands the rest of the run to MINPACK. LM's acceptance test (actual against
predicted reduction) checks every step either way. The fitter uses this module for every
LM run, small ones too: scipy's MINPACK (1.17) took different steps from the same
residuals and Jacobian in different processes (a 300-sample coupled fit ended anywhere
between 4.1 and 6.0 in cost), while this module is reproducible to the last bit
(tests/fitting/test_determinism.py); its optimum is as good (``bench_optimum.py``, 20
cases of egpi, agpi and agpi_coupled: the same shares as with MINPACK).

References
----------
J. J. Moré, "The Levenberg-Marquardt algorithm: implementation and theory", Numerical
Analysis, Lecture Notes in Mathematics 630, Springer, 1978, pp. 105-116.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import OptimizeResult, least_squares

_EPS = float(np.finfo(float).eps)
_DWARF = float(np.finfo(float).tiny)

#: The normal equations solve a step only when the scaled J^T J's smallest eigenvalue
#: is at least this fraction of its largest (condition number of the scaled Jacobian
#: <= 1e5, a step accurate to ~1e-6); below it the step comes from a QR of the Jacobian.
NORMAL_MIN_EIGEN_RATIO = 1e-10

#: Messages of the result's ``status`` (scipy's ``least_squares`` codes).
MESSAGES = {
    0: "The maximum number of function evaluations is exceeded.",
    1: "`gtol` termination condition is satisfied.",
    2: "`ftol` termination condition is satisfied.",
    3: "`xtol` termination condition is satisfied.",
    4: "Both `ftol` and `xtol` termination conditions are satisfied.",
}


@dataclass(frozen=True)
class ScaledSystem:
    """The Gauss-Newton system at one point in scaled variables q = D p.

    Attributes
    ----------
    eigenvalues : ndarray, shape (n,)
        Eigenvalues of D^-1 J^T J D^-1 (ascending; those below ``n eps`` of the largest
        set to 0).
    b : ndarray, shape (n,)
        V^T D^-1 J^T f, the scaled gradient in the eigenvector basis V.
    vectors : ndarray, shape (n, n)
        The eigenvectors V (columns).
    normal : bool
        Made from the normal equations (:meth:`of`), not from a QR (:meth:`of_qr`).
    """

    eigenvalues: np.ndarray
    b: np.ndarray
    vectors: np.ndarray
    normal: bool = True

    @classmethod
    def of(cls, jtj: np.ndarray, jtf: np.ndarray, diag: np.ndarray) -> ScaledSystem | None:
        """The system of J^T J (n, n), J^T f (n,) and the scaling D (n,); None when
        the scaled J^T J is too ill-conditioned for its eigen-decomposition to resolve
        every direction (smallest eigenvalue below :data:`NORMAL_MIN_EIGEN_RATIO` of
        the largest; use :meth:`of_qr`)."""
        lam, vec = np.linalg.eigh(jtj / np.outer(diag, diag))
        if not lam[0] >= lam[-1] * NORMAL_MIN_EIGEN_RATIO:
            return None
        return cls(lam, vec.T @ (jtf / diag), vec)

    @classmethod
    def of_qr(cls, jac: np.ndarray, f: np.ndarray, diag: np.ndarray) -> ScaledSystem:
        """The system from a QR of [J D^-1, f] (m, n + 1) and the SVD of its R: as
        accurate as MINPACK's QR (eigenvalues sigma^2 of R, b = sigma U^T Q^T f
        without squaring the condition number); singular values below ``n eps`` of
        the largest count as 0."""
        n = diag.size
        r = np.linalg.qr(np.column_stack([jac / diag, f]), mode="r")
        u, sig, vt = np.linalg.svd(r[:n, :n])
        sig = np.where(sig > sig[0] * n * _EPS, sig, 0.0)[::-1]
        b = sig * (u.T @ r[:n, n])[::-1]
        return cls(sig**2, b, vt[::-1].T, normal=False)

    def step_norm(self, par: float) -> float:
        """||q(par)||, the scaled length of the step at LM parameter ``par``."""
        return float(np.sqrt(np.sum(self._weights(par) ** 2)))

    def step(self, par: float) -> np.ndarray:
        """q(par) = -(S + par I)^-1 D^-1 J^T f, shape (n,) (directions of zero
        eigenvalue left out at par = 0)."""
        return -(self.vectors @ self._weights(par))

    def _weights(self, par: float) -> np.ndarray:
        d = self.eigenvalues + par
        return np.divide(self.b, d, out=np.zeros_like(self.b), where=d > 0)

    def newton_slope(self, par: float) -> float:
        """q^T (S + par I)^-1 q / ||q||^2 at ``par`` (the Newton correction's
        denominator in ``lmpar``, ||R^-T D q / ||D q|| ||^2 there)."""
        w = self._weights(par)
        d = self.eigenvalues + par
        num = np.sum(np.divide(w * w, d, out=np.zeros_like(w), where=d > 0))
        return float(num / np.sum(w * w))

    @property
    def singular(self) -> bool:
        return bool(self.eigenvalues[0] == 0.0)


def lm_parameter(system: ScaledSystem, delta: float, par: float) -> float:
    """The LM parameter for the trust radius ``delta`` (MINPACK ``lmpar``'s iteration):
    0 when the Gauss-Newton step is within 1.1 ``delta``, else par > 0 with the step's
    scaled length within 10 % of ``delta`` (at most 10 Newton iterations, safeguarded
    by the bounds parl, paru).

    Parameters
    ----------
    system : ScaledSystem
    delta : float
        Trust-region radius (scaled units), > 0.
    par : float
        The previous LM parameter (the iteration's start).
    """
    dxnorm = system.step_norm(0.0)
    fp = dxnorm - delta
    if fp <= 0.1 * delta:
        return 0.0
    parl = 0.0 if system.singular else fp / delta / system.newton_slope(0.0)
    gnorm = float(np.linalg.norm(system.b))
    paru = gnorm / delta
    if paru == 0.0:
        paru = _DWARF / min(delta, 0.1)
    par = min(max(par, parl), paru)
    if par == 0.0:
        par = gnorm / dxnorm
    for it in range(1, 11):
        if par == 0.0:
            par = max(_DWARF, 0.001 * paru)
        dxnorm = system.step_norm(par)
        previous, fp = fp, dxnorm - delta
        if abs(fp) <= 0.1 * delta or (parl == 0.0 and fp <= previous < 0.0) or it == 10:
            break
        if dxnorm == 0.0:
            break
        parc = fp / delta / system.newton_slope(par)
        if fp > 0.0:
            parl = max(parl, par)
        elif fp < 0.0:
            paru = min(paru, par)
        par = max(parl, par + parc)
    return par


def least_squares_lm(
    fun: Callable[[np.ndarray], np.ndarray],
    jac: Callable[[np.ndarray], np.ndarray],
    x0: np.ndarray,
    *,
    ftol: float = 1e-8,
    xtol: float = 1e-8,
    gtol: float = 1e-8,
    max_nfev: int | None = None,
    factor: float = 100.0,
) -> OptimizeResult:
    """Minimise 1/2 ||fun(x)||^2 by Moré's LM (``lmder``, ``mode=1``), steps from the
    normal equations.

    Parameters
    ----------
    fun : callable
        x (n,) -> residuals (m,), m >= n, finite.
    jac : callable
        x (n,) -> Jacobian (m, n).
    x0 : ndarray, shape (n,)
        Start.
    ftol, xtol, gtol : float
        scipy ``least_squares``' tolerances (relative cost reduction, relative step,
        scaled gradient), each >= machine epsilon.
    max_nfev : int, optional
        Limit on evaluations of ``fun`` (default 100 n, as scipy's ``lm``).
    factor : float
        Initial trust radius, ``factor`` x ||D x0|| (MINPACK's default 100).

    Returns
    -------
    OptimizeResult
        As ``scipy.optimize.least_squares(method="lm")``: ``x``, ``cost`` (1/2 ||f||^2),
        ``fun``, ``jac`` (at ``x``), ``grad``, ``optimality``, ``active_mask`` (zeros),
        ``nfev``, ``njev``, ``status`` (0 evaluations exhausted, 1 gtol, 2 ftol, 3 xtol,
        4 ftol and xtol), ``message``, ``success``.
    """
    state = _State.start(fun, x0)
    max_nfev = 100 * state.x.size if max_nfev is None else int(max_nfev)
    status = None
    while status is None:
        J = np.asarray(jac(state.x), dtype=float)
        state.njev += 1
        with np.errstate(over="ignore", invalid="ignore"):
            jtj, jtf = J.T @ J, J.T @ state.f
        if not (np.isfinite(jtj).all() and np.isfinite(jtf).all()):
            # entries beyond ~1e154: MINPACK's QR (with its scaled norms) takes over
            return _minpack_from(fun, jac, state, ftol, xtol, gtol, max_nfev)
        jacnorm = np.sqrt(np.diag(jtj))
        if state.it == 1:
            state.scale_from(jacnorm, factor)
        gnorm = _scaled_gradient_norm(jtf, jacnorm, state.fnorm)
        if gnorm <= gtol:
            status = 1
            break
        state.diag = np.maximum(state.diag, jacnorm)
        system = ScaledSystem.of(jtj, jtf, state.diag) or ScaledSystem.of_qr(J, state.f, state.diag)
        status = _steps_until_accepted(state, fun, (J, jtj), system, gnorm, (ftol, xtol, max_nfev))
    J = np.asarray(jac(state.x), dtype=float)
    g = J.T @ state.f
    return OptimizeResult(
        x=state.x, cost=0.5 * float(state.f @ state.f), fun=state.f, jac=J, grad=g,
        optimality=float(np.max(np.abs(g))) if g.size else 0.0,
        active_mask=np.zeros(state.x.size, dtype=int), nfev=state.nfev, njev=state.njev,
        status=status, message=MESSAGES[status], success=status > 0,
    )  # fmt: skip


@dataclass
class _State:
    """The LM search's state (``lmder``'s variables): point, residuals and their norm,
    evaluation counts, iteration number, LM parameter, scaling D, trust radius,
    ||D x||."""

    x: np.ndarray
    f: np.ndarray
    fnorm: float
    nfev: int = 1
    njev: int = 0
    it: int = 1
    par: float = 0.0
    diag: np.ndarray | None = None
    delta: float = 0.0
    xnorm: float = 0.0

    @classmethod
    def start(cls, fun, x0) -> _State:
        x = np.array(x0, dtype=float)
        f = np.asarray(fun(x), dtype=float)
        return cls(x, f, _norm(f))

    def scale_from(self, jacnorm: np.ndarray, factor: float) -> None:
        """The first iteration's scaling (the column norms, 1 for a zero column) and
        trust radius (``factor`` ||D x0||, or ``factor``)."""
        self.diag = np.where(jacnorm == 0.0, 1.0, jacnorm)
        self.xnorm = float(np.linalg.norm(self.diag * self.x))
        self.delta = factor * self.xnorm if self.xnorm != 0.0 else factor


def _steps_until_accepted(state: _State, fun, jacs, system, gnorm, tolerances) -> int | None:
    """Trial steps from ``state`` (one LM parameter each, the radius shrinking after
    each refused one) until one is accepted (actual / predicted reduction >= 1e-4;
    ``state`` moves there) or a termination test holds (its status returned; else
    None). ``jacs``: (J, J^T J)."""
    ftol, xtol, max_nfev = tolerances
    J, jtj = jacs
    while True:
        state.par = lm_parameter(system, state.delta, state.par)
        p = system.step(state.par) / state.diag
        pnorm = float(np.linalg.norm(state.diag * p))
        if state.it == 1:
            state.delta = min(state.delta, pnorm)
        x_new = state.x + p
        f_new = np.asarray(fun(x_new), dtype=float)
        state.nfev += 1
        fnorm1 = _norm(f_new)
        ratio, actred, prered, state.delta, state.par = _trust_update(
            state.fnorm, fnorm1, _model_norm(p, J, jtj, system), state.par, pnorm, state.delta
        )
        if ratio >= 1e-4:
            state.x, state.f, state.fnorm = x_new, f_new, fnorm1
            state.xnorm = float(np.linalg.norm(state.diag * state.x))
            state.it += 1
        status = _termination(actred, prered, ratio, state.delta, state.xnorm, gnorm,
                              state.nfev, ftol, xtol, max_nfev)  # fmt: skip
        if status is not None or ratio >= 1e-4:
            return status


def _minpack_from(fun, jac, state: _State, ftol, xtol, gtol, max_nfev) -> OptimizeResult:
    """scipy's MINPACK LM from ``state.x`` for the evaluations left of ``max_nfev``, the
    evaluations already spent added to its counts."""
    left = max_nfev - state.nfev
    if left < 1:
        J = np.asarray(jac(state.x), dtype=float)
        res = OptimizeResult(x=state.x, cost=0.5 * float(state.f @ state.f), fun=state.f,
                             jac=J, status=0, message=MESSAGES[0], success=False, nfev=0,
                             njev=0)  # fmt: skip
    else:
        res = least_squares(fun, state.x, jac=jac, method="lm", x_scale="jac", ftol=ftol,
                            xtol=xtol, gtol=gtol, max_nfev=left)  # fmt: skip
    res.nfev += state.nfev
    res.njev = (res.njev or 0) + state.njev
    return res


def _norm(v: np.ndarray) -> float:
    """Euclidean norm of ``v`` without overflow (a trial point's residuals can be huge;
    MINPACK's ``enorm`` scales as well)."""
    with np.errstate(over="ignore"):
        n = float(np.linalg.norm(v))
    if np.isfinite(n) or not np.isfinite(v).all():
        return n
    big = float(np.max(np.abs(v)))
    return big * float(np.linalg.norm(v / big))


def _scaled_gradient_norm(jtf: np.ndarray, jacnorm: np.ndarray, fnorm: float) -> float:
    """max_j |(J^T f)_j| / (||f|| ||J_j||) over the nonzero columns (``lmder``'s gnorm)."""
    if fnorm == 0.0:
        return 0.0
    ok = jacnorm != 0.0
    return float(np.max(np.abs(jtf[ok]) / (fnorm * jacnorm[ok]), initial=0.0))


def _model_norm(p, J, jtj, system: ScaledSystem) -> float:
    """||J p||, the linear model's change along the step: from J^T J when the step
    came from the normal equations (conditioned enough for it: accurate to ~1e-6; one
    m x n product less per trial step), else from J p itself."""
    if system.normal:
        return float(np.sqrt(max(p @ jtj @ p, 0.0)))
    return _norm(J @ p)


def _trust_update(fnorm, fnorm1, jpnorm, par, pnorm, delta):
    """(ratio, actred, prered, delta, par) after a trial step (``jpnorm`` = ||J p||): the actual and
    predicted relative reductions of ||f||^2, their ratio and the updated trust radius
    and LM parameter (``lmder``'s rules)."""
    actred = 1.0 - (fnorm1 / fnorm) ** 2 if 0.1 * fnorm1 < fnorm else -1.0
    temp1 = jpnorm / fnorm
    temp2 = np.sqrt(par) * pnorm / fnorm
    prered = temp1**2 + temp2**2 / 0.5
    dirder = -(temp1**2 + temp2**2)
    ratio = actred / prered if prered != 0.0 else 0.0
    if ratio <= 0.25:
        temp = 0.5 if actred >= 0.0 else 0.5 * dirder / (dirder + 0.5 * actred)
        if 0.1 * fnorm1 >= fnorm or temp < 0.1:
            temp = 0.1
        delta = temp * min(delta, pnorm / 0.1)
        par = par / temp
    elif par == 0.0 or ratio >= 0.75:
        delta = pnorm / 0.5
        par = 0.5 * par
    return ratio, actred, prered, delta, par


def _termination(actred, prered, ratio, delta, xnorm, gnorm, nfev, ftol, xtol, max_nfev):
    """scipy's status code when ``lmder``'s tests stop the search, else None (the
    tolerances at machine precision are reported as the tolerance they stand for)."""
    f_ok = abs(actred) <= ftol and prered <= ftol and 0.5 * ratio <= 1.0
    x_ok = delta <= xtol * xnorm
    if f_ok or x_ok:
        return 4 if f_ok and x_ok else (2 if f_ok else 3)
    if nfev >= max_nfev:
        return 0
    if abs(actred) <= _EPS and prered <= _EPS and 0.5 * ratio <= 1.0:
        return 2
    if delta <= _EPS * xnorm:
        return 3
    if gnorm <= _EPS:
        return 1
    return None
