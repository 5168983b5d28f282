"""Issue 20 items 3, 4 and 6 at the fitter: nested fits are never worse than their base,
a recording starting mid-range gets its initial state, null standard errors get a reason."""

from __future__ import annotations

import numpy as np
import pytest

from i2ris_calib.diagnosis.synthetic import case_dataset, make_case
from i2ris_calib.fitting.fit import fit_model, starts_at_rest
from i2ris_calib.fitting.pipeline import fit, fit_warnings, split_masks
from i2ris_calib.hysteresis.effects import CATALOGUE, add_effect
from i2ris_calib.hysteresis.models import continuous_egpi_model, gpi_model, i2ris_egpi_model
from i2ris_calib.hysteresis.presets import gpi_values, loading_trajectory, paper_like_params
from i2ris_calib.io.fit import model_record

BASES = {
    "gpi": gpi_model,
    "egpi": lambda: i2ris_egpi_model(deadband_counts=2.0),
    "egpi_c": lambda: continuous_egpi_model(deadband_counts=2.0),
}


@pytest.fixture(scope="module")
def clean_case():
    """A short clean synthetic case (EGPI truth, other axis moving, times), as a dataset."""
    return case_dataset(make_case(3, None, n_cycles=4))


@pytest.fixture(scope="module")
def base_fits(clean_case):
    return {k: fit(f(), clean_case) for k, f in BASES.items()}


#: the (effect, base) pairs of the default run, one per base kind (the issue's two
#: reported cases among them); the full grid (30 fits, ~2 min) is marked slow
#: creep-egpi_c (~6 s) is slow since the default run reached its 5-minute budget
FAST_PAIRS = {("axis_coupling", "gpi"), ("time_delay", "egpi")}


@pytest.mark.parametrize(
    ("effect", "kind"),
    [
        pytest.param(e, k, marks=() if (e, k) in FAST_PAIRS else pytest.mark.slow)
        for e in CATALOGUE
        for k in BASES
    ],
)
def test_extended_fit_never_worse_than_its_base(clean_case, base_fits, kind, effect):
    """An effect added through the API starts from its base's fit with the effect
    neutral: its fitted cost never exceeds the base's (was: EGPI + axis_coupling or
    time_delay 0.38 vs 0.20 deg, from the base's default values)."""
    base = base_fits[kind]
    ext = fit(add_effect(BASES[kind](), effect), clean_case)
    assert ext.chisqr <= base.chisqr * (1 + 1e-9), (ext.chisqr, base.chisqr, ext.notes)
    assert ext.converged


def test_nested_start_off_keeps_the_old_path(clean_case):
    """``nested=False`` is the fit from the given starts alone; the default adds one
    start (the wrapped model's fit, effect neutral) and never ends worse."""
    m = add_effect(i2ris_egpi_model(deadband_counts=2.0), "time_delay")
    d = clean_case
    on = fit_model(m, d.signals, d.theta_deg, holdout_mask=d.holdout)
    off = fit_model(m, d.signals, d.theta_deg, holdout_mask=d.holdout, nested=False)
    assert on.starts_tried == off.starts_tried + 1
    assert on.chisqr <= off.chisqr * (1 + 1e-9)
    inner = fit_model(m.inner, d.signals, d.theta_deg, holdout_mask=d.holdout)
    assert on.chisqr <= inner.chisqr * (1 + 1e-9)


NOISE = 0.1


def _mid_range(kind: str, seed: int = 1):
    """(v, theta, truth model, first input) of a recording cut from a longer one so that
    it starts on a falling branch at about half the range (operators not relaxed)."""
    rng = np.random.default_rng(seed)
    _, v = loading_trajectory(rng, n_cycles=7, n_samples=4000)
    truth_values = paper_like_params("yaw+")
    if kind == "gpi":
        truth = gpi_model(**gpi_values(truth_values))
    else:
        truth = i2ris_egpi_model(deadband_counts=2.0, **truth_values)
    y = truth(v)
    k0 = int(np.flatnonzero((np.diff(v) < 0) & (v[1:] < 0.55 * v.max()))[0])
    v, y = v[k0:], y[k0:] + rng.normal(0.0, NOISE, v.size - k0)
    return v, y, truth


@pytest.mark.parametrize("kind", ["gpi", pytest.param("egpi", marks=pytest.mark.slow)])  # egpi ~9 s
def test_recording_starting_mid_range_gets_its_initial_state(kind):
    """The first sample was off by ~15 deg (operators started relaxed at v[0]) and the
    held-out RMSE 1.1 deg; with the initial state fitted both are at the noise, and
    the state is reported (FitResult, fit.json record, one warning line)."""
    v, y, truth = _mid_range(kind)
    assert not starts_at_rest(v)
    assert abs(truth(v)[0] - y[0]) > 5  # the relaxed start is far off
    model = gpi_model() if kind == "gpi" else i2ris_egpi_model(deadband_counts=2.0)
    res = fit(model, (v, y))
    assert abs(res.residuals[0]) < 4 * NOISE
    # predict on the fit's own data runs the fitted pre-history too (predictions.csv,
    # the report's figures): it reproduces the residuals; from relaxed operators it
    # does not
    np.testing.assert_allclose(res.predict(v) - y, res.residuals, atol=1e-9)
    assert abs(res.predict(v, initial_state=False)[0] - y[0]) > 5
    assert res.holdout_metrics.rmse_deg < 1.2 * NOISE
    assert res.metrics.rmse_deg < 1.2 * NOISE
    st = res.initial_state
    assert st is not None and st.v0 == v[0] and st.v_from > v[0] and st.n_samples >= 2
    assert "initial_state.v_from" not in res.params  # the model's own parameters only
    assert any("starts mid-range" in w for w in fit_warnings(res, v))
    rec = model_record(res, kind, res.model, v)
    assert rec["initial_state"]["v_from"] == st.v_from
    # the same fit with every operator relaxed at v[0] (the old behaviour)
    hold = split_masks(v)[1]
    rest = fit_model(model, v, y, holdout_mask=hold, starts=[model.guess(v, y).values],
                     initial_state="rest")  # fmt: skip
    assert rest.initial_state is None and abs(rest.residuals[0]) > 5


def test_recording_at_rest_keeps_the_relaxed_start(clean_case, base_fits):
    """A recording starting at zero input is fitted as before: no initial state."""
    assert starts_at_rest(clean_case.signals.v)
    assert base_fits["egpi"].initial_state is None
    assert model_record(base_fits["egpi"], "egpi", base_fits["egpi"].model)["initial_state"] is None


def test_null_standard_errors_have_a_reason(clean_case):
    """Every free parameter with a NaN standard error has a reason: the profiled flag
    point, and lam freed (exactly redundant with the envelope scale: not identified,
    naming what it trades against); the warning lists them."""
    d = clean_case
    egpi = fit(i2ris_egpi_model(deadband_counts=2.0), d)
    assert egpi.stderr_reasons.keys() == {"v_f"} and "profiled" in egpi.stderr_reasons["v_f"]
    m = gpi_model().with_fixed(free=("lam",))
    res = fit_model(m, d.signals, d.theta_deg, holdout_mask=d.holdout,
                    starts=[m.guess(d.v, d.theta_deg).values])  # fmt: skip
    nan = {k for k in res.free if not np.isfinite(res.stderr[k])}
    assert "lam" in nan
    assert nan == set(res.stderr_reasons)
    assert "not identified" in res.stderr_reasons["lam"]
    assert any(k in res.stderr_reasons["lam"] for k in ("a1", "a2", "a3", "a4"))
    assert any(w.startswith("no standard error for") for w in fit_warnings(res, d.v))
    assert model_record(res, "gpi", res.model, d.v)["stderr_reasons"] == res.stderr_reasons


def test_parameter_at_a_bound_has_a_reason(clean_case):
    """A parameter that ends on its bound (a dead zone the clean data do not have)
    gets NaN and the reason."""
    d = clean_case
    m = add_effect(gpi_model(), "dead_zone", {"d_counts": 500.0})
    res = fit(m, d)
    for k in res.free:
        if not np.isfinite(res.stderr[k]):
            assert k in res.stderr_reasons
