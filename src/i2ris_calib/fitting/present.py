"""How a fit is shown: the text report, the one-line repr, the notebook display and
the figure of a :class:`~i2ris_calib.fitting.result.FitResult`, apart from the optimiser.

As lmfit keeps ``fit_report`` in ``printfuncs`` and ``ModelResult.plot`` delegates to
its plotting functions, ``FitResult.fit_report``, ``__repr__``, ``_repr_html_`` and
``plot`` are one-line methods calling these functions. They read a result's fields
and numeric methods (``metrics``, ``correlations``, ``redchi``, ``predict``,
``eval_uncertainty``, ``parameters``) and compute nothing of the fit.

* :func:`fit_report` (``FitResult.fit_report``): plain text like lmfit's: statistics,
  parameters with standard errors and units, correlations, notes.
* :func:`summary` (``repr(res)``) and :func:`report_html` (the notebook display).
* :func:`plot_fit` (``FitResult.plot``): angle vs input and vs time with the
  prediction band, and the residuals; matplotlib is imported when it draws.

The parameter table and the saved-fit file are :mod:`i2ris_calib.fitting.results`.
"""

from __future__ import annotations

import html

import numpy as np

import i2ris_calib._display as _display
from i2ris_calib.errors import CalibError
from i2ris_calib.model import Signals

# ------------------------------------------------------------------------ the text


def fit_report(res, min_correl: float = 0.5) -> str:
    """Plain-text summary of the FitResult ``res``, like lmfit's: fit statistics,
    parameters with standard errors and units, correlations above ``min_correl``,
    notes. See ``FitResult.fit_report``."""
    m, h = res.metrics, res.holdout_metrics
    profiled = res.profiled
    lines = [
        f"[[Fit of {res.model.name}]]",
        f"    converged          = {res.converged} ({res.message})",
        f"    samples in loss    = {res.n_samples}, free parameters = {res.n_fitted}"
        + (f" (+ {', '.join(profiled)} profiled)" if profiled else ""),
        f"    function evals     = {res.nfev}, starts = {res.starts_tried}",
        *(
            [f"    global search      = {res.certificate.text}"]
            + (
                [f"    WARNING            : {res.certificate.warning}"]
                if res.certificate.warning
                else []
            )
            if res.certificate is not None
            else []
        ),
        f"    RMSE / max |err|   = {m.rmse_deg:.4g} / {m.max_abs_err_deg:.4g} deg "
        f"(NRMSE {m.nrmse_pct:.3g} %)",
        f"    held-out RMSE      = {h.rmse_deg:.4g} deg on {h.n_samples} samples",
        f"    reduced chi-square = {res.redchi:.4g} deg^2",
        f"    AIC / BIC          = {res.aic:.5g} / {res.bic:.5g}",
        "[[Parameters]]",
    ]
    for p in res.model.parameters:
        se = res.stderr.get(p.name, float("nan"))
        reason = res.stderr_reasons.get(p.name, "")
        if p.name not in res.free:
            how = "(fixed)"
        elif np.isfinite(se):
            how = f"+/- {se:.3g}"
        elif p.name in profiled:
            how = "(profiled)"
        elif reason.startswith("at its bound"):
            how = "(at its bound)"
        else:
            how = "(not identified)"
        lines.append(
            f"    {p.name:<8} = {res.params[p.name]:<12.6g} {how:<20} {p.unit:<10} {p.doc}"
        )
    cor = sorted(
        ((k, c) for k, c in res.correlations.items() if abs(c) >= min_correl),
        key=lambda kc: -abs(kc[1]),
    )
    if cor:
        lines.append(f"[[Correlations]] (|C| >= {min_correl})")
        lines += [f"    C({a}, {b}) = {c:+.3f}" for (a, b), c in cor]
    if res.notes:
        lines.append("[[Notes]]")
        lines += [f"    {n.code}: {n.text}" for n in res.notes]
    return "\n".join(lines)


def summary(res) -> str:
    """``repr`` of the FitResult ``res``: the model, RMSE, held-out RMSE, samples, free
    parameters and whether it converged, on one line."""
    h = res.holdout_metrics.rmse_deg
    held = f", held-out {h:.3g} deg" if np.isfinite(h) else ""
    prof = f" (+{len(res.profiled)} profiled)" if res.profiled else ""
    return (
        f"<FitResult {res.model.name}: RMSE {res.metrics.rmse_deg:.3g} deg{held}, "
        f"{res.n_samples} samples, {res.n_fitted} free{prof}, "
        f"{'converged' if res.converged else 'NOT converged'}>"
    )


def report_html(res) -> str:
    """Notebook display of the FitResult ``res``: the statistics, the parameter table
    (value, stderr, start, bounds, unit, meaning) and the correlations above 0.9."""
    m, h = res.metrics, res.holdout_metrics
    cor = [f"C({a}, {b}) = {c:+.3f}" for (a, b), c in sorted(res.correlations.items(), key=lambda kc: -abs(kc[1])) if abs(c) >= 0.9]  # fmt: skip
    return (
        f"<b>FitResult {html.escape(res.model.name)}</b>: "
        f"{'converged' if res.converged else '<b>NOT converged</b>'}; RMSE "
        f"{m.rmse_deg:.4g} deg, held-out {h.rmse_deg:.4g} deg, max {m.max_abs_err_deg:.4g} deg, "
        f"reduced chi-square {res.redchi:.4g}, AIC {res.aic:.5g}, BIC {res.bic:.5g}, "
        f"{res.n_samples} samples"
        + res.parameters._repr_html_()
        + (f"<p>correlations: {html.escape('; '.join(cor))}</p>" if cor else "")
    )


# ---------------------------------------------------------------------- the figure


def _plot_inputs(res, signals, theta_deg):
    """(signals, measured angle, fitted mask, held-out mask) for :func:`plot_fit`."""
    from i2ris_calib.data.dataset import Dataset

    if signals is None:
        signals = res.extra.get("signals")
        if signals is None:
            raise CalibError(
                "plot: this FitResult does not keep its data; pass them, e.g. res.plot(data) "
                "with the Dataset, or res.plot(signals, theta_deg)"
            )
    if isinstance(signals, Dataset):
        data = signals
        theta = np.asarray(data.theta_measured_deg if theta_deg is None else theta_deg, float)
        hold = np.asarray(data.holdout, bool) & np.isfinite(theta)
        used = np.asarray(data.in_direction, bool) & np.isfinite(theta) & ~hold
        return data.signals, theta, used, hold
    s = signals if isinstance(signals, Signals) else Signals(v=np.asarray(signals, dtype=float))
    n = np.asarray(s.v).size
    if theta_deg is None:
        if np.size(res.residuals) != n:
            raise CalibError(
                f"plot: {n} input samples but the fit has {np.size(res.residuals)} residuals; "
                "pass theta_deg (the measured angle) too"
            )
        theta = None  # the fitted samples' angle: predicted - residual (set by the caller)
    else:
        theta = np.asarray(theta_deg, dtype=float)
        if theta.shape != (n,):
            raise CalibError(f"plot: theta_deg has shape {theta.shape}; give one angle per input")
    used = np.isfinite(theta) if theta is not None else np.isfinite(res.residuals)
    return s, theta, used, np.zeros(n, bool)


def plot_fit(res, signals=None, theta_deg=None, ax=None, band=True, sigma=2.0):
    """The figure of a fit: angle vs input, angle vs time with the prediction band,
    residuals vs time. See ``FitResult.plot``."""
    import matplotlib.pyplot as plt

    s, theta, used, hold = _plot_inputs(res, signals, theta_deg)
    y = res.predict(s)
    if theta is None:
        theta = np.where(np.isfinite(res.residuals), y - np.asarray(res.residuals, float), np.nan)
    t = np.arange(y.size, dtype=float) if s.t_s is None else np.asarray(s.t_s, dtype=float)
    t_label = "sample" if s.t_s is None else "time (s)"
    v = np.asarray(s.v, dtype=float)
    if ax is None:
        fig, axes = plt.subplots(3, 1, figsize=(8, 9), constrained_layout=True)
    else:
        axes = list(ax) if isinstance(ax, (list, tuple, np.ndarray)) else [ax]
        if len(axes) != 3:
            raise CalibError("plot: ax must be three matplotlib Axes (loop, time, residuals)")
        fig = axes[0].figure
    a_loop, a_time, a_res = axes
    width = res.eval_uncertainty(s, sigma) if band else None
    name = res.model.name
    a_loop.plot(v[used], theta[used], ".", ms=2, color="0.6", label="measured (fitted)")
    if hold.any():
        a_loop.plot(v[hold], theta[hold], ".", ms=2, color="tab:orange", label="held out")
    a_loop.plot(v, y, "-", lw=0.8, color="tab:blue", label=name)
    a_loop.set(xlabel="input", ylabel="angle (deg)", title=f"{name}: angle vs input")
    a_loop.legend(loc="best", fontsize="small")
    shown = used | hold
    a_time.plot(t[shown], theta[shown], ".", ms=2, color="0.6", label="measured")
    a_time.plot(t, y, "-", lw=0.8, color="tab:blue", label=name)
    if width is not None:
        a_time.fill_between(t, y - width, y + width, color="tab:blue", alpha=0.3,
                            label=f"{_display.num(sigma)}-sigma band")  # fmt: skip
    a_time.set(xlabel=t_label, ylabel="angle (deg)", title="angle vs time")
    a_time.legend(loc="best", fontsize="small")
    r = theta - y
    a_res.axhline(0.0, color="0.3", lw=0.6)
    a_res.plot(t[used], r[used], ".", ms=2, color="0.4", label="fitted")
    if hold.any():
        a_res.plot(t[hold], r[hold], ".", ms=2, color="tab:orange", label="held out")
    if width is not None:
        a_res.fill_between(t, -width, width, color="tab:blue", alpha=0.3, label="band")
    a_res.set(xlabel=t_label, ylabel="measured - model (deg)", title="residuals")
    a_res.legend(loc="best", fontsize="small")
    return fig
