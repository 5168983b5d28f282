"""Results a scientist expects: the parameter table, correlations, plot, save/load, and
short reprs with a notebook display for datasets, models, fits, diagnoses, compensations."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace

import matplotlib
import numpy as np
import pytest

from i2ris_calib import CalibError, FitResult, add_effect, fit, fit_model, make_dataset
from i2ris_calib.compensation.inverse import CompensationResult
from i2ris_calib.diagnosis.results import Comparison, Diagnosis, ModelScore, Step
from i2ris_calib.fitting.results import Correlations, FittedParameter, ParamTable
from i2ris_calib.hysteresis.models import egpi_model
from i2ris_calib.hysteresis.presets import (
    loading_trajectory,
    paper_like_params,
    random_two_tendon_params,
    through_zero_trajectory,
)
from i2ris_calib.hysteresis.registry import model_for_kind
from i2ris_calib.model import NamedParameters, Parameter, Signals

matplotlib.use("Agg")

MAX_REPR = 200


@pytest.fixture(scope="module")
def data():
    rng = np.random.default_rng(3)
    t, v = loading_trajectory(rng, n_cycles=4, n_samples=1500)
    y = model_for_kind("egpi").with_values(paper_like_params("yaw+"))(v)
    return make_dataset("yaw", "+", t, v, y + rng.normal(0, 0.1, v.size), source="/x/synced.csv")


@pytest.fixture(scope="module")
def egpi_fit(data):
    return fit(model_for_kind("egpi"), data)


def _signed():
    rng = np.random.default_rng(5)
    truth = random_two_tendon_params(rng, offset_deg=-4.0)
    t, v, start = through_zero_trajectory(rng, 1200, 30.0)
    y = model_for_kind("agpi").with_values(truth)(v)
    return t[start:], v[start:], y[start:] + rng.normal(0, 0.2, v.size - start)


def _same(a, b):
    """Equal numbers, NaN equal to NaN."""
    return a == b or (math.isnan(a) and math.isnan(b))


# ----------------------------------------------------------------------- the table


def test_table_holds_params_stderr_start_bounds(egpi_fit):
    res = egpi_fit
    table = res.parameters
    assert isinstance(table, ParamTable) and list(table) == list(res.params)
    assert table.value_dict() == res.params
    for p in res.model.parameters:
        row = table[p.name]
        assert isinstance(row, FittedParameter)
        assert row.value == res.params[p.name]
        assert _same(row.stderr, res.stderr[p.name])
        assert (row.lower, row.upper, row.unit, row.meaning) == (p.lower, p.upper, p.unit, p.doc)
        assert row.fixed == (p.name not in res.free)
        assert row.start == res.start[p.name]
        assert row.stderr_reason == res.stderr_reasons.get(p.name, "")
    assert table["lam"].fixed and table["lam"].stderr == 0
    assert "profiled" in table["v_f"].stderr_reason and math.isnan(table["v_f"].stderr)
    # the first start of the kind's path (data-driven), every parameter recorded
    assert set(res.start) == set(res.params) and all(map(math.isfinite, res.start.values()))
    frame = table.to_frame()
    assert list(frame.index) == list(res.params) and frame.loc["a1", "value"] == res.params["a1"]
    with pytest.raises(AttributeError):
        table.model_name = "x"
    with pytest.raises(TypeError):
        table["a1"] = 1.0
    with pytest.raises(KeyError, match="did you mean 'kappa'"):
        table["kapa"]


def test_start_is_the_first_start_vector():
    rng = np.random.default_rng(1)
    v = np.concatenate([np.linspace(0, 3000, 200), np.linspace(3000, 0, 200)] * 2)
    truth = model_for_kind("gpi")
    theta = truth(v) + rng.normal(0, 0.05, v.size)
    x0 = truth.values * 1.1
    res = fit_model(truth, v, theta, starts=[x0])
    assert list(res.start.values()) == pytest.approx(list(x0), rel=0, abs=0)
    assert fit_model(truth, v, theta).start == truth.value_dict()


def test_correlations_symmetric_unit_diagonal(egpi_fit):
    corr = egpi_fit.parameters.correlations
    assert isinstance(corr, Correlations) and len(corr) >= 8
    m = corr.matrix
    np.testing.assert_array_equal(m, m.T)
    np.testing.assert_array_equal(np.diag(m), 1.0)
    assert np.all(np.abs(m) <= 1 + 1e-9)
    assert set(corr.names) <= set(egpi_fit.free)
    for (a, b), c in egpi_fit.correlations.items():  # the FitResult's own pairs
        assert corr[a, b] == pytest.approx(c, abs=1e-12) and corr[b, a] == corr[a, b]
    frame = corr.to_frame()
    assert list(frame.index) == list(corr.names) == list(frame.columns)
    assert corr.pairs(0.5) == sorted(corr.pairs(0.5), key=lambda kc: -abs(kc[1]))
    assert len(repr(corr)) <= MAX_REPR and "<table>" in corr._repr_html_()


# ------------------------------------------------------------------------ save/load


@pytest.fixture(scope="module")
def fits():
    """{name: (FitResult, signals)} of every saved model structure."""
    rng = np.random.default_rng(2)
    t, v = loading_trajectory(rng, n_cycles=3, n_samples=900)
    s = Signals(v=v, t_s=t)
    out = {}
    for kind in ("gpi", "egpi", "egpi_c"):
        base = model_for_kind(kind)
        truth = base.with_values(
            {k: x for k, x in paper_like_params("yaw+").items() if k in base.names}
        )
        theta = truth(v) + rng.normal(0, 0.1, v.size)
        model = model_for_kind(kind, deadband_counts=3.0) if kind != "gpi" else truth
        model = model.with_bounds(r1=(0.0, 50.0))  # a changed bound is saved too
        out[kind] = (fit_model(model, s, theta, starts=[truth.values], max_nfev=20), s)
    ts, vs, ys = _signed()
    agpi = model_for_kind("agpi")
    signed = Signals(v=vs, t_s=ts)
    out["agpi"] = (fit_model(agpi, signed, ys, max_nfev=10), signed)
    delayed = add_effect(model_for_kind("egpi").with_values(paper_like_params("yaw+")),
                         "time_delay", {"tau_s": 0.2})  # fmt: skip
    theta = delayed(s) + rng.normal(0, 0.1, v.size)
    out["egpi+time_delay"] = (fit_model(delayed, s, theta, max_nfev=10, nested=False), s)
    vals = {"l1_slope": 0.007, "l1_offset": 0.5, "r1_slope": 0.007, "r1_offset": -0.5,
            "lam": 0.06, "sigma": 0.2, "r1": 0.3, "rn": 3.0}  # fmt: skip
    general = egpi_model([("linear", "linear")], vals).with_fixed(fixed=("lam",))
    out["egpi_general"] = (fit_model(general, s, general(s) + 0.01, max_nfev=5), s)
    return out


@pytest.mark.parametrize(
    "name", ["gpi", "egpi", "egpi_c", "agpi", "egpi+time_delay", "egpi_general"]
)
def test_save_load_reproduces_the_fit(fits, name, tmp_path):
    res, s = fits[name]
    path = res.save(tmp_path / "fit.json")
    back = FitResult.load(path)
    assert type(back.model) is type(res.model) and back.model.name == res.model.name
    np.testing.assert_allclose(back.predict(s), res.predict(s), rtol=0, atol=1e-12)
    assert back.params == res.params and back.free == res.free and back.start == res.start
    assert all(_same(back.stderr[k], res.stderr[k]) for k in res.stderr)
    np.testing.assert_array_equal(back.covariance, res.covariance)
    np.testing.assert_array_equal(back.residuals, res.residuals)
    for m_back, m_res in ((back.metrics, res.metrics), (back.holdout_metrics, res.holdout_metrics)):
        pairs = zip(m_back.as_dict().values(), m_res.as_dict().values(), strict=True)
        assert all(_same(a, b) for a, b in pairs)
    assert (back.aic, back.bic, back.message, back.notes) == (
        res.aic,
        res.bic,
        res.message,
        res.notes,
    )
    assert (back.converged, back.nfev, back.n_samples) == (res.converged, res.nfev, res.n_samples)
    assert back.initial_state == res.initial_state
    assert back.certificate == res.certificate or (
        back.certificate.as_dict() | {"next_cost": 0}
        == res.certificate.as_dict() | {"next_cost": 0}
    )
    assert back.stderr_reasons == res.stderr_reasons
    for a, b in zip(back.model.parameters, res.model.parameters, strict=True):
        assert (a.name, a.value, a.lower, a.upper, a.fixed) == (
            b.name,
            b.value,
            b.lower,
            b.upper,
            b.fixed,
        )
    # saving again gives the same file (the path may be overwritten)
    text = path.read_text()
    back.save(path)
    assert path.read_text().split("\n", 3)[3] == text.split("\n", 3)[3]


def test_load_refuses_other_files(tmp_path, egpi_fit):
    other = tmp_path / "other.json"
    other.write_text('{"schema": "i2ris-calib.model/1"}')
    with pytest.raises(CalibError, match="expected 'i2ris-calib.fit-result/1'"):
        FitResult.load(other)
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(CalibError, match="bad.json"):
        FitResult.load(tmp_path / "bad.json")
    with pytest.raises(CalibError, match="is a folder"):
        egpi_fit.save(tmp_path)


def _edited(path, edit):
    import json

    doc = json.loads(path.read_text())
    edit(doc)
    path.write_text(json.dumps(doc))  # NaN written as the JSON extension NaN
    return path


def _decl(doc, name):
    return next(d for d in doc["model"]["parameters"] if d["name"] == name)


@pytest.mark.parametrize(
    ("edit", "needle"),
    [
        (lambda d: _decl(d, "a1").update(value=float("nan")), "parameter a1 is nan"),
        (lambda d: _decl(d, "r1").update(value=80.0),
         "parameter r1 = 80 is outside its bounds 0..50"),
        (lambda d: _decl(d, "r1").update(lower=60.0), "parameter r1 has bounds 60 > 50"),
        (lambda d: d["params"].update(a1=1.5), "'params' says a1 = 1.5 but the model"),
        (lambda d: d["params"].update(a1=None), "'params' says a1 = nan but the model"),
        (lambda d: d["params"].pop("a1"), "missing: a1"),
    ],
    ids=["nan", "outside-bounds", "bounds-reversed", "params-disagree", "params-nan",
         "params-missing"],
)  # fmt: skip
def test_load_refuses_values_no_fit_gives(fits, tmp_path, edit, needle):
    """A NaN parameter (predict NaN, the repr 'converged'), a value outside its bounds
    and a ``params`` copy that disagrees with the model were all loaded."""
    res, _ = fits["egpi"]
    path = _edited(res.save(tmp_path / "fit.json"), edit)
    with pytest.raises(CalibError) as exc:
        FitResult.load(path)
    msg = str(exc.value)
    assert needle in msg and "fit.json" in msg and "\n" not in msg, msg


def test_load_keeps_a_value_the_fit_reported_outside_its_bounds(fits, tmp_path):
    """An unbounded method may leave a free parameter outside its bounds; the fit lists
    it in ``outside_bounds`` and such a file still loads."""
    res, _ = fits["egpi"]

    def edit(d):
        _decl(d, "r1").update(value=80.0)
        d["params"]["r1"] = 80.0
        d["outside_bounds"] = ["r1"]

    back = FitResult.load(_edited(res.save(tmp_path / "fit.json"), edit))
    assert back.params["r1"] == 80.0


def test_save_writes_its_own_schema_and_reads_the_older_id(fits, tmp_path):
    """FitResult.save's format is i2ris-calib.fit-result/1, not the fit command's
    i2ris-calib.fit/1; a file saved before, under the fit command's id, still loads."""
    res, s = fits["egpi"]
    path = res.save(tmp_path / "fit.json")
    assert json.loads(path.read_text())["schema"] == "i2ris-calib.fit-result/1"
    back = FitResult.load(_edited(path, lambda d: d.update(schema="i2ris-calib.fit/1")))
    np.testing.assert_array_equal(back.predict(s), res.predict(s))


def test_a_fit_with_effects_loads_in_a_fresh_process(fits, tmp_path):
    """The model codec knows every effect: FitResult.load in a new process, with nothing
    imported beforehand, rebuilds the model (it needed ``from i2ris_calib import
    add_effect`` first: 'unknown codec')."""
    import subprocess
    import sys

    res, _ = fits["egpi+time_delay"]
    path = res.save(tmp_path / "fit.json")
    code = (
        "from i2ris_calib.fitting.fit import FitResult\n"
        f"res = FitResult.load({str(path)!r})\n"
        "print(res.model.name, repr(res.params['time_delay.tau_s']))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["egpi+time_delay", repr(res.params["time_delay.tau_s"])]


def test_load_of_the_fit_commands_fit_json_says_what_to_use(tmp_path):
    """A fit.json of the fit command (schema i2ris-calib.fit/1, also the older id of a
    saved fit) is named, with the function that reads it, not a KeyError."""
    doc = {"schema": "i2ris-calib.fit/1", "axis": "yaw", "datasets": [{"name": "yaw+"}]}
    path = tmp_path / "fit.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(CalibError, match="the 'fit' command") as exc:
        FitResult.load(path)
    msg = str(exc.value)
    assert "read_fit_json" in msg and "KeyError" not in msg and "\n" not in msg


# ---------------------------------------------------------------------- the figure


def test_plot_draws_loop_time_and_residuals(egpi_fit, data):
    import matplotlib.pyplot as plt
    from matplotlib.figure import Figure

    fig = egpi_fit.plot(data)
    assert isinstance(fig, Figure) and len(fig.axes) == 3
    loop, time, resid = fig.axes
    assert loop.get_xlabel() == "input" and time.get_xlabel() == "time (s)"
    assert "residuals" in resid.get_title()
    assert len(time.collections) == 1  # the prediction band
    plt.close(fig)
    fig, axes = plt.subplots(1, 3)
    assert egpi_fit.plot(signals=data.signals, theta_deg=data.theta_deg, ax=axes, band=False) is fig
    assert len(axes[1].collections) == 0
    plt.close(fig)
    with pytest.raises(CalibError, match="does not keep its data"):
        egpi_fit.plot()


# ------------------------------------------------------------------- reprs, display


def test_dataset_repr_and_html(data):
    r = repr(data)
    assert len(r) <= MAX_REPR and r.startswith("<Dataset yaw+: 1500 samples")
    assert "held out" in r and "synced.csv" in r
    assert "<table>" in data._repr_html_() and "duration" in data._repr_html_()


@pytest.mark.parametrize("kind", ["gpi", "egpi", "egpi_c", "agpi", "agpi_coupled"])
def test_model_repr_is_one_short_line(kind):
    m = model_for_kind(kind)
    r = repr(m)
    assert len(r) <= MAX_REPR and "\n" not in r and f"'{kind}'" in r
    assert f"{m.parameters[0].name}=" in r
    h = m._repr_html_()
    assert all(f"<td>{p.name}</td>" in h for p in m.parameters)


def test_effect_model_repr_shows_the_effect_first():
    m = add_effect(model_for_kind("egpi"), "time_delay", {"tau_s": 0.15})
    r = repr(m)
    assert len(r) <= MAX_REPR and "time_delay.tau_s=0.15" in r and r.startswith("<EffectModel")
    assert "time_delay.tau_s" in m._repr_html_()


@dataclass(frozen=True)
class _Exploding(NamedParameters):
    """A model whose evaluation fails: a display must not evaluate it."""

    name: str = "boom"
    parameters: tuple[Parameter, ...] = (
        Parameter("a", value=1.0),
        Parameter("b", value=2.0, fixed=True),
    )

    def evaluate(self, signals, values):
        raise AssertionError("a display evaluated the model")


def test_reprs_do_not_evaluate(egpi_fit):
    m = _Exploding()
    assert repr(m) == "<_Exploding 'boom' (2 parameters, 1 fixed): a=1, b=2>"
    assert "<td>b</td>" in m._repr_html_()
    res = replace(egpi_fit, model=egpi_fit.model.with_values(egpi_fit.model.values))
    assert repr(res) == repr(egpi_fit)


def test_fit_result_repr_and_html(egpi_fit):
    r = repr(egpi_fit)
    assert len(r) <= MAX_REPR and "egpi" in r and "RMSE" in r
    h = egpi_fit._repr_html_()
    assert all(f"<td>{name}</td>" in h for name in egpi_fit.params)
    assert "start" in h and "stderr" in h
    assert len(repr(egpi_fit.parameters)) <= MAX_REPR


def test_diagnosis_repr_and_html():
    base = model_for_kind("egpi")
    final = add_effect(base, "time_delay", {"tau_s": 0.1})
    before, after = ModelScore(0.2, 0.5, 10.0, 11), ModelScore(0.1, 0.11, -5.0, 12)
    step = Step("time_delay", base, final, before, after,
                Comparison(0.78, 9.0, 1e-10, 6, 6, -15.0, True), (), {}, ())  # fmt: skip
    d = Diagnosis(base, final, before, after, (step,), (), {}, (), np.zeros(3, bool), 1)
    r = repr(d)
    assert len(r) <= MAX_REPR and "time_delay" in r and "0.5 -> 0.11" in r
    h = d._repr_html_()
    assert "<td>time_delay</td>" in h and "held-out" in h


def test_compensation_result_repr_and_html():
    n = 50
    c = CompensationResult(
        commands=np.zeros(n), commands_real=np.zeros(n), predicted_deg=np.full(n, 1.0),
        target_deg=np.full(n, 1.1), status=np.zeros(n, np.int8), t_s=np.arange(n) * 0.01,
        kind="egpi", v_limits=(0.0, 4000.0), max_rate=float("inf"), quantum=1.0,
    )  # fmt: skip
    r = repr(c)
    assert len(r) <= MAX_REPR and "egpi" in r and "50 samples" in r and "0.1 deg" in r
    assert "rmse_deg" in c._repr_html_()


def test_compensator_repr_and_html():
    from i2ris_calib import Compensator

    c = Compensator({"yaw": model_for_kind("egpi")}, {"yaw": (0.0, 4000.0)},
                    signs={"yaw": -1}, max_counts_per_s=2000.0)  # fmt: skip
    assert repr(c) == "<Compensator yaw egpi at 0 counts>"
    h = c._repr_html_()
    assert h.startswith("<p><b>Compensator</b> yaw</p><table>")
    for cell in ("egpi", "-1", "0 .. 4000", "2000", "0"):
        assert f"<td>{cell}</td>" in h, cell
    cmd = c.step(target_yaw_deg=-0.5, dt_s=0.01)["yaw"]
    h = c._repr_html_()
    assert f"<td>{cmd.counts:.6g}</td>" in h and "<td>0.01</td>" in h  # the state stepped
    assert (
        "<td>none</td>"
        in Compensator({"yaw": model_for_kind("gpi")}, {"yaw": (0.0, 4000.0)})._repr_html_()
    )  # no rate limit
