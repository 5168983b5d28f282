"""Regenerate everything in sample_data/ (deterministic; seeds fixed here).

    .venv/bin/python scripts/make_sample_data.py

- sample_data/session/: a small rendered two-microscope session (configs/sample_session.toml),
  the input of the README's first command, and its target.csv: a yaw tip trajectory for
  compensation (configs/compensate.example.toml).
- sample_data/datasets/{yaw_pos,yaw_neg,pitch_pos,pitch_neg}.csv: four paper-like synced
  datasets (docs/formats.md, "The synced CSV"): EGPI truth with the fixed paper-like
  parameters of each motion direction, a Fig-5-like input (ramps out and back with pauses,
  six loading cycles), 30 Hz, Gaussian angle noise 0.1 deg, 1 % of frames unmeasured.
- sample_data/datasets/lab_export.csv (+ lab_export_truth.csv): a lab's own export of a
  two-motor recording (both motors at once through zero, pitch following the yaw joint,
  starting mid-loop, 5 Hz, 250 samples, epoch times, 0.3 deg tracker noise) under its own
  column names, read with configs/columns.lab.toml (docs/formats.md, "A lab's own files").
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


#: The lab export's column names (configs/columns.lab.toml maps them)
LAB_COLUMNS = ("Img TS", "Enc TS", "Encoder counts 0", "Encoder counts 1", "yaws", "pitches")


def write_lab_export() -> None:
    """A two-motor recording as a lab's tracker exports it, and its truth beside it."""
    from i2ris_calib.io.atomic import write_csv
    from i2ris_calib.simulation.two_motor import simulate_two_motor

    r = simulate_two_motor(7, n_samples=250, rate_hz=5.0, noise_deg=0.3, coupling=0.6)
    epoch = 1_732_000_000.0  # the tracker's clock: Unix time (s)
    img, enc_t = epoch + r.t_s, epoch + r.t_s + 0.004  # the encoder read 4 ms after the frame
    counts = [np.round(e).astype(int) for e in (r.enc_yaw, r.enc_pitch)]
    cols = (img, enc_t, *counts, r.yaw_deg, r.pitch_deg)
    frame = pd.DataFrame(dict(zip(LAB_COLUMNS, cols, strict=True)))
    write_csv(OUT / "datasets" / "lab_export.csv", frame, "%.6f")
    truth = pd.DataFrame({"Img TS": img, "yaw_true_deg": r.yaw_true_deg,
                          "pitch_true_deg": r.pitch_true_deg})  # fmt: skip
    write_csv(OUT / "datasets" / "lab_export_truth.csv", truth, "%.6f")


def write_session() -> None:
    from i2ris_calib.commands.simulate import write_simulated_session
    from i2ris_calib.io.config_io import load_config

    cfg = load_config(ROOT / "configs" / "sample_session.toml")
    write_simulated_session(OUT / "session", cfg, force=True)


def write_target() -> None:
    """session/target.csv: a yaw target for compensation (docs/compensate.md): 20 s at
    50 Hz, from rest at 0 deg up to a slow sine between 10 and 20 deg, inside what the
    sample session's yaw+ fit reaches (its loops go to ~37 deg)."""
    t = np.arange(0.0, 20.0, 0.02)
    ramp = np.clip(t / 4.0, 0.0, 1.0)
    yaw = ramp * (15.0 + 5.0 * np.sin(2 * np.pi * t / 8.0))
    pd.DataFrame({"time_s": t, "yaw_deg": yaw}).to_csv(
        OUT / "session" / "target.csv", index=False, float_format="%.6f"
    )


if __name__ == "__main__":
    write_datasets()
    write_lab_export()
    if "--datasets-only" not in sys.argv:
        write_session()
        write_target()
