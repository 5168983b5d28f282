"""The model codec's view of a fit.json model record (``fit_json_fields`` /
``model_from_fit_json``): what the ``fit`` command writes of a model and what
``compensate`` rebuilds from it, one encoding in ``hysteresis/codec.py``."""

from __future__ import annotations

import numpy as np
import pytest

from i2ris_calib.hysteresis.codec import fit_json_fields, model_from_fit_json, model_to_dict
from i2ris_calib.hysteresis.effects import add_effect
from i2ris_calib.hysteresis.registry import BUILT_KINDS, model_for_kind


@pytest.mark.parametrize("kind", BUILT_KINDS)
def test_a_fit_json_record_rebuilds_the_model(kind):
    model = model_for_kind(kind, n=12, deadband_counts=3.5)
    x = np.array([p.value for p in model.parameters], dtype=float)
    moved = model.with_values(np.where([p.fixed for p in model.parameters], x, x * 1.01))
    rec = {"params": moved.value_dict(), **fit_json_fields(moved)}
    assert rec["units"] == {p.name: p.unit for p in moved.parameters}
    assert rec["n_operators"] == 12
    back = model_from_fit_json(kind, rec)
    assert type(back) is type(moved)
    assert back.value_dict() == moved.value_dict()
    if "deadband_counts" in rec:
        assert rec["deadband_counts"] == back.deadband_counts == 3.5


def test_an_extended_model_reports_its_base_settings_as_final_model_json_does():
    model = add_effect(model_for_kind("egpi", n=20, deadband_counts=1.5), "time_delay",
                       {"tau_s": 0.1})  # fmt: skip
    own, base = fit_json_fields(model), model_to_dict(model)["base"]
    assert own["n_operators"] == base["n"] == 20
    assert own["deadband_counts"] == base["deadband_counts"] == 1.5
    assert "time_delay.tau_s" in own["units"]
    assert list(own) == ["units", "n_operators", "deadband_counts"]  # fit.json's key order
