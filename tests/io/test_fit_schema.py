"""fit.json's check (io/fit_schema.py) for kinds whose parameter names depend on n."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest

from i2ris_calib.cli import main
from i2ris_calib.errors import CalibError
from i2ris_calib.hysteresis.registry import model_for_kind
from i2ris_calib.io.fit import read_fit_json

ROOT = Path(__file__).resolve().parents[2]


def test_maxwell_slip_with_its_own_number_of_thresholds(tmp_path):
    """A Maxwell-slip record with n = 5 has w0..w5: checked against n_operators, not
    against the kind's default 15 thresholds."""
    csv = ROOT / "sample_data" / "datasets" / "yaw_pos.csv"
    assert main(["fit", str(csv), "--axis", "yaw", "--model", "gpi", "--out",
                 str(tmp_path / "o")]) == 0  # fmt: skip
    path = tmp_path / "o" / "fit.json"
    doc = json.loads(path.read_text())
    rec = copy.deepcopy(doc["datasets"][0]["models"]["gpi"])
    names = model_for_kind("maxwell_slip", n=5).names
    rec.update(params={k: 0.1 for k in names}, stderr={k: None for k in names}, n_operators=5,
               units={k: "deg" for k in names}, free=list(names))  # fmt: skip
    doc["datasets"][0]["models"]["maxwell_slip"] = rec
    doc["models"] = doc["datasets"][0]["models"]
    path.write_text(json.dumps(doc))
    got = read_fit_json(path)
    assert set(got["datasets"][0]["models"]["maxwell_slip"]["params"]) == set(names)
    rec["n_operators"] = 15  # the names of 5 thresholds under the default: refused
    path.write_text(json.dumps(doc))
    with pytest.raises(CalibError, match="maxwell_slip.params has no w6"):
        read_fit_json(path)
