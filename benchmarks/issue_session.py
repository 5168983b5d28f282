"""The session of the tracking/sync issue, rendered by this project's simulator.

60 s, 1280x1024 mp4, two pinhole microscopes (f = 20000 px, each tilted by 3 deg about
a random axis), the side camera's frames 5 ms after the top one's, 25 ms exposure, a
500 Hz encoder log sampling the LED state, three flashes of different lengths (0.2,
0.25, 0.3 s), clock offset 7.3 s and drift 45 ppm, yaw and pitch excursions to ~40 deg
in both directions with holds, minor loops and compound moves (preset ``exact``:
exact whole-history EGPI truth), 200 px markers, noise sigma 2.

Used by ``bench_tracking.py --issue-session DIR`` (tracking figures) and
``bench_sync.py --issue-session DIR`` (event / auto / model sync figures); both render
the session into DIR when it is not there yet and reuse it otherwise.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pandas as pd

from i2ris_calib.commands.simulate import build_session
from i2ris_calib.simulation.config import SimulationConfig
from i2ris_calib.simulation.presets import preset_config

#: ``[simulate]`` overrides of preset ``exact`` that make the issue's session
ISSUE_SESSION = dict(
    width_px=1280,
    height_px=1024,
    marker_size_px=200.0,
    focal_px=20000.0,
    misalignment_deg=3.0,
    exposure_s=0.025,
    encoder_rate_hz=500.0,
    second_camera_phase_s=0.005,
    offset_s=7.3,
    drift_ppm=45.0,
    n_flashes=3,
    excursions=2,
    ramp_s=2.5,
    video_format="mp4",
)


def issue_config(seed: int = 0, **overrides) -> SimulationConfig:
    """The validated simulation settings of the issue's session."""
    return preset_config("exact", seed=seed, **{**ISSUE_SESSION, **overrides})


def ensure_session(folder: Path, seed: int = 0, **overrides) -> Path:
    """Render the issue's session into ``folder`` unless a session is already there."""
    folder = Path(folder)
    if not (folder / "session.toml").is_file():
        folder.mkdir(parents=True, exist_ok=True)
        t0 = time.perf_counter()
        build_session(folder, issue_config(seed, **overrides), name=folder.name)
        print(f"rendered {folder} in {time.perf_counter() - t0:.0f} s", flush=True)
    return folder


def truth_steps(truth_deg: np.ndarray, jump_deg: float = 0.5) -> np.ndarray:
    """Frames next to a step of the true angle (bool, shape (n,)).

    The exact EGPI truth steps by ``y2 - y1`` at the flag point, inside one frame
    interval. The side camera's frames (5 ms later) are interpolated to the top
    camera's times, and no interpolation can place a step between two frames: the
    frames around it get part of the step as error. A frame k is at a step when its
    change ``theta_k - theta_(k-1)`` differs by more than ``jump_deg`` from the median
    change of the three intervals each side; k-1, k and k+1 are marked.
    """
    d = np.diff(truth_deg, prepend=truth_deg[0])
    out = np.zeros(d.size, dtype=bool)
    for k in range(d.size):
        nb = np.r_[d[max(k - 3, 0) : k], d[k + 1 : k + 4]]
        if nb.size and abs(d[k] - np.median(nb)) > jump_deg:
            out[max(k - 1, 0) : k + 2] = True
    return out


def tracking_figures(
    session: Path, angles: pd.DataFrame, beyond_deg: float = 15.0, skip_steps: bool = False
) -> dict:
    """The issue's tracking figures of ``angles`` against ``session/truth``.

    Per axis: RMS overall, RMS while the other axis is beyond ``beyond_deg`` (true angle),
    RMS otherwise, the bias while beyond, max |error| and frames off by > 1 deg; frames
    measured of those with both markers visible. ``skip_steps``: the error figures
    leave out the frames next to a step of either true angle (:func:`truth_steps`).
    """
    truth = pd.read_csv(session / "truth" / "truth_frames.csv")
    m = angles.merge(truth, on="frame", suffixes=("", "_true"))
    ok = (m["status"] == "measured").to_numpy()
    vis = ((m["visible_top"] == 1) & (m["visible_side"] == 1)).to_numpy()
    steps = truth_steps(m["yaw_deg_true"].to_numpy(float)) | truth_steps(
        m["pitch_deg_true"].to_numpy(float)
    )
    out: dict = {
        "frames": int(len(m)),
        "visible": int(vis.sum()),
        "measured_visible": int((ok & vis).sum()),
        "step_frames": int(steps.sum()),
    }
    if skip_steps:
        ok = ok & ~steps
    for axis, other in (("yaw", "pitch"), ("pitch", "yaw")):
        e = (m[f"{axis}_deg"] - m[f"{axis}_deg_true"]).to_numpy(float)[ok]
        big = np.abs(m[f"{other}_deg_true"].to_numpy(float)[ok]) > beyond_deg
        out[axis] = {
            "rms": float(np.sqrt(np.mean(e**2))),
            "rms_beyond": float(np.sqrt(np.mean(e[big] ** 2))) if big.any() else float("nan"),
            "rms_otherwise": float(np.sqrt(np.mean(e[~big] ** 2))),
            "bias_beyond": float(np.mean(e[big])) if big.any() else float("nan"),
            "n_beyond": int(big.sum()),
            "max": float(np.max(np.abs(e))),
            "over_1deg": int(np.sum(np.abs(e) > 1.0)),
        }
    return out
