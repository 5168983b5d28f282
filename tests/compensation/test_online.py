"""The online Compensator: the batch's commands step by step, its JSON and the plain
Python reference stepper (the spec of a C++/ROS implementation), and the two-tendon
GPI's inverse (agpi) fitted from noisy data."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
import reference_compensator as ref  # the pure-Python port (this folder)
from online_cases import AGPI_TRUTH

from i2ris_calib.compensation import compensate
from i2ris_calib.compensation.inverse import forward
from i2ris_calib.compensation.online import AxisState
from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.pipeline import model_from_params
from i2ris_calib.hysteresis.presets import gpi_values, paper_like_params
from i2ris_calib.hysteresis.registry import model_for_kind
from i2ris_calib.io.online import Compensator


def make(kind):
    """(model, v_limits, target (n,), t (n,)) of a kind: a 20 s, 100 Hz smooth target."""
    t = np.arange(2000) * 0.01
    wave = 8 * np.sin(0.7 * t) + 3 * np.sin(2.1 * t)
    if kind == "agpi":
        return model_for_kind("agpi", **AGPI_TRUTH), (-4000.0, 4000.0), wave, t
    pp = paper_like_params("yaw+")
    model = model_from_params(kind, gpi_values(pp) if kind == "gpi" else pp, 30, 2.0)
    return model, (0.0, 6000.0), 15 + wave, t


@pytest.mark.parametrize("rate", [5000.0, None])
@pytest.mark.parametrize("kind", ["gpi", "egpi", "egpi_c", "agpi"])
def test_step_gives_the_batch_commands(kind, rate):
    model, lim, target, t = make(kind)
    start = 0.0
    res = compensate(model, target, t, v_limits=lim, max_rate=rate, v_initial=start,
                     entry=False, repair_spikes=False)  # fmt: skip
    c = Compensator({"yaw": model}, {"yaw": lim}, max_counts_per_s=rate, start_counts=start)
    dts = np.diff(t, prepend=t[0] - (t[1] - t[0]))
    steps = [c.step(x, dt_s=float(dt))["yaw"] for x, dt in zip(target, dts, strict=True)]
    u = np.array([s.counts for s in steps])
    np.testing.assert_allclose(u, res.commands, atol=1e-9, rtol=0)
    y = np.array([s.predicted_deg for s in steps])
    np.testing.assert_allclose(y, res.predicted_deg, atol=1e-7, rtol=0)
    assert [s.status for s in steps] == res.status.tolist()


def test_minus_dataset_sign_and_two_axes():
    gpi = model_from_params("gpi", gpi_values(paper_like_params("yaw-")), 30, 2.0)
    agpi = model_for_kind("agpi", **AGPI_TRUTH)
    t = np.arange(500) * 0.01
    yaw = -(15 + 8 * np.sin(0.7 * t))  # a "-" dataset: robot angle and counts negative
    pitch = 6 * np.sin(1.3 * t)
    c = Compensator({"yaw": gpi, "pitch": agpi}, {"yaw": (0.0, 6000.0), "pitch": (-4000, 4000)},
                    signs={"yaw": -1.0}, max_counts_per_s=3000.0)  # fmt: skip
    out = [c.step(y, p, dt_s=0.01) for y, p in zip(yaw, pitch, strict=True)]
    for axis, goal, model, sign, lim in (("yaw", -yaw, gpi, -1, (0, 6000)),
                                         ("pitch", pitch, agpi, 1, (-4000, 4000))):  # fmt: skip
        res = compensate(model, goal, t, v_limits=lim, max_rate=3000.0, v_initial=0.0,
                         entry=False, repair_spikes=False)  # fmt: skip
        u = np.array([o[axis].counts for o in out])
        np.testing.assert_allclose(u, sign * res.commands, atol=1e-9, rtol=0)
    assert all(o["yaw"].counts <= 0 for o in out)


def test_state_reset_continues_identically():
    model, lim, target, _ = make("egpi")
    c = Compensator({"yaw": model}, {"yaw": lim}, max_counts_per_s=4000.0)
    for x in target[:700]:
        c.step(x, dt_s=0.01)
    saved = c.state
    assert isinstance(saved["yaw"], AxisState)
    a = [c.step(x, dt_s=0.01)["yaw"].counts for x in target[700:900]]
    c.reset()
    assert c.state["yaw"].last_input == 0.0
    c.reset(saved)
    b = [c.step(x, dt_s=0.01)["yaw"].counts for x in target[700:900]]
    assert a == b
    with pytest.raises(CalibError, match="give a state of the axes yaw"):
        c.reset({"pitch": saved["yaw"]})


@pytest.mark.parametrize("kind", ["gpi", "egpi", "egpi_c", "agpi"])
def test_json_and_reference_stepper_reproduce_step(kind, tmp_path):
    model, lim, target, _ = make(kind)
    rng = np.random.default_rng(1)
    c = Compensator({"yaw": model}, {"yaw": lim}, max_counts_per_s=6000.0)
    for x in target[:50]:  # a state mid-way is exported too
        c.step(x, dt_s=0.01)
    c.to_json(tmp_path / "c.json")
    doc = json.loads((tmp_path / "c.json").read_text())
    assert doc["axes"]["yaw"]["model"] == kind and doc["axes"]["yaw"]["max_counts_per_s"] == 6000
    loaded = Compensator.from_json(tmp_path / "c.json")
    axes = ref.load(tmp_path / "c.json")
    goal = np.concatenate((target[50:], target[:50]))[:1000] + rng.normal(0, 0.05, 1000)
    dts = rng.uniform(0.005, 0.015, 1000)
    for x, dt in zip(goal, dts, strict=True):
        a = c.step(float(x), dt_s=float(dt))["yaw"]
        b = loaded.step(float(x), dt_s=float(dt))["yaw"]
        u, y, st = axes["yaw"].step(float(x), float(dt))
        assert a == b
        assert abs(u - a.counts) <= 1e-9 and abs(y - a.predicted_deg) <= 1e-9 and st == a.status


def test_refusals_are_one_line(tmp_path):
    from i2ris_calib.hysteresis.effects import add_effect

    model, lim, _, _ = make("egpi")
    coupled = add_effect(model_for_kind("agpi_coupled"), "time_delay", {"tau_s": 0.1})
    with pytest.raises(CalibError, match="time delay") as e:
        Compensator({"yaw": coupled}, {"yaw": (-4000, 4000)})
    assert "\n" not in str(e.value)
    c = Compensator({"yaw": model}, {"yaw": lim})
    with pytest.raises(CalibError, match="target_yaw_deg"):
        c.step(None, dt_s=0.01)
    with pytest.raises(CalibError, match="dt_s"):
        c.step(1.0, dt_s=0.0)
    with pytest.raises(CalibError, match="outside the input range"):
        Compensator({"yaw": model}, {"yaw": lim}, start_counts=-5.0)
    # the batch's checks of the range, rate and quantum, named for the axis
    with pytest.raises(CalibError, match=r"^Compensator: yaw v_limits must be finite"):
        Compensator({"yaw": model}, {"yaw": (100.0, 100.0)})
    with pytest.raises(CalibError, match=r"^Compensator: yaw max_counts_per_s must be > 0"):
        Compensator({"yaw": model}, {"yaw": lim}, max_counts_per_s=0.0)
    (tmp_path / "bad.json").write_text("{}")
    with pytest.raises(CalibError, match="not a compensator document"):
        Compensator.from_json(tmp_path / "bad.json")


def _fit_agpi(tmp_path, seed=3):
    """A signed fit of noisy data (0.05 deg) from the two-tendon truth through zero."""
    from dataclasses import replace

    from i2ris_calib.commands.fit import fit_files
    from i2ris_calib.io.config_io import load_config

    rng = np.random.default_rng(seed)
    t = np.arange(0, 80, 1 / 30)
    enc = np.round(3500 * np.sin(2 * np.pi * t / 20) * (0.6 + 0.4 * np.cos(2 * np.pi * t / 53)))
    truth = model_for_kind("agpi", **AGPI_TRUTH)
    theta = forward(truth, enc, t) + rng.normal(0, 0.05, t.size)
    pd.DataFrame({"time_s": t, "enc_yaw": enc, "yaw_deg": theta}).to_csv(
        tmp_path / "s.csv", index=False
    )
    cfg = load_config(None)
    cfg = replace(cfg, fit=replace(cfg.fit, signed=True))
    fit_files([tmp_path / "s.csv"], "yaw", "agpi", tmp_path / "fit", cfg)
    return truth, tmp_path / "fit" / "fit.json"


def test_agpi_fitted_from_noisy_data_tracks_a_target_through_zero(tmp_path):
    from i2ris_calib.commands.compensate import compensate_files
    from i2ris_calib.io.fit import read_fit_json
    from i2ris_calib.io.fit_records import load_model

    truth, fit_json = _fit_agpi(tmp_path)
    doc = read_fit_json(fit_json)
    rec = next(d for d in doc["datasets"] if d["name"] == "yaw±")
    fitted = load_model(doc, rec, "agpi", fit_json)
    tt = np.arange(0, 30, 0.01)
    target = 7.0 * np.sin(2 * np.pi * tt / 10)  # one axis of a circle through zero
    pd.DataFrame({"time_s": tt, "yaw_deg": target}).to_csv(tmp_path / "t.csv", index=False)
    out = compensate_files([fit_json], ["yaw±"], tmp_path / "t.csv", tmp_path / "c.csv",
                           model="agpi")  # fmt: skip
    ax = out["axes"]["yaw"]
    rate, lo, hi = ax["max_counts_per_s"], *ax["input_range_counts"]
    assert rate is not None and ax["spikes_left"] == 0
    df = pd.read_csv(tmp_path / "c.csv")
    u, ts = df["enc_yaw"].to_numpy(float), df["time_s"].to_numpy()
    assert np.max(np.abs(np.diff(u)) / np.diff(ts)) <= rate * (1 + 1e-9) + 1 / 0.01  # one count
    assert (u < 0).any() and (u > 0).any()
    n = ax["n_entry"]
    ideal = compensate(truth, target, tt, v_limits=(lo, hi), max_rate=rate, v_initial=0.0)
    e_ideal = forward(truth, ideal.commands, tt, 0.0) - target
    for plant in (fitted, truth):
        achieved = forward(plant, u, ts)[n:]
        rmse = np.sqrt(np.mean((achieved - target) ** 2))
        assert rmse <= 1.2 * np.sqrt(np.mean(e_ideal**2)) + 0.02, (plant.name, rmse)
    # up-and-back command spikes: none left
    d1, d2 = np.diff(u)[:-1], np.diff(u)[1:]
    back = (d1 * d2 < 0) & (np.minimum(abs(d1), abs(d2)) > 0.01 * (hi - lo))
    assert not back.any()


def test_agpi_coupled_needs_the_other_axis_one_line(tmp_path):
    agpi = model_for_kind("agpi_coupled", **AGPI_TRUTH)
    with pytest.raises(CalibError, match="other motor's commands") as e:
        compensate(agpi, np.zeros(10), np.arange(10) * 0.01, v_limits=(-100, 100))
    assert "\n" not in str(e.value)
    vo = 500 * np.sin(np.arange(200) * 0.05)
    target = forward(agpi, 1500 * np.sin(np.arange(200) * 0.03), None, 0.0, v_other=vo)
    res = compensate(agpi, target, np.arange(200) * 0.01, v_limits=(-4000, 4000), v_initial=0.0,
                     v_other=vo, v_other_initial=0.0)  # fmt: skip
    assert res.summary()["rmse_deg"] < 0.01


def test_online_kinds_are_the_registrys_inverse_kinds():
    """io.online's kinds come from the registry: every kind the batch inverts, each on
    the kernel kind of its registry row's inverse family (a coupled kind: plus the
    coupling); the JSON names the kernel kinds as before."""
    from i2ris_calib.compensation.online import KIND_NAMES
    from i2ris_calib.compensation.plan import COUPLED_KINDS
    from i2ris_calib.hysteresis.kinds import INVERSE_FAMILIES
    from i2ris_calib.hysteresis.registry import INVERSE_KINDS, kind_info
    from i2ris_calib.io import online as io_online

    assert io_online.ONLINE_KINDS == INVERSE_KINDS == (*KIND_NAMES.values(), "agpi_coupled")
    assert KIND_NAMES == {0: "gpi", 1: "egpi", 2: "egpi_c", 3: "agpi"}
    assert tuple(KIND_NAMES.values()) == INVERSE_FAMILIES
    assert COUPLED_KINDS == ("agpi_coupled",)
    for k in io_online.ONLINE_KINDS:
        assert kind_info(k).inverse in KIND_NAMES.values()


# ---------------------------------------------------------------- issue 33: values checked


def _saved(tmp_path):
    model, lim, target, _ = make("egpi")
    c = Compensator({"yaw": model}, {"yaw": lim}, max_counts_per_s=4000.0)
    for x in target[:20]:
        c.step(x, dt_s=0.01)
    c.to_json(tmp_path / "c.json")
    return json.loads((tmp_path / "c.json").read_text())


def _nan_c(a):
    a["c"][0] = float("nan")


@pytest.mark.parametrize(
    ("edit", "needle"),
    [
        (lambda a: a.update(start_counts=99999.0), "start input 99999"),
        (lambda a: a["state"].update(last_input=1e9), "state last_input 1e+09 is outside"),
        (_nan_c, "c[0] is nan"),
        (lambda a: a["p"].__setitem__(3, float("inf")), "p[3] is inf"),
        (lambda a: a.update(v_limits=[6000.0, 0.0]), "v_limits must be finite with lo < hi"),
        (lambda a: a.update(max_counts_per_s=-5.0), "max_counts_per_s must be > 0"),
        (lambda a: a.update(quantum=-1.0), "quantum must be >= 0"),
        (lambda a: a.update(tol_deg=-0.1), "tol_deg = -0.1 is not valid"),
        (lambda a: a.update(deadband_counts=-2.0), "deadband_counts = -2 is not valid"),
        (lambda a: a["params"].update(lam=float("nan")), "params['lam'] is nan"),
    ],
    ids=["start", "last-input", "nan-coefficient", "inf-weight", "reversed-limits",
         "negative-rate", "quantum", "tol", "deadband", "nan-param"],
)  # fmt: skip
def test_from_json_checks_values_as_from_fit_does(tmp_path, edit, needle):
    """Types were checked, values not: a start of 99999 counts in 0..6000, a state at
    1e9 counts, a NaN coefficient ("reached" with a NaN angle), reversed limits, a
    negative rate were all loaded."""
    doc = _saved(tmp_path)
    edit(doc["axes"]["yaw"])
    (tmp_path / "bad.json").write_text(json.dumps(doc))
    with pytest.raises(CalibError) as exc:
        Compensator.from_json(tmp_path / "bad.json")
    msg = str(exc.value)
    assert needle in msg and "bad.json" in msg and "axis 'yaw'" in msg and "\n" not in msg, msg


def test_from_json_of_a_good_file_still_loads(tmp_path):
    doc = _saved(tmp_path)
    (tmp_path / "ok.json").write_text(json.dumps(doc))
    c = Compensator.from_json(tmp_path / "ok.json")
    assert c.state["yaw"].last_input == doc["axes"]["yaw"]["state"]["last_input"]


@pytest.mark.parametrize(
    ("call", "needle"),
    [
        (lambda c: c.step("12"), "target_yaw_deg is the str '12'; give a number"),
        (lambda c: c.step(np.array([12.0])), "target_yaw_deg is an array of shape (1,)"),
        (lambda c: c.step([12.0]), "target_yaw_deg is a list of 1 item"),
        (lambda c: c.step(12.0, dt_s="0.01"), "dt_s is the str '0.01'; give a number"),
        (lambda c: c.step(12.0, dt_s=np.array([0.01])), "dt_s is an array of shape (1,)"),
        (lambda c: c.reset({"yaw": "x"}), "state['yaw'] is the str 'x'; give a AxisState"),
        (lambda c: c.advance({"yaw": "abc"}), "commands['yaw'] is the str 'abc'"),
        (lambda c: c.advance({"yaw": [1.0, "a"]}), "commands['yaw'] is not numeric"),
        (lambda c: c.advance({"yaw": [1.0]}, dt_s="x"), "dt_s is the str 'x'"),
    ],
    ids=["str-target", "array-target", "list-target", "str-dt", "array-dt", "reset-str",
         "advance-str", "advance-mixed", "advance-dt"],
)  # fmt: skip
def test_wrong_argument_types_are_one_line_calib_errors(call, needle):
    """Raw TypeError / AttributeError / ValueError before."""
    model, lim, _, _ = make("egpi")
    c = Compensator({"yaw": model}, {"yaw": lim})
    before = c.state
    with pytest.raises(CalibError) as exc:
        call(c)
    msg = str(exc.value)
    assert needle in msg and "\n" not in msg and msg.startswith("Compensator."), msg
    assert c.state == before  # nothing stepped
    c.step(np.float32(12.0), dt_s=np.float64(0.01))  # numpy scalars are numbers


def test_history_of_strings_is_one_line():
    model, lim, _, _ = make("egpi")
    for bad, needle in (("abc", "is the str 'abc'"), ([1.0, "x"], "is not numeric"),
                        ([], "has 0 samples; give at least 1")):  # fmt: skip
        with pytest.raises(CalibError, match=r"^Compensator: history\['yaw'\] ") as exc:
            Compensator({"yaw": model}, {"yaw": lim}, history={"yaw": bad})
        assert needle in str(exc.value)


def test_reset_to_a_state_outside_the_range_refused():
    model, lim, _, _ = make("egpi")
    c = Compensator({"yaw": model}, {"yaw": lim})
    from dataclasses import replace

    bad = {"yaw": replace(c.state["yaw"], last_input=1e9)}
    with pytest.raises(CalibError, match=r"^Compensator.reset: yaw: state last_input 1e\+09"):
        c.reset(bad)
