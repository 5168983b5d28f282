"""The online Compensator on the kinds issue 21 item 5 left out: the coupled two-motor
model (one axis given the other motor's counts, and both axes solved jointly), a model
with a time delay, and a start after a command history (a conditioning sweep) - each
against the batch ``compensate`` on the same target, and the plain-Python reference
stepper (tests/compensation/reference_compensator.py) on the exported JSON."""

from __future__ import annotations

import json

import numpy as np
import pytest
import reference_compensator as ref  # the pure-Python port (this folder)
from online_cases import AGPI_TRUTH

from i2ris_calib.compensation import compensate
from i2ris_calib.compensation.inverse import forward
from i2ris_calib.compensation.online import SCHEMA, UNSETTLED
from i2ris_calib.compensation.safety import conditioning_sweep
from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.pipeline import model_from_params
from i2ris_calib.hysteresis.effects import add_effect, base_of
from i2ris_calib.hysteresis.presets import gpi_values, paper_like_params
from i2ris_calib.hysteresis.registry import model_for_kind
from i2ris_calib.io.online import Compensator

LIM = (-4000.0, 4000.0)
#: coupling of each axis to the other motor (hysteretic, both sides, opposite signs)
COUPLING = dict(a1_cp=0.0009, a3_cp=0.0008, a4_cp=-0.3, lam_cp=0.06, sigma_cp=0.2, r1_cp=0.3,
                rn_cp=3.0, sign_cp=1.0, a1_cn=0.0007, a3_cn=0.0006, a4_cn=-0.2, lam_cn=0.06,
                sigma_cn=0.2, r1_cn=0.4, rn_cn=3.0, sign_cn=-1.0)  # fmt: skip
T = np.arange(1500) * 0.01
BATCH = dict(v_limits=LIM, entry=False, repair_spikes=False)


def coupled(**over):
    return model_for_kind("agpi_coupled", **(AGPI_TRUTH | COUPLING | over))


def circle():
    """A circle through zero (deg): yaw, pitch."""
    return 7 * np.sin(2 * np.pi * T / 6), 6 * np.cos(2 * np.pi * T / 6) - 1.0


def run(c, yaw, pitch, dts=None, other=None):
    dts = np.full(yaw.size, 0.01) if dts is None else dts
    out = []
    for k in range(yaw.size):
        kw = {} if other is None else {"other_counts": float(other[k])}
        out.append(c.step(float(yaw[k]), None if pitch is None else float(pitch[k]),
                          dt_s=float(dts[k]), **kw))  # fmt: skip
    return out


def counts(out, axis):
    return np.array([o[axis].counts for o in out])


@pytest.mark.parametrize("rate", [3000.0, None])
def test_coupled_axis_given_the_other_motor_is_the_batch(rate):
    model = coupled()
    yaw, _ = circle()
    vo = np.rint(2500 * np.sin(2 * np.pi * T / 5 + 0.4))
    res = compensate(model, yaw, T, max_rate=rate, v_initial=0.0, v_other=vo,
                     v_other_initial=300.0, **BATCH)  # fmt: skip
    c = Compensator({"yaw": model}, {"yaw": LIM}, max_counts_per_s=rate,
                    start_counts={"yaw": 0.0, "pitch": 300.0})  # fmt: skip
    assert c.coupled == {"yaw": "pitch"}
    out = run(c, yaw, None, other=vo)
    np.testing.assert_allclose(counts(out, "yaw"), res.commands, atol=1e-9, rtol=0)
    y = np.array([o["yaw"].predicted_deg for o in out])
    np.testing.assert_allclose(y, res.predicted_deg, atol=1e-9, rtol=0)
    assert [o["yaw"].status for o in out] == res.status.tolist()
    with pytest.raises(CalibError, match="other_counts") as e:
        c.step(1.0, dt_s=0.01)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("signs", [(1.0, 1.0), (-1.0, 1.0)])
def test_two_coupled_axes_solved_jointly_each_is_the_batch_given_the_other(signs):
    # the joint step settles at a fixed point: each axis's commands are then exactly
    # the batch inverse given the other motor's commands sent
    my, mp = coupled(), coupled(theta0=-0.3, a1_p=0.0075, sign_cn=1.0)
    yaw, pitch = circle()
    sy, sp = signs
    lim_y = LIM
    c = Compensator({"yaw": my, "pitch": mp}, {"yaw": lim_y, "pitch": LIM},
                    signs={"yaw": sy, "pitch": sp}, max_counts_per_s=4000.0)  # fmt: skip
    out = run(c, sy * yaw, sp * pitch)
    assert not any(UNSETTLED in o[a].flags for o in out for a in ("yaw", "pitch"))
    uy, up = counts(out, "yaw"), counts(out, "pitch")
    for axis, model, goal, sign, u, other in (("yaw", my, yaw, sy, uy, up),
                                              ("pitch", mp, pitch, sp, up, uy)):  # fmt: skip
        res = compensate(model, goal, T, max_rate=4000.0, v_initial=0.0, v_other=other,
                         v_other_initial=0.0, **BATCH)  # fmt: skip
        np.testing.assert_allclose(u, sign * res.commands, atol=1e-9, rtol=0)
        y = np.array([o[axis].predicted_deg for o in out])
        np.testing.assert_allclose(y, sign * res.predicted_deg, atol=1e-9, rtol=0)
        # the model follows the circle (the joint solve is not a poor one)
        assert np.sqrt(np.mean(res.error_deg[200:] ** 2)) < 0.05


def test_an_uncoupled_axis_with_a_coupled_one_needs_one_round():
    mp = coupled()
    my = model_for_kind("agpi", **AGPI_TRUTH)
    yaw, pitch = circle()
    c = Compensator({"yaw": my, "pitch": mp}, {"yaw": LIM, "pitch": LIM},
                    max_counts_per_s=4000.0)  # fmt: skip
    out = run(c, yaw, pitch)
    uy, up = counts(out, "yaw"), counts(out, "pitch")
    ry = compensate(my, yaw, T, max_rate=4000.0, v_initial=0.0, **BATCH)
    rp = compensate(mp, pitch, T, max_rate=4000.0, v_initial=0.0, v_other=uy,
                    v_other_initial=0.0, **BATCH)  # fmt: skip
    np.testing.assert_allclose(uy, ry.commands, atol=1e-9, rtol=0)
    np.testing.assert_allclose(up, rp.commands, atol=1e-9, rtol=0)


@pytest.mark.parametrize("kind", ["egpi", "egpi_c", "agpi"])
def test_delayed_model_steps_on_the_target_tau_ahead(kind):
    tau = 0.15
    if kind == "agpi":
        base, lim, target = model_for_kind("agpi", **AGPI_TRUTH), LIM, circle()[0]
    else:
        base = model_from_params(kind, paper_like_params("yaw+"), 30, 2.0)
        lim, target = (0.0, 6000.0), 15 + 8 * np.sin(0.7 * T) + 3 * np.sin(2.1 * T)
    model = add_effect(base, "time_delay", {"tau_s": tau})
    res = compensate(model, target, T, v_limits=lim, max_rate=5000.0, v_initial=0.0,
                     entry=False, repair_spikes=False)  # fmt: skip
    assert res.delay_s == pytest.approx(tau)
    c = Compensator({"yaw": model}, {"yaw": lim}, max_counts_per_s=5000.0)
    assert c.delays == {"yaw": pytest.approx(tau)}
    ahead = np.interp(T + tau, T, target)  # what a controller with the trajectory passes
    out = run(c, ahead, None)
    u = counts(out, "yaw")
    np.testing.assert_allclose(u, res.commands, atol=1e-9, rtol=0)
    # predicted: the angle tau after each command = the base model on the commands
    y = np.array([o["yaw"].predicted_deg for o in out])
    np.testing.assert_allclose(y, forward(base_of(model), u, T, 0.0), atol=1e-9, rtol=0)


@pytest.mark.parametrize("kind", ["gpi", "egpi", "egpi_c", "agpi_coupled"])
def test_start_after_a_history_is_the_batch_after_it(kind):
    rng = np.random.default_rng(4)
    if kind == "agpi_coupled":
        model, lim = coupled(), LIM
        target = circle()[0][:800]
        past = np.rint(np.interp(np.linspace(0, 8, 300), np.arange(9), rng.uniform(-3000, 3000, 9)))
        hist = np.concatenate((past, conditioning_sweep(past[-1], -3500, 3500, 3000, 0.01, 1.0)))
        hist_o = np.rint(1500 * np.sin(np.arange(hist.size) * 0.02))
        vo = np.rint(1500 * np.sin((hist.size + np.arange(800)) * 0.02))
    else:
        pp = paper_like_params("yaw+")
        model = model_from_params(kind, gpi_values(pp) if kind == "gpi" else pp, 30, 2.0)
        lim = (0.0, 6000.0)
        target = (15 + 6 * np.sin(T))[:800]
        past = np.rint(np.interp(np.linspace(0, 8, 300), np.arange(9), rng.uniform(0, 6000, 9)))
        hist = np.concatenate((past, conditioning_sweep(past[-1], 0, 6000, 3000, 0.01, 1.0)))
        hist_o, vo = None, None
    t = T[:800]
    res = compensate(model, target, t, v_limits=lim, max_rate=3000.0, v_history=hist,
                     v_other_history=hist_o, v_other=vo, entry=False, repair_spikes=False)  # fmt: skip
    history = {"yaw": hist} if hist_o is None else {"yaw": hist, "pitch": hist_o}
    c = Compensator({"yaw": model}, {"yaw": lim}, max_counts_per_s=3000.0, history=history)
    out = run(c, target, None, other=vo)
    np.testing.assert_allclose(counts(out, "yaw"), res.commands, atol=1e-9, rtol=0)
    y = np.array([o["yaw"].predicted_deg for o in out])
    np.testing.assert_allclose(y, res.predicted_deg, atol=1e-9, rtol=0)
    # advance() from the start state at the history's first counts is the same start
    c2 = Compensator(
        {"yaw": model},
        {"yaw": lim},
        max_counts_per_s=3000.0,
        start_counts={"yaw": hist[0], "pitch": 0.0 if hist_o is None else hist_o[0]},
    )
    c2.advance({k: v[1:] for k, v in history.items()}, dt_s=0.01)
    assert c2.state == Compensator({"yaw": model}, {"yaw": lim}, max_counts_per_s=3000.0,
                                   history=history).state  # fmt: skip


def test_history_refusals_are_one_line():
    model = coupled()
    for kw, match in (
        ({"history": {"yaw": [0.0, 10.0]}}, "history needs the counts of pitch"),
        ({"history": {"yaw": [0.0, 10.0], "pitch": [0.0]}}, "same number"),
        ({"history": {"yaw": [0.0, 9000.0], "pitch": [0.0, 0.0]}}, "outside the input range"),
    ):
        with pytest.raises(CalibError, match=match) as e:
            Compensator({"yaw": model}, {"yaw": LIM}, **kw)
        assert "\n" not in str(e.value)
    with pytest.raises(CalibError, match="time delay") as e:
        Compensator({"yaw": add_effect(model, "time_delay", {"tau_s": 0.1})}, {"yaw": LIM})
    assert "\n" not in str(e.value)


def _step_reference(axes, yaw, pitch, dt, vo=None):
    if len(axes) == 2 and (axes["yaw"].coupling or axes["pitch"].coupling):
        a, b = ref.step_pair(axes["yaw"], axes["pitch"], yaw, pitch, dt)
        return {"yaw": a, "pitch": b}
    out = {}
    for name, tk in (("yaw", yaw), ("pitch", pitch)):
        if name in axes:
            out[name] = axes[name].step(tk, dt, 0.0 if vo is None else vo) + (True,)
    return out


@pytest.mark.parametrize(
    "case", ["pair", "pair_strong", "one_coupled", "delay", "history", "real_valued"]
)
def test_json_and_reference_stepper_on_the_new_kinds(case, tmp_path):
    rng = np.random.default_rng(7)
    yaw, pitch = circle()
    vo = None
    if case == "pair_strong":  # a coupling 5x stronger: some joint steps do not settle
        strong = {k: 5 * v for k, v in COUPLING.items() if k[:2] in ("a1", "a3", "a4")}
        c = Compensator({"yaw": coupled(**strong), "pitch": coupled(theta0=-0.2, **strong)},
                        {"yaw": LIM, "pitch": LIM}, max_counts_per_s=5000.0)  # fmt: skip
    elif case == "pair":
        c = Compensator({"yaw": coupled(), "pitch": coupled(theta0=-0.2, sign_cp=-1.0)},
                        {"yaw": LIM, "pitch": LIM}, signs={"pitch": -1.0},
                        max_counts_per_s=5000.0)  # fmt: skip
    elif case == "one_coupled":
        c = Compensator({"pitch": coupled()}, {"pitch": LIM}, max_counts_per_s=5000.0,
                        start_counts={"yaw": -200.0})  # fmt: skip
        yaw, vo = None, np.rint(2000 * np.sin(T))
    elif case == "real_valued":  # quantum 0: the commands are the roots themselves
        base = model_from_params("egpi", paper_like_params("yaw+"), 30, 2.0)
        c = Compensator({"yaw": base, "pitch": coupled()}, {"yaw": (0.0, 6000.0), "pitch": LIM},
                        max_counts_per_s=5000.0, quantum=0.0)  # fmt: skip
        yaw = 15 + 8 * np.sin(T)
    elif case == "delay":
        base = model_from_params("egpi", paper_like_params("yaw+"), 30, 2.0)
        c = Compensator({"yaw": add_effect(base, "time_delay", {"tau_s": 0.1})},
                        {"yaw": (0.0, 6000.0)}, max_counts_per_s=5000.0)  # fmt: skip
        yaw, pitch = 15 + 8 * np.sin(T), None
    else:
        c = Compensator(
            {"yaw": coupled(), "pitch": model_for_kind("agpi", **AGPI_TRUTH)},
            {"yaw": LIM, "pitch": LIM},
            max_counts_per_s=5000.0,
            history={"yaw": [0.0, 800.0, -500.0], "pitch": [0.0, 300.0, 100.0]},
        )
    n0 = 50
    for k in range(n0):  # a state mid-way is exported too
        c.step(
            None if yaw is None else float(yaw[k]),
            None if pitch is None else float(pitch[k]),
            dt_s=0.01,
            **({} if vo is None else {"other_counts": float(vo[k])}),
        )
    c.to_json(tmp_path / "c.json")
    doc = json.loads((tmp_path / "c.json").read_text())
    assert doc["schema"] == SCHEMA
    loaded = Compensator.from_json(tmp_path / "c.json")
    axes = ref.load(tmp_path / "c.json")
    dts = rng.uniform(0.005, 0.015, 600)
    unsettled = 0
    for k in range(n0, n0 + 600):
        ty = None if yaw is None else float(yaw[k]) + rng.normal(0, 0.05)
        tp = None if pitch is None else float(pitch[k]) + rng.normal(0, 0.05)
        kw = {} if vo is None else {"other_counts": float(vo[k])}
        a = c.step(ty, tp, dt_s=float(dts[k - n0]), **kw)
        b = loaded.step(ty, tp, dt_s=float(dts[k - n0]), **kw)
        r = _step_reference(axes, ty, tp, float(dts[k - n0]), None if vo is None else vo[k])
        assert a == b
        for name, cmd in a.items():
            u, y, st, settled = r[name]
            assert abs(u - cmd.counts) <= 1e-9 and abs(y - cmd.predicted_deg) <= 1e-9
            assert st == cmd.status and settled == (UNSETTLED not in cmd.flags)
            unsettled += not settled
    assert (unsettled > 0) == (case == "pair_strong")


def test_schema_1_documents_still_load(tmp_path):
    model = model_from_params("egpi", paper_like_params("yaw+"), 30, 2.0)
    c = Compensator({"yaw": model}, {"yaw": (0.0, 6000.0)}, max_counts_per_s=5000.0)
    doc = c.to_dict()
    doc["schema"] = "i2ris-calib.compensator/1"
    for a in doc["axes"].values():
        del a["delay_s"], a["coupling"]
    del doc["joint_rounds"]
    (tmp_path / "old.json").write_text(json.dumps(doc))
    old = Compensator.from_json(tmp_path / "old.json")
    for x in 15 + 8 * np.sin(T[:300]):
        assert old.step(float(x))["yaw"] == c.step(float(x))["yaw"]


def _coupled_fit_json(path, axis, values):
    rec = {"params": values, "n_operators": 30, "deadband_counts": 2.0,
           "metrics": {"rmse_deg": 0.05}, "holdout_metrics": {"rmse_deg": 0.05}}  # fmt: skip
    agpi = dict(rec, params={k: v for k, v in values.items() if k in AGPI_TRUTH or k[-2:] in
                             ("_p", "_n") and not k.startswith("sign")},
                holdout_metrics={"rmse_deg": 0.5})  # fmt: skip
    ds = {
        "name": f"{axis}±",
        "input_range_counts": list(LIM),
        "max_input_rate_counts_per_s": 4000.0,
        "models": {"agpi_coupled": rec, "agpi": agpi},
    }
    path.write_text(json.dumps({"schema": "i2ris-calib.fit/1", "axis": axis, "datasets": [ds]}))
    return path


def test_from_fit_both_axes_coupled_after_a_history(tmp_path):
    my = coupled().value_dict()
    mp = coupled(theta0=-0.3).value_dict()
    fy = _coupled_fit_json(tmp_path / "y.json", "yaw", my)
    fp = _coupled_fit_json(tmp_path / "p.json", "pitch", mp)
    hist = {"yaw": [0.0, 1500.0, -2000.0, -2000.0], "pitch": [0.0, -800.0, 600.0, 500.0]}
    c = Compensator.from_fit([fy, fp], history=hist)
    assert c.coupled == {"yaw": "pitch", "pitch": "yaw"}
    assert c.to_dict()["axes"]["yaw"]["model"] == "agpi_coupled"
    assert c.state["yaw"].last_input == -2000.0 and c.state["pitch"].other_counts == -2000.0
    yaw, pitch = circle()
    out = run(c, yaw[:400], pitch[:400])
    uy, up = counts(out, "yaw"), counts(out, "pitch")
    res = compensate(coupled(), yaw[:400], T[:400], v_limits=LIM, max_rate=4000.0,
                     v_history=hist["yaw"], v_other_history=hist["pitch"], v_other=up,
                     entry=False, repair_spikes=False)  # fmt: skip
    np.testing.assert_allclose(uy, res.commands, atol=1e-9, rtol=0)
    # one fit alone: the uncoupled model by default (the coupled one needs the other motor)
    assert Compensator.from_fit(fy).to_dict()["axes"]["yaw"]["model"] == "agpi"


def test_from_fit_errors_name_its_arguments_not_cli_flags(tmp_path):
    fy = _coupled_fit_json(tmp_path / "y.json", "yaw", coupled().value_dict())
    for kwargs, needle in (
        ({"dataset": "yaw+"}, "choose dataset= from those"),
        ({"model": "gpi"}, "choose model= from those"),
    ):
        with pytest.raises(CalibError, match=needle) as exc:
            Compensator.from_fit(fy, **kwargs)
        assert "--" not in str(exc.value), str(exc.value)


def test_reset_returns_to_the_state_after_the_history():
    model = model_from_params("egpi", paper_like_params("yaw+"), 30, 2.0)
    hist = {"yaw": conditioning_sweep(0.0, 0.0, 6000.0, 3000.0, 0.01, 1.0)}
    c = Compensator({"yaw": model}, {"yaw": (0.0, 6000.0)}, max_counts_per_s=3000.0,
                    history=hist)  # fmt: skip
    start = c.state
    first = [c.step(float(x))["yaw"] for x in 15 + 5 * np.sin(T[:200])]
    c.reset()
    assert c.state == start
    assert [c.step(float(x))["yaw"] for x in 15 + 5 * np.sin(T[:200])] == first


def test_from_fit_diagnosed_model_with_its_delay(tmp_path):
    from i2ris_calib.hysteresis.codec import model_to_dict

    pp = paper_like_params("yaw+")
    model = add_effect(model_from_params("egpi", pp, 30, 2.0), "time_delay", {"tau_s": 0.1})
    (tmp_path / "final_model.json").write_text(json.dumps(model_to_dict(model)))
    rec = {"params": {p.name: p.value for p in model.parameters}, "n_operators": 30,
           "deadband_counts": 2.0, "holdout_metrics": {"rmse_deg": 0.1}}  # fmt: skip
    ds = {"name": "yaw+", "input_range_counts": [0.0, 6000.0],
          "max_input_rate_counts_per_s": 5000.0, "models": {"diagnosed": rec}}  # fmt: skip
    fit = tmp_path / "fit.json"
    fit.write_text(json.dumps({"schema": "i2ris-calib.fit/1", "axis": "yaw", "datasets": [ds]}))
    with pytest.raises(CalibError, match="needs model_file=") as exc:
        Compensator.from_fit(fit, model="diagnosed")
    assert "--" not in str(exc.value)  # a Python caller has no command-line flags
    c = Compensator.from_fit(fit, model="diagnosed", model_file=tmp_path / "final_model.json")
    assert c.delays == {"yaw": pytest.approx(0.1)}
    target = 15 + 5 * np.sin(T)
    out = run(c, np.interp(T + 0.1, T, target), None)
    res = compensate(model, target, T, v_limits=(0.0, 6000.0), max_rate=5000.0, v_initial=0.0,
                     entry=False, repair_spikes=False)  # fmt: skip
    np.testing.assert_allclose(counts(out, "yaw"), res.commands, atol=1e-9, rtol=0)
    assert c.to_dict()["axes"]["yaw"]["delay_s"] == pytest.approx(0.1)
