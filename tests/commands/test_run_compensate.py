"""`run` with a [compensate] target: commands from this run's fits, shown in the report."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from test_fit_command import synced_frame

from i2ris_calib.cli import main
from i2ris_calib.commands.run import compensate_run, compensation_target
from i2ris_calib.compensation.config import CompensateConfig
from i2ris_calib.config import PipelineConfig
from i2ris_calib.errors import CalibError


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    root = tmp_path_factory.mktemp("run")
    synced_frame(directions=("yaw+",), n=800).to_csv(root / "synced.csv", index=False)
    assert (
        main(["fit", str(root / "synced.csv"), "--axis", "yaw", "--out", str(root / "fit" / "yaw")])
        == 0
    )
    t = np.arange(0.0, 12.0, 0.05)
    pd.DataFrame({"time_s": t, "yaw_deg": 15 + 8 * np.sin(2 * np.pi * t / 6)}).to_csv(
        root / "target.csv", index=False
    )
    return root


def test_compensate_stage_writes_commands_and_report_section(run_dir):
    cfg = PipelineConfig(
        compensate=CompensateConfig(target="target.csv", max_counts_per_s=float("inf"))
    )
    target = compensation_target(run_dir, "target.csv")
    compensate_run(run_dir, target, run_dir / "compensate", cfg)
    doc = json.loads((run_dir / "compensate" / "compensate.json").read_text())
    assert doc["axes"]["yaw"]["dataset"] == "yaw+"  # direction from the target's sign
    cmds = pd.read_csv(run_dir / "compensate" / "commands.csv")
    # the fitted model follows a reachable smooth target to well within the noise it was fitted on
    assert doc["axes"]["yaw"]["rmse_reachable_deg"] < 0.01 and cmds["reachable"].mean() > 0.95
    from i2ris_calib.io.run_folder import load_run
    from i2ris_calib.report.build import build_document

    run, _ = load_run(run_dir)
    titles = [s.title for s in build_document(run).sections]
    assert "Feedforward compensation" in titles


def test_missing_target_and_bad_config():
    with pytest.raises(CalibError, match="not found"):
        compensation_target(__import__("pathlib").Path("/nonexistent"), "nope.csv")
    with pytest.raises(ValueError, match="one direction per axis"):
        CompensateConfig(datasets=("yaw+", "yaw-")).validate()
    with pytest.raises(ValueError, match="max_counts_per_s"):
        CompensateConfig(max_counts_per_s=-1).validate()


@pytest.mark.parametrize(
    "write",
    [lambda p: p.write_text("time_s,yaw_deg\n0,5\n0.1,6\n", encoding="utf-16"),
     lambda p: p.write_bytes(b"")],
    ids=["utf16", "empty"],
)  # fmt: skip
def test_unreadable_target_is_one_line_in_run(run_dir, tmp_path, write):
    """The target's header, read to pick the axes: UnicodeDecodeError / EmptyDataError."""
    write(tmp_path / "bad.csv")
    cfg = PipelineConfig(compensate=CompensateConfig(target=str(tmp_path / "bad.csv")))
    out = tmp_path / "compensate"
    with pytest.raises(CalibError, match="bad.csv: not a readable CSV") as exc:
        compensate_run(run_dir, tmp_path / "bad.csv", out, cfg)
    assert "\n" not in str(exc.value) and not out.exists()


def test_the_example_config_runs_on_the_sample_session(run_dir, tmp_path):
    """configs/compensate.example.toml names target.csv; the sample session ships one
    (a reachable yaw target), so the example runs on it as is."""
    from dataclasses import replace
    from pathlib import Path

    from i2ris_calib.io.config_io import load_config

    root = Path(__file__).resolve().parents[2]
    cfg = load_config(root / "configs" / "compensate.example.toml")
    target = compensation_target(root / "sample_data" / "session", cfg.compensate.target)
    assert target == root / "sample_data" / "session" / "target.csv"
    (tmp_path / "c").mkdir()
    # this module's fit recorded a slow motor (400 counts/s); the sample session's 3000
    unlimited = replace(cfg, compensate=replace(cfg.compensate, max_counts_per_s=float("inf")))
    compensate_run(run_dir, target, tmp_path / "c", unlimited)
    doc = json.loads((tmp_path / "c" / "compensate.json").read_text())
    assert doc["axes"]["yaw"]["dataset"] == "yaw+"
    assert pd.read_csv(tmp_path / "c" / "commands.csv")["reachable"].mean() > 0.9
