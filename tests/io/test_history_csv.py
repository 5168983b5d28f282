"""``compensate --history``: the commands sent before, read against the compensation
plans (:class:`~i2ris_calib.compensation.plan.AxisPlan`: each axis's sign and input
range), not a loose dict."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from i2ris_calib.compensation.plan import FittedDataset, axis_plan
from i2ris_calib.errors import CalibError
from i2ris_calib.fitting.decision import Decision
from i2ris_calib.io.target_csv import read_history


def plan(name: str, rng=(0.0, 4000.0)):
    fit = FittedDataset(name, "fit.json", rng, 800.0, ("gpi",), {"gpi": 0.1}, True,
                        Decision(name, "gpi", "by the rule", ("gpi",), (("gpi", 0.1),)))  # fmt: skip
    return axis_plan(fit, None)


def test_history_is_read_in_each_plans_convention(tmp_path):
    csv = tmp_path / "history.csv"
    pd.DataFrame({"enc_yaw": [0.0, 100.0, 250.0], "enc_pitch": [0.0, -50.0, -300.0]}).to_csv(
        csv, index=False
    )
    past = read_history(csv, {"yaw": plan("yaw+"), "pitch": plan("pitch-", (0.0, 1000.0))})
    np.testing.assert_array_equal(past["yaw"], [0.0, 100.0, 250.0])
    np.testing.assert_array_equal(past["pitch"], [0.0, 50.0, 300.0])  # sign -1: model's input


def test_counts_outside_the_plans_range_name_the_dataset(tmp_path):
    csv = tmp_path / "history.csv"
    pd.DataFrame({"enc_yaw": [0.0, -10.0, -2000.0]}).to_csv(csv, index=False)
    with pytest.raises(CalibError, match=r"outside the yaw- fit's input range -1000\.\.0 counts"):
        read_history(csv, {"yaw": plan("yaw-", (0.0, 1000.0))})
