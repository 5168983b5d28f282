"""The compensation plan (issue 34): the axis set-up, the rate limit, the start state and
the model choice before any inversion, file-free in compensation/; one Compensator; no
model-kind literal in compensation/."""

from __future__ import annotations

import ast
import dataclasses
from pathlib import Path

import numpy as np
import pytest

import i2ris_calib
from i2ris_calib.compensation.plan import (
    AxisPlan,
    FittedDataset,
    after_history,
    axis_plan,
    decided_kind,
    kinds_to_invert,
    online_kind,
    start_state,
    with_start,
    with_target,
)
from i2ris_calib.compensation.rate import FALLBACK_RANGE_SHARE_PER_S, rate_limit
from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.decision import Decision
from i2ris_calib.hysteresis.registry import ALL_KINDS

SRC = Path(i2ris_calib.__file__).parent


def fitted(name="yaw+", rng=(120.0, 5000.0), rate=800.0, virgin=True, kinds=("gpi", "egpi"),
           model="egpi", ranking=("egpi", "gpi")) -> FittedDataset:  # fmt: skip
    hold = {k: 0.1 * (i + 1) for i, k in enumerate(kinds)}
    return FittedDataset(name, "fit.json", rng, rate, tuple(kinds), hold, virgin,
                         Decision(name, model, "by the rule", tuple(ranking), tuple(hold.items())))  # fmt: skip


def test_no_model_kind_string_literal_in_compensation():
    """A kind's inverse family is its registry row's; compensation/ names no kind."""
    found = []
    for f in sorted((SRC / "compensation").glob("*.py")):
        for node in ast.walk(ast.parse(f.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Constant) and node.value in ALL_KINDS:
                found.append(f"{f.name}:{node.lineno} {node.value!r}")
    assert found == []


def test_one_class_named_compensator_the_public_one():
    where = [
        f.relative_to(SRC).as_posix()
        for f in SRC.rglob("*.py")
        for node in ast.walk(ast.parse(f.read_text(encoding="utf-8")))
        if isinstance(node, ast.ClassDef) and node.name == "Compensator"
    ]
    assert where == ["io/online.py"]
    assert i2ris_calib.Compensator.__module__ == "i2ris_calib.io.online"


@pytest.mark.parametrize(
    "name, rng, sign, lo, hi",
    [("yaw+", (120.0, 5000.0), 1.0, 0.0, 5000.0),  # a direction's range includes rest
     ("pitch-", (40.0, 3000.0), -1.0, 0.0, 3000.0),
     ("yaw±", (-3000.0, 4000.0), 1.0, -3000.0, 4000.0)],
)  # fmt: skip
def test_axis_plan_sign_and_range(name, rng, sign, lo, hi):
    plan = axis_plan(fitted(name, rng), None)
    assert (plan.axis, plan.name, plan.sign, plan.lo, plan.hi) == (name[:-1], name, sign, lo, hi)
    assert plan.rate.counts_per_s == 800.0 and plan.rate.warning is None
    with pytest.raises(dataclasses.FrozenInstanceError):
        plan.lo = 1.0  # type: ignore[misc]


def test_rate_limit_explicit_then_configured_then_recorded_then_fallback():
    assert rate_limit(800.0, 50.0, 70.0, 5000.0, "yaw+").source == "--max-counts-per-s"
    assert rate_limit(800.0, None, 70.0, 5000.0, "yaw+").counts_per_s == 70.0
    assert rate_limit(800.0, None, 0.0, 5000.0, "yaw+").counts_per_s == 800.0
    assert rate_limit(800.0, float("inf"), 0.0, 5000.0, "yaw+").counts_per_s == np.inf
    fb = rate_limit(None, None, 0.0, 5000.0, "yaw+", "max_counts_per_s=")
    assert fb.counts_per_s == FALLBACK_RANGE_SHARE_PER_S * 5000.0 == 500.0
    assert fb.source == "fallback" and fb.warning.startswith("yaw+: fit.json has no")
    assert fb.warning.endswith("give max_counts_per_s=")
    with pytest.raises(CalibError, match=r"^max_counts_per_s = 0: give a rate > 0") as e:
        rate_limit(800.0, 0.0, 0.0, 5000.0, "yaw+", "max_counts_per_s=")
    assert "\n" not in str(e.value)
    assert axis_plan(fitted(rate=None), None).rate.counts_per_s == 500.0  # range 0..5000


def test_start_input_and_history_start():
    plan = axis_plan(fitted("yaw-", (100.0, 4000.0)), None)
    t = np.arange(5) * 0.1
    p = with_target(plan, np.full(5, -3.0), t, None)
    assert (p.v0, p.start_source) == (0.0, "default (rest at 0)")
    assert np.array_equal(p.goal, np.full(5, 3.0))  # the model's convention
    assert with_target(plan, np.zeros(5), t, -250.0).v0 == 250.0
    with pytest.raises(CalibError, match=r"--start-counts 250 is outside .* -4000..0 counts"):
        with_target(plan, np.zeros(5), t, 250.0)
    moved = after_history({"yaw": p}, {"yaw": np.array([0.0, 30.0, 20.0])}, None, "h.csv")
    assert moved["yaw"].v0 == 20.0 and p.v0 == 0.0  # a new plan; the old one unchanged
    with pytest.raises(CalibError, match="not the history's last yaw counts -20"):
        after_history({"yaw": p}, {"yaw": np.array([0.0, 20.0])}, 5.0, "h.csv")


@pytest.mark.parametrize(
    "virgin, conditioning, history, sweep, method",
    [(False, "auto", False, True, "conditioning_sweep"),
     (True, "auto", False, False, "rest"),
     (None, "auto", False, False, "rest"),
     (False, "auto", True, False, "history"),
     (True, "sweep", True, True, "history+conditioning_sweep"),
     (False, "none", False, False, "rest")],
)  # fmt: skip
def test_start_state(virgin, conditioning, history, sweep, method):
    plans = {"yaw": axis_plan(fitted(virgin=virgin), None)}
    st = start_state(plans, conditioning, history)
    assert (st.sweep, st.method) == (sweep, method)
    if virgin is None and conditioning == "auto" and not history:
        assert "older fit" in st.reason


def test_with_start_pads_the_shorter_sweep_and_starts_the_entry_at_its_end():
    t = np.arange(50) * 0.01
    goal = np.linspace(1.0, 5.0, 50)  # rises: the sweep ends at lo
    plans = {
        "yaw": with_target(axis_plan(fitted("yaw+", (0.0, 1000.0), 1e5), None), goal, t, None),
        "pitch": with_target(axis_plan(fitted("pitch+", (0.0, 300.0), 1e5), None), goal, t,
                             None),
    }  # fmt: skip
    out = with_start(plans, start_state(plans, "sweep", False), None, t)
    y, p = out["yaw"], out["pitch"]
    assert y.hist.size == p.hist.size and y.n_pre == p.n_pre == 1
    assert y.v_entry == p.v_entry == 0.0 and y.sweep_ends == (1000.0, 0.0)
    assert np.max(y.hist) == 1000.0 and np.max(p.hist) == 300.0
    assert all(a.hist is None for a in with_start(plans, start_state(plans, "none", False),
                                                  None, t).values())  # fmt: skip


def test_kinds_to_invert_and_the_decision_with_a_refusal():
    plan = axis_plan(fitted("yaw±", (-3000.0, 3000.0), kinds=("agpi", "agpi_coupled",
                                                               "bouc_wen")), None)  # fmt: skip
    assert kinds_to_invert(plan, both_axes=False, model=None, model_file=False) == ["agpi"]
    assert kinds_to_invert(plan, True, None, False) == ["agpi", "agpi_coupled"]
    with pytest.raises(CalibError, match="needs the pitch motor's commands"):
        kinds_to_invert(plan, False, "agpi_coupled", False)
    fit = fitted("yaw±", kinds=("agpi", "agpi_coupled"), model="agpi_coupled",
                 ranking=("agpi_coupled", "agpi"))  # fmt: skip
    assert online_kind(fit, None, coupled_ok=True) == ("agpi_coupled", "")
    kind, note = online_kind(fit, None, coupled_ok=False)
    assert kind == "agpi" and "instead of the recommended agpi_coupled" in note
    with pytest.raises(CalibError, match=r"^fit.json \[yaw±\]: "):
        decided_kind(fit.decision, lambda k: "no", "fit.json [yaw±]")
    with pytest.raises(CalibError, match="model must be one of gpi, egpi"):
        online_kind(fit, "bouc_wen", coupled_ok=True)


def test_axis_plan_is_the_one_axis_set_up():
    """commands/compensate.py and io/online.py set their axes up with axis_plan only."""
    for rel in ("commands/compensate.py", "io/online.py"):
        text = (SRC / rel).read_text(encoding="utf-8")
        assert "axis_plan(" in text and 'endswith("±")' not in text, rel
    assert isinstance(axis_plan(fitted(), None), AxisPlan)
