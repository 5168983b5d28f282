"""FitResult.eval_uncertainty (the confidence band of the curve, from the parameter
covariance) and eval_prediction_band (a new measurement: that plus the noise)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pytest

from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.fit import FitResult, fit_model
from i2ris_calib.fitting.metrics import NAN_METRICS
from i2ris_calib.hysteresis.models import continuous_egpi_model, gpi_model
from i2ris_calib.hysteresis.presets import loading_trajectory
from i2ris_calib.model import NamedParameters, Parameter, Signals


@dataclass(frozen=True)
class LineModel(NamedParameters):
    """y = a v + b: a model without a ``jacobian`` (the finite-difference path)."""

    name: str = "line"
    parameters: tuple[Parameter, ...] = (
        Parameter("a", value=0.01, unit="deg/count"),
        Parameter("b", value=0.0, unit="deg"),
    )

    def evaluate(self, signals, values):
        v = np.asarray(signals.v if isinstance(signals, Signals) else signals, dtype=float)
        return values[0] * v + values[1]

    def with_values(self, values):
        return replace(
            self,
            parameters=tuple(
                replace(p, value=float(x)) for p, x in zip(self.parameters, values, strict=True)
            ),
        )


def _line_data(seed=0, n=200):
    rng = np.random.default_rng(seed)
    v = np.linspace(-500.0, 1500.0, n)
    theta = 0.02 * v + 1.5 + rng.normal(0, 0.3, n)
    return v, theta


def test_linear_model_band_equals_least_squares_truth():
    v, theta = _line_data()
    res = fit_model(LineModel(), v, theta)
    # ordinary least squares: Cov = s^2 (X^T X)^-1, band = sqrt(diag(X Cov X^T))
    x = np.column_stack([v, np.ones_like(v)])
    coef, rss, *_ = np.linalg.lstsq(x, theta, rcond=None)
    cov = rss[0] / (v.size - 2) * np.linalg.inv(x.T @ x)
    v_new = np.linspace(-1000, 3000, 57)
    x_new = np.column_stack([v_new, np.ones_like(v_new)])
    truth = np.sqrt(np.einsum("ij,jk,ik->i", x_new, cov, x_new))
    np.testing.assert_allclose(res.covariance, cov, rtol=1e-6)
    np.testing.assert_allclose(res.eval_uncertainty(v_new), truth, rtol=1e-6)
    # narrowest at the data's centre of mass, wider outside the fitted range
    band = res.eval_uncertainty(v_new)
    assert band[np.argmin(np.abs(v_new - v.mean()))] == pytest.approx(band.min(), rel=0.05)
    assert band[0] > band[len(band) // 2] and band[-1] > band[len(band) // 2]


def test_sigma_scales_and_probabilities_convert():
    v, theta = _line_data(1)
    res = fit_model(LineModel(), v, theta)
    one = res.eval_uncertainty(v)
    np.testing.assert_allclose(res.eval_uncertainty(v, sigma=2), 2 * one, rtol=1e-12)
    np.testing.assert_allclose(res.eval_uncertainty(v, sigma=0.6826894921), one, rtol=1e-6)
    np.testing.assert_allclose(res.eval_uncertainty(v, sigma=0.95), 1.959964 * one, rtol=1e-5)


def test_fixed_parameter_adds_nothing():
    v, theta = _line_data(2)
    model = LineModel()
    model = replace(
        model, parameters=(model.parameters[0], replace(model.parameters[1], value=1.5, fixed=True))
    )
    res = fit_model(model, v, theta)
    assert res.stderr["b"] == 0.0
    np.testing.assert_allclose(res.eval_uncertainty(v), np.abs(v) * res.stderr["a"], rtol=1e-9)


def _result(model, cov) -> FitResult:
    names = model.names
    return FitResult(
        model=model,
        params=model.value_dict(),
        stderr={n: float(np.sqrt(cov[i, i])) for i, n in enumerate(names)},
        covariance=cov,
        residuals=np.zeros(1),
        metrics=NAN_METRICS,
        holdout_metrics=NAN_METRICS,
        aic=0.0,
        bic=0.0,
        converged=True,
        message="",
        nfev=0,
        n_samples=1,
        free=names,
    )


@pytest.mark.parametrize("factory", [gpi_model, continuous_egpi_model])
def test_exact_jacobian_band_equals_finite_difference_band(factory):
    """GPI and EGPI_C have an exact Jacobian; the band from it equals the one from
    central differences of the output (the output is piecewise linear in the parameters)."""
    model = factory()
    p = len(model.names)
    rng = np.random.default_rng(3)
    a = rng.normal(size=(p, p))
    scale = 0.01 * (1.0 + np.abs(model.values))
    cov = (a @ a.T / p + np.eye(p)) * np.outer(scale, scale) * 1e-2
    if "v_f" in model.names:  # profiled: no covariance
        i = model.names.index("v_f")
        cov[i, :] = cov[:, i] = 0.0
    res = _result(model, cov)
    _, v = loading_trajectory(np.random.default_rng(4), n_cycles=3, n_samples=800)
    v = np.round(v)
    band = res.eval_uncertainty(v)
    x = model.values
    jac = np.zeros((v.size, p))
    for j in range(p):
        if cov[j, j] == 0:
            continue
        h = 1e-7 * max(1.0, abs(x[j]))
        xp, xm = x.copy(), x.copy()
        xp[j] += h
        xm[j] -= h
        jac[:, j] = (model.evaluate(v, xp) - model.evaluate(v, xm)) / (2 * h)
    truth = np.sqrt(np.einsum("ij,jk,ik->i", jac, cov, jac))
    np.testing.assert_allclose(band, truth, rtol=1e-4, atol=1e-9 * truth.max())
    assert band.shape == v.shape and np.all(band >= 0) and truth.max() > 0


def test_no_covariance_gives_zeros_and_misuse_is_one_line():
    model = gpi_model()
    res = _result(model, np.zeros((len(model.names),) * 2))
    assert np.all(res.eval_uncertainty(np.arange(10.0)) == 0.0)
    with pytest.raises(CalibError, match="pass the signals"):
        res.eval_uncertainty()
    with pytest.raises(CalibError, match="sigma"):
        res.eval_uncertainty(np.arange(3.0), sigma=0)
    with pytest.raises(CalibError, match="sigma"):
        res.eval_uncertainty(np.arange(3.0), sigma="2")
    # the fit's own input, when recorded, is the default
    rec = replace(res, extra={"signals": Signals(v=np.arange(4.0))})
    assert rec.eval_uncertainty().shape == (4,)


def test_prediction_band_covers_new_measurements_where_the_confidence_band_does_not():
    """Issue 32 item 6: the band about the curve is not where new data fall. For a line
    with noise 0.3, about 95 % of new measurements fall inside the 0.95 prediction
    band; the confidence band alone holds far fewer."""
    v, theta = _line_data(5, n=400)
    res = fit_model(LineModel(), v, theta)
    rng = np.random.default_rng(9)
    new = 0.02 * v + 1.5 + rng.normal(0, 0.3, v.size)
    y = res.predict(v)
    pred = res.eval_prediction_band(v, sigma=0.95)
    conf = res.eval_uncertainty(v, sigma=0.95)
    inside = np.mean(np.abs(new - y) <= pred)
    assert 0.92 <= inside <= 0.98
    assert np.mean(np.abs(new - y) <= conf) < 0.5
    np.testing.assert_allclose(
        res.eval_prediction_band(v, 2), 2 * np.sqrt(res.eval_uncertainty(v) ** 2
                                                    + res.metrics.rmse_deg**2), rtol=1e-12)  # fmt: skip
