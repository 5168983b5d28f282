"""Fixtures of the report tests: synthetic run folders with known truth (see runfolder.py)."""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd
import pytest

sys.path.insert(0, str(Path(__file__).parent))

from runfolder import make_run_folder  # noqa: E402

from i2ris_calib.report.data import DiagnosisData, FitData, RunData  # noqa: E402


@pytest.fixture
def run_folder(tmp_path):
    """(path, truth) of a complete run folder with a yaw diagnosis."""
    root = tmp_path / "session_a"
    truth = make_run_folder(root, diagnosis=True)
    return root, truth


def run_data_from_folder(root: Path) -> RunData:
    """RunData read with plain pandas/json (independent of the io layer under test)."""
    import json

    fits = tuple(
        FitData(
            axis,
            json.loads((root / "fit" / axis / "fit.json").read_text()),
            pd.read_csv(root / "fit" / axis / "predictions.csv"),
        )
        for axis in ("yaw", "pitch")
        if (root / "fit" / axis / "fit.json").is_file()
    )
    diag_dir = root / "diagnose" / "yaw"
    diagnoses = ()
    if diag_dir.is_dir():
        diag = json.loads((diag_dir / "diagnosis.json").read_text())
        images = {rel: (diag_dir / rel).read_bytes() for rel in diag["steps"][0]["plots"]}
        diagnoses = (DiagnosisData("yaw", diag, (diag_dir / "diagnosis.md").read_text(), images),)
    return RunData(
        name=root.name,
        angles=pd.read_csv(root / "track" / "angles.csv"),
        track=json.loads((root / "track" / "track.json").read_text()),
        sync=json.loads((root / "sync" / "sync.json").read_text()),
        synced=pd.read_csv(root / "sync" / "synced.csv"),
        fits=fits,
        diagnoses=diagnoses,
    )


@pytest.fixture
def run_data(run_folder) -> tuple[RunData, dict]:
    root, truth = run_folder
    return run_data_from_folder(root), truth
