"""End to end: rendered videos -> track -> sync -> diagnose names the hidden effect.

Slow (rendering and tracking two microscope videos per session): run with
``pytest -m slow tests/diagnosis/test_pipeline.py``.
"""

from __future__ import annotations

import json

import pytest

from i2ris_calib.cli import main

SESSION_TOML = """
[simulate]
seed = {seed}
width_px = 640
height_px = 512
marker_size_px = 110.0
datasets = ["yaw+"]
cycles = 8
cycle_fractions = [1.0, 0.5, 0.8, 0.6, 1.0, 0.7, 0.9, 1.0]
ramp_s = 3.0
pause_s = 1.5

[simulate.effects.{effect}]
{params}
"""


@pytest.mark.slow
@pytest.mark.parametrize(
    "effect, params, check",
    [
        ("time_delay", {"tau_s": 0.25}, lambda p: abs(p["tau_s"] - 0.25) < 0.04),
        (
            "saturation",
            {"knee_deg": 20.0, "limit_deg": 4.0},
            lambda p: abs(p["knee_deg"] - 20.0) < 1.5 and abs(p["limit_deg"] - 4.0) < 1.0,
        ),
    ],
)
def test_hidden_effect_found_through_the_pipeline(tmp_path, effect, params, check):
    cfg = tmp_path / "cfg.toml"
    body = "\n".join(f"{k} = {v}" for k, v in params.items())
    cfg.write_text(SESSION_TOML.format(seed=7, effect=effect, params=body))
    session = tmp_path / "session"
    assert main(["simulate", "--out", str(session), "--config", str(cfg)]) == 0
    assert main(["track", str(session)]) == 0
    assert main(["sync", str(session)]) == 0
    out = tmp_path / "diag"
    synced = session / "sync" / "synced.csv"
    assert main(["diagnose", str(synced), "--axis", "yaw", "--out", str(out)]) == 0
    rec = json.loads((out / "diagnosis.json").read_text())
    assert rec["named_effects"] == [effect]
    assert check(rec["steps"][0]["params"])
    assert rec["final"]["holdout_rmse_deg"] < 0.5 * rec["baseline"]["holdout_rmse_deg"]
