"""Regenerate everything in sample_data/ (deterministic; seeds fixed here).

    .venv/bin/python scripts/make_sample_data.py

- sample_data/session/: a small rendered two-microscope session (configs/sample_session.toml),
  the input of the README's first command.
- sample_data/datasets/{yaw_pos,yaw_neg,pitch_pos,pitch_neg}.csv: four paper-like synced
  datasets (docs/formats.md, "The synced CSV"): EGPI truth with the fixed paper-like
  parameters of each motion direction, a Fig-5-like input (ramps out and back with pauses,
  six loading cycles), 30 Hz, Gaussian angle noise 0.1 deg, 1 % of frames unmeasured.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "sample_data"
DATASETS = {"yaw+": "yaw_pos", "yaw-": "yaw_neg", "pitch+": "pitch_pos", "pitch-": "pitch_neg"}


def synced_dataset(name: str, seed: int) -> pd.DataFrame:
    """One paper-like motion-direction dataset in the synced-CSV format."""
    from i2ris_calib.hysteresis.models import i2ris_egpi_model
    from i2ris_calib.hysteresis.presets import loading_trajectory, paper_like_params

    rng = np.random.default_rng(seed)
    t, v = loading_trajectory(rng, n_cycles=6, rate_hz=30.0)
    params = paper_like_params(name)
    theta = i2ris_egpi_model().evaluate_dict(v, params) + rng.normal(0.0, 0.1, v.size)
    sign = -1.0 if name.endswith("-") else 1.0
    axis, other = ("yaw", "pitch") if name.startswith("yaw") else ("pitch", "yaw")
    status = np.where(rng.random(v.size) < 0.01, "not_found", "measured")
    angle = np.where(status == "measured", sign * theta, np.nan)
    return pd.DataFrame(
        {
            "time_s": np.round(t, 6),
            f"enc_{axis}": (sign * v).astype(int),
            f"enc_{other}": 0,
            f"{axis}_deg": np.round(angle, 5),
            f"{other}_deg": np.where(status == "measured", 0.0, np.nan),
            "status": status,
        }
    )[["time_s", "enc_yaw", "enc_pitch", "yaw_deg", "pitch_deg", "status"]]


def write_datasets() -> None:
    from i2ris_calib.io.atomic import write_csv

    for k, (name, stem) in enumerate(DATASETS.items()):
        write_csv(OUT / "datasets" / f"{stem}.csv", synced_dataset(name, seed=100 + k), "%.6f")


def write_session() -> None:
    from i2ris_calib.commands.simulate import write_simulated_session
    from i2ris_calib.io.config_io import load_config

    cfg = load_config(ROOT / "configs" / "sample_session.toml")
    write_simulated_session(OUT / "session", cfg, force=True)


if __name__ == "__main__":
    write_datasets()
    if "--datasets-only" not in sys.argv:
        write_session()
