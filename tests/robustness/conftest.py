"""A small rendered session shared by the robustness tests (helpers: robust_cli.py).

Every case of the fault matrix runs the CLI the way a user does
(``i2ris_calib.cli.main``) and checks the contract of issue 9: one line
``error: what, where, how to fix`` on stderr, exit 2, no traceback, nothing half
written, nothing previously good destroyed.
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

from i2ris_calib.commands.simulate import build_session  # noqa: E402
from i2ris_calib.simulation.presets import preset_config  # noqa: E402


@pytest.fixture(scope="session")
def rendered(tmp_path_factory) -> Path:
    """~8.6 s at 20 fps (173 frames per camera, 320x256): a yaw+ then a pitch- ramp
    (both axes turn ~40 deg), rest 1 s at the start (reference window), four flashes."""
    folder = tmp_path_factory.mktemp("robust") / "s"
    folder.mkdir()
    cfg = preset_config("ci", datasets=("yaw+", "pitch-"), ramp_s=0.8, pause_s=0.2,
                        settle_s=0.3, fps=20.0, seed=3)  # fmt: skip
    build_session(folder, cfg, name="s")
    return folder


@pytest.fixture(scope="session")
def serial_config(tmp_path_factory) -> Path:
    """Pipeline TOML with serial tracking (spawning workers costs more than tiny videos)."""
    p = tmp_path_factory.mktemp("cfg") / "serial.toml"
    p.write_text("[track]\nworkers = 1\n")
    return p


@pytest.fixture
def session(rendered, tmp_path) -> Path:
    """A private copy of the rendered session (tests may break it)."""
    dst = tmp_path / "s"
    shutil.copytree(rendered, dst)
    return dst
