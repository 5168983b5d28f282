"""The result of a fit as data: :class:`FitResult` (the fitted numbers and what follows
from them: ``predict``, the bands, ``chisqr``, ``correlations``), the fitter's notes
(:class:`FitNote`) and how well its search established the optimum
(:class:`SearchCertificate`).

The optimiser that makes them is :mod:`~i2ris_calib.fitting.fit`; how a result is shown,
:mod:`~i2ris_calib.fitting.present`; its parameter table and saved file,
:mod:`~i2ris_calib.fitting.results`; the start state it runs a model after,
:mod:`~i2ris_calib.fitting.prehistory`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from i2ris_calib._validate import describe
from i2ris_calib.errors import CalibError
from i2ris_calib.fitting import present, results
from i2ris_calib.fitting.metrics import Metrics
from i2ris_calib.fitting.prehistory import InitialState, _FromLevel, state_levels, state_own_levels
from i2ris_calib.fitting.results import ParamTable
from i2ris_calib.hysteresis.models import as_signals
from i2ris_calib.model import Model, Signals
from i2ris_calib.model import analytic_method as _analytic_jacobian

#: The search is certified when at least this many starts reached the best cost;
#: until then it restarts from perturbations of the best end (basin hopping).
CERTIFIED_AT = 2


@dataclass(frozen=True)
class FitNote:
    """Something the fitter did or found that a user should know, as data.

    Attributes
    ----------
    code : str
        ``"left_bounds"`` (unbounded LM ended outside the bounds; refitted bounded),
        ``"refit_from_start"`` (ended worse than a start; refitted from it),
        ``"not_a_minimum"`` (still worse than a start: ``converged`` is False),
        ``"at_bound"`` (parameters ending on a bound; their stderr is NaN).
    text : str
        The sentence also appended to ``message``.
    params : tuple of str
        Parameters concerned (``left_bounds``, ``at_bound``).
    """

    code: str
    text: str
    params: tuple[str, ...] = ()


#: A next minimum within this relative difference of the best is named as a flat
#: valley in the certificate's warning (about as good a fit).
NEAR_MINIMUM = 0.01
#: Two costs within this relative difference are the same minimum: a start whose
#: polished end is within it of the best cost "reached the best" (the certificate).
SAME_MINIMUM = 1e-3


def _ratio_text(r: float) -> str:
    """``r`` as "1.004x" / "12x": enough digits to tell it from 1."""
    return f"{r:.4g}x" if r < 1.1 else f"{r:.3g}x"


@dataclass(frozen=True)
class SearchCertificate:
    """How well the global search established its optimum, as data.

    A least-squares cost over hysteresis parameters has several minima. The fitter
    screens every start, polishes the lowest distinct ends on every fitted sample
    and, while fewer than :data:`CERTIFIED_AT` of them agree on the best cost, restarts
    from perturbations of the best end (basin hopping). The certificate says what that
    search found: a best cost reached from several starts is a minimum the search
    would find again; one reached once may have a lower neighbour nobody visited.

    Attributes
    ----------
    starts : int
        Start vectors screened (data-driven, spread, nested and given ones).
    polished : int
        Ends polished to convergence on every fitted sample (hops included).
    at_best : int
        Starts whose end lies within :data:`SAME_MINIMUM` (0.1 %) of the best cost:
        polished ends, and screened ends already there (not polished again).
    best_cost : float
        The best cost (sum of squared residuals over the fitted samples, deg^2).
    next_cost : float
        The lowest polished cost above the best by more than 0.1 %: the next basin
        (NaN when every polished end reached the best).
    hops : int
        Basin-hopping restarts run.
    replaced : str
        Set when a later stage found a lower cost for this model on the same data and
        the fit was rerun with that end as one more start (``fit.json``'s ``replaced``
        record): what found it and the cost before and after; ``""`` for a fit's own
        search. The counts are the rerun's (the later stage's start among them).
    """

    starts: int
    polished: int
    at_best: int
    best_cost: float
    next_cost: float
    hops: int
    replaced: str = ""

    @property
    def certified(self) -> bool:
        """True when at least :data:`CERTIFIED_AT` starts reached the best cost."""
        return self.at_best >= CERTIFIED_AT

    @property
    def text(self) -> str:
        """One sentence: how many starts reached the best cost and the next basin."""
        nxt = (
            f"; the next minimum found costs {_ratio_text(self.next_cost / self.best_cost)} "
            "the best"
            if np.isfinite(self.next_cost) and self.best_cost > 0
            else ""
        )
        hops = f", {self.hops} restart(s) from perturbations of the best" if self.hops else ""
        rerun = f"; rerun: {self.replaced}" if self.replaced else ""
        return (
            f"{self.at_best} of {self.starts + self.hops} starts reached the best cost "
            f"(within {100 * SAME_MINIMUM:.1f} %; {self.polished} polished{hops}){nxt}{rerun}"
        )

    @property
    def warning(self) -> str | None:
        """A sentence when only one start reached the best cost, else None."""
        if self.certified:
            return None
        near = (
            np.isfinite(self.next_cost)
            and self.best_cost > 0
            and self.next_cost <= self.best_cost * (1 + NEAR_MINIMUM)
        )
        return "only one start reached the best cost: " + (
            f"the next minimum found is within {100 * NEAR_MINIMUM:.0f} % of it (a flat "
            "valley: about as good a fit, with other values)"
            if near
            else "the search may have missed a lower minimum (more starts: [fit] n_starts)"
        )

    def as_dict(self) -> dict:
        """JSON-ready fields (``next_cost`` None when NaN) with ``text``; ``replaced``
        only when set."""
        out = {
            "starts": self.starts,
            "polished": self.polished,
            "at_best": self.at_best,
            "best_cost": self.best_cost,
            "next_cost": self.next_cost if np.isfinite(self.next_cost) else None,
            "hops": self.hops,
            "certified": self.certified,
            "text": self.text,
        }
        if self.replaced:
            out["replaced"] = self.replaced
        return out

    @classmethod
    def from_dict(cls, d: dict) -> SearchCertificate:
        """The certificate :meth:`as_dict` wrote."""
        nxt = d.get("next_cost")
        return cls(
            int(d["starts"]), int(d["polished"]), int(d["at_best"]), float(d["best_cost"]),
            float("nan") if nxt is None else float(nxt), int(d.get("hops", 0)),
            str(d.get("replaced") or ""),
        )  # fmt: skip


def output_after_state(
    model: Model, state: InitialState | None, signals: Signals | np.ndarray, values: np.ndarray
) -> np.ndarray:
    """Output (deg), shape (m,), of ``model`` at ``values`` run after the pre-history of
    ``state`` (a fit's :attr:`FitResult.initial_state`; None: from relaxed operators).

    The pre-history ends at the first input of ``signals``, so ``signals`` need not be
    the fitted recording's own: the same state on the input at a shifted clock (sync's
    offset profile) moves with it instead of dropping back to rest.
    """
    s = as_signals(signals)
    x = np.asarray(values, dtype=float)
    if state is None:
        return model.evaluate(s, x)
    lead = _FromLevel(model, np.asarray(s.v, dtype=float), state.cycle_samples,
                      s.v_other if state.other_v_from is not None else None,
                      state_own_levels(state))  # fmt: skip
    return lead.evaluate(s, np.append(x, state_levels(state, lead.levels, lead.n_own)))


@dataclass(frozen=True)
class FitResult:
    """Outcome of :func:`~i2ris_calib.fitting.fit.fit_model`: the fitted numbers and
    what follows from them (``predict``, the bands, ``chisqr``, ``correlations``). How it
    is shown (the text report, the notebook display, the figure) is
    :mod:`~i2ris_calib.fitting.present`;
    its parameter table and saved file, :mod:`~i2ris_calib.fitting.results`.

    Attributes
    ----------
    model : Model
        New model carrying the fitted values (fixed parameters unchanged).
    params, stderr : dict
        Fitted value and standard error per parameter name (stderr 0 for fixed
        parameters, NaN where the Jacobian is rank deficient, and for a profiled v_f).
    covariance : ndarray, shape (p, p)
        Covariance of all parameters in model order (zero rows/columns for fixed ones).
    residuals : ndarray, shape (n,)
        ``y - theta`` (deg) at every sample (NaN where theta is NaN).
    metrics : Metrics
        Eq25-27 on the samples used in the loss.
    holdout_metrics : Metrics
        Eq25-27 on the held-out samples (all NaN when none).
    aic, bic : float
        Gaussian information criteria ``n ln(RSS/n) + 2k`` and ``n ln(RSS/n) + k ln n``
        over the n fitted samples, k free parameters
        (:func:`~i2ris_calib.fitting.metrics.information_criteria`).
    converged : bool
        Optimiser reported convergence (not the evaluation limit) with a finite cost.
    message : str
        Optimiser message of the final run. When the unbounded ``"lm"`` ends with
        free parameters outside their bounds (unphysical: negative slopes, thresholds,
        sigma or kappa), the fit is redone bounded (``"trf"``) from that point clipped
        into the bounds (and, when clipping more than doubles the cost, the other
        parameters first re-fitted by LM with those held there); the message names them, and parameters ending on a bound get
        NaN stderr. When the result is worse than a start (or a screened point) inside
        the bounds, it is refitted bounded from that point (trf never ends worse than
        its start); should it still be worse, ``converged`` is False and the message
        says "NOT a minimum".
    nfev : int
        Model evaluations in total (all starts, Jacobians, profile searches). An
        exact Jacobian (a model with a ``jacobian`` method: GPI, EGPI, EGPI_C) counts
        as one evaluation, as does the paper EGPI's flag-point profile over one set of
        family outputs; finite-difference Jacobians count one per free parameter.
    n_samples : int
        Samples in the loss.
    free : tuple of str
        Names of the fitted parameters.
    starts_tried : int
        Start vectors screened (with the nested start of an extended model).
    extra : dict
        ``outside_bounds``: free parameters outside their bounds.
    notes : tuple of FitNote
        What the fitter did that a user should know.
    stderr_reasons : dict
        Why the standard error of a free parameter is NaN, by name (only those):
        profiled, at a bound, not identified by these data (with the parameters it
        cannot be told apart from), no effect on the fitted samples, too few samples.
    initial_state : InitialState or None
        The operator state estimated at the first sample of a recording that does
        not start at rest (None: it starts at rest, the model's own relaxed start).
    start : dict
        Value of every parameter in the first start vector (the model's own values
        unless ``starts`` were given; empty when not recorded).
    certificate : SearchCertificate or None
        How many starts reached the best cost, the next minimum's cost and the
        restarts run (None: not recorded, e.g. a result loaded from an older file).
    """

    model: Model
    params: dict[str, float]
    stderr: dict[str, float]
    covariance: np.ndarray
    residuals: np.ndarray
    metrics: Metrics
    holdout_metrics: Metrics
    aic: float
    bic: float
    converged: bool
    message: str
    nfev: int
    n_samples: int
    free: tuple[str, ...] = ()
    starts_tried: int = 1
    extra: dict = field(default_factory=dict)
    notes: tuple[FitNote, ...] = ()
    stderr_reasons: dict[str, str] = field(default_factory=dict)
    initial_state: InitialState | None = None
    start: dict[str, float] = field(default_factory=dict)
    certificate: SearchCertificate | None = None

    def predict(
        self, signals: Signals | np.ndarray, initial_state: bool | None = None
    ) -> np.ndarray:
        """Fitted model output (deg) for ``signals``.

        ``initial_state``: run the model after the fitted pre-history
        (:attr:`initial_state`, a recording that did not start at rest), as the fit
        did. Default: when the fit has one and ``signals`` start at the fitted
        recording's first input (the fit's own data); False runs from relaxed operators.
        """
        s = as_signals(signals)
        x = np.array([p.value for p in self.model.parameters])
        st = self.initial_state
        if initial_state is None:
            v = np.asarray(s.v, dtype=float)
            initial_state = st is not None and v.size > 0 and float(v[0]) == st.v0
        return output_after_state(self.model, st if initial_state else None, s, x)

    def eval_uncertainty(
        self, signals: Signals | np.ndarray | None = None, sigma: float = 1.0
    ) -> np.ndarray:
        """Confidence band of the fitted model curve from the parameter covariance (deg),
        per sample (where the curve may lie; a new measurement: :meth:`eval_prediction_band`).

        As lmfit's ``ModelResult.eval_uncertainty``: ``sigma_y = sqrt(diag(J C J^T))``
        with ``J`` the Jacobian of the model output with respect to the parameters the
        covariance covers (free, not profiled; fixed ones and a profiled ``v_f`` have
        zero rows and add nothing) and ``C`` :attr:`covariance`. ``J`` is the model's
        exact ``jacobian`` when it has one (GPI, EGPI, EGPI_C), else central
        differences with steps of 1 % of each standard error. The band is the
        uncertainty of the model curve from the parameters alone (not the scatter of
        new measurements about it), valid where the output is smooth in them.

        Parameters
        ----------
        signals : Signals or ndarray, shape (n,), optional
            Input to evaluate at (counts), the whole history in time order (the model
            has state). Default: the fit's own input when recorded in ``extra["signals"]``.
        sigma : float
            Width in standard errors (``2`` -> the 2-sigma band); a value in (0, 1) is a
            two-sided probability (``0.95`` -> 1.96 sigma), as in lmfit.

        Returns
        -------
        ndarray, shape (n,)
            ``sigma`` x the standard error of :meth:`predict` at every sample (deg);
            zeros when no parameter has a covariance (all fixed).

        Raises
        ------
        CalibError
            ``signals`` not given and not recorded; ``sigma`` not a positive number.
        """
        if signals is None:
            signals = self.extra.get("signals")
            if signals is None:
                raise CalibError(
                    "eval_uncertainty: this FitResult does not keep its input; pass the "
                    "signals, e.g. res.eval_uncertainty(dataset.signals)"
                )
        if isinstance(sigma, bool) or not isinstance(sigma, (int, float, np.floating)):
            raise CalibError(f"eval_uncertainty: sigma is {describe(sigma)}; give a number > 0")
        if not (np.isfinite(sigma) and sigma > 0):
            raise CalibError(
                f"eval_uncertainty: sigma = {sigma} must be > 0 (1 = one standard error)"
            )
        if sigma < 1:
            from scipy.special import ndtri

            sigma = float(ndtri(0.5 + 0.5 * sigma))
        s = as_signals(signals)
        x = np.array([p.value for p in self.model.parameters], dtype=float)
        cov = np.asarray(self.covariance, dtype=float)
        diag = np.diag(cov) if cov.shape == (x.size, x.size) else np.zeros(x.size)
        idx = np.flatnonzero(np.isfinite(diag) & (diag > 0))
        n = np.asarray(s.v).size
        if idx.size == 0:
            return np.zeros(n)
        jac_fn = _analytic_jacobian(self.model, "jacobian")
        if jac_fn is not None:
            jac = np.asarray(jac_fn(s, x), dtype=float)[:, idx]
        else:
            jac = np.empty((n, idx.size))
            for col, i in enumerate(idx):
                h = 0.01 * float(np.sqrt(diag[i])) or 1e-6 * (1.0 + abs(x[i]))
                up, down = x.copy(), x.copy()
                up[i] += h
                down[i] -= h
                jac[:, col] = (self.model.evaluate(s, up) - self.model.evaluate(s, down)) / (2 * h)
        c = cov[np.ix_(idx, idx)]
        var = np.einsum("ij,jk,ik->i", jac, c, jac)
        return sigma * np.sqrt(np.maximum(var, 0.0))

    def eval_prediction_band(
        self, signals: Signals | np.ndarray | None = None, sigma: float = 1.0
    ) -> np.ndarray:
        """Prediction band of a new measurement (deg), per sample: the confidence band
        of the model curve (:meth:`eval_uncertainty`) and the scatter of the data about
        it (the fitted RMSE, :attr:`metrics`) together,
        ``sigma * sqrt(sd_curve^2 + rmse^2)``. Where :meth:`eval_uncertainty` says
        where the curve may lie, this says where a new measured angle may.

        Parameters and errors as :meth:`eval_uncertainty`.

        Returns
        -------
        ndarray, shape (n,)
        """
        curve = self.eval_uncertainty(signals, sigma)  # checks sigma
        width = float(sigma)
        if width < 1:  # a two-sided probability, as eval_uncertainty reads it
            from scipy.special import ndtri

            width = float(ndtri(0.5 + 0.5 * width))
        noise = float(self.metrics.rmse_deg)
        noise = noise if np.isfinite(noise) else 0.0
        return np.sqrt(curve**2 + (width * noise) ** 2)

    @property
    def chisqr(self) -> float:
        """Residual sum of squares over the fitted samples (deg^2)."""
        return float(self.metrics.rmse_deg**2 * self.n_samples)

    @property
    def redchi(self) -> float:
        """Reduced chi-square ``RSS / (n - k)`` (deg^2): the residual variance; equals
        the measurement noise variance when the model is right."""
        dof = self.n_samples - len(self.free)
        return self.chisqr / dof if dof > 0 else float("nan")

    @property
    def correlations(self) -> dict[tuple[str, str], float]:
        """Correlation of every pair of fitted parameters with finite standard errors."""
        names = [p.name for p in self.model.parameters]
        idx = [
            i
            for i, n in enumerate(names)
            if n in self.free and np.isfinite(self.stderr[n]) and self.stderr[n] > 0
        ]
        out = {}
        for a, i in enumerate(idx):
            for j in idx[a + 1 :]:
                d = np.sqrt(self.covariance[i, i] * self.covariance[j, j])
                if d > 0:
                    out[(names[i], names[j])] = float(self.covariance[i, j] / d)
        return out

    @property
    def profiled(self) -> tuple[str, ...]:
        """Free parameters placed by a profile search (the EGPI flag point ``v_f``): no
        derivative, no standard error by design; not counted in :attr:`n_fitted`."""
        return tuple(
            k for k in self.free if str(self.stderr_reasons.get(k, "")).startswith("profiled")
        )

    @property
    def n_fitted(self) -> int:
        """Free parameters fitted by least squares (the report's count): ``free``
        without the :attr:`profiled` ones."""
        return len(self.free) - len(self.profiled)

    # ---- shown (fitting/present.py); the table and the file (fitting/results.py) ----

    def __repr__(self) -> str:
        return present.summary(self)

    def _repr_html_(self) -> str:
        """Notebook display: the statistics, the parameter table (value, stderr, start,
        bounds, unit, meaning) and the correlations above 0.9."""
        return present.report_html(self)

    def fit_report(self, min_correl: float = 0.5) -> str:
        """Plain-text summary like lmfit's: fit statistics, parameters with standard
        errors and units, correlations above ``min_correl``, notes
        (:func:`~i2ris_calib.fitting.present.fit_report`)."""
        return present.fit_report(self, min_correl)

    @property
    def parameters(self) -> ParamTable:
        """Every parameter as a :class:`~i2ris_calib.fitting.results.FittedParameter`
        (value, stderr, start, bounds, fixed, unit, meaning, why a stderr is missing)
        in a frozen mapping by name, with ``correlations`` (a labelled matrix) and
        ``to_frame()``. Its values and standard errors are :attr:`params` and
        :attr:`stderr`."""
        return results.param_table(self)

    def plot(self, signals=None, theta_deg=None, *, ax=None, band=True, sigma=2.0):
        """Figure of the fit: angle vs input (measured, held out, model), angle vs time
        with the prediction band (:meth:`eval_uncertainty`), residuals vs time.

        Parameters
        ----------
        signals : Dataset, Signals or ndarray, shape (n,)
            The data: a Dataset gives the input, times, the measured angle and its
            held-out cycles. With Signals or a bare input, ``theta_deg`` is the measured
            angle (default: the fit's own, ``predict - residuals``, when the input is
            the fitted one).
        theta_deg : ndarray, shape (n,), optional
            Measured angle (deg).
        ax : sequence of three matplotlib Axes, optional
            Where to draw (loop, time, residuals); default a new figure.
        band : bool
            Draw the ``sigma`` band of the model curve from the parameter covariance.
        sigma : float
            Band width in standard errors (or a two-sided probability below 1).

        Returns
        -------
        matplotlib.figure.Figure
        """
        return present.plot_fit(self, signals, theta_deg, ax=ax, band=band, sigma=sigma)

    def save(self, path) -> Path:
        """Write the fit to ``path`` as JSON (format ``i2ris-calib.fit-result/1``,
        docs/formats.md): the model's kind, settings and every parameter's declaration
        and value, standard errors, start, covariance, residuals, metrics, notes and
        message. A file already at ``path`` is replaced (written beside it and renamed,
        never half-written). :meth:`load` rebuilds a result whose ``predict`` is this
        one's to the last bit, a model with diagnosed effects too. Returns the path."""
        return results.write_record(path, results.fit_record(self))

    @classmethod
    def load(cls, path) -> FitResult:
        """The FitResult :meth:`save` wrote to ``path`` (also a file of the older id
        ``i2ris-calib.fit/1``); CalibError naming the file when it is not one."""
        kw = results.fit_fields(results.read_record(path), str(path))
        state = kw.pop("initial_state")
        cert = kw.pop("certificate")
        return cls(
            **kw
            | {
                "notes": tuple(
                    FitNote(n["code"], n["text"], tuple(n.get("params", ()))) for n in kw["notes"]
                ),
                "initial_state": None if state is None else InitialState(**state),
                "certificate": None if cert is None else SearchCertificate.from_dict(cert),
            }
        )


def fit_notices(res: FitResult) -> tuple[str, ...]:
    """Sentences a user should read about ``res`` (the fitting stage adds them to its
    warnings): the initial state fitted for a recording that does not start at rest,
    and the free parameters without a standard error and why (a profiled flag point
    has none by design and is not listed)."""
    out = []
    if res.initial_state is not None:
        out.append(res.initial_state.text)
    if res.certificate is not None and res.certificate.warning:
        out.append(f"{res.certificate.warning} ({res.certificate.text})")
    missing = {k: r for k, r in res.stderr_reasons.items() if not r.startswith("profiled")}
    if missing:
        out.append("no standard error for " + "; ".join(f"{k} ({r})" for k, r in missing.items()))
    return tuple(out)
