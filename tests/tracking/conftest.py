"""Fixtures for tracking tests: a small rendered session with known truth."""

from __future__ import annotations

import pandas as pd
import pytest

from i2ris_calib.commands.simulate import build_session
from i2ris_calib.commands.track import track
from i2ris_calib.io.session import load_session
from i2ris_calib.simulation.presets import preset_config
from i2ris_calib.tracking.config import TrackingConfig


@pytest.fixture(scope="session")
def ci_session(tmp_path_factory):
    """Folder of a rendered CI session (320x256, 80 px markers, yaw+ and pitch-, ~10 s)."""
    folder = tmp_path_factory.mktemp("ci_session")
    build_session(folder, preset_config("ci", seed=7), name="ci")
    return folder


@pytest.fixture(scope="session")
def ci_tracked(ci_session):
    """(angles DataFrame merged with truth_frames.csv, summary) of the CI session."""

    res = track(ci_session, load_session(ci_session), TrackingConfig())
    truth = pd.read_csv(ci_session / "truth" / "truth_frames.csv")
    merged = res["angles"].merge(truth, on="frame", suffixes=("", "_true"))
    return merged, res["summary"]
