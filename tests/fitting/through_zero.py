"""Synced tables of recordings through zero for the fitting tests (a helper module)."""

from __future__ import annotations

import numpy as np
import pandas as pd


def yaw_recording(rng, t, v, y, noise_deg):
    """A synced table of a yaw-only recording: ``v`` counts -> ``y`` deg (the truth over
    the whole history, already cut to the recorded stretch) plus ``noise_deg`` noise;
    the pitch motor still, its angle noise only."""
    return pd.DataFrame(
        {
            "time_s": t,
            "enc_yaw": v,
            "enc_pitch": 0.0,
            "yaw_deg": y + rng.normal(0, noise_deg, v.size),
            "pitch_deg": rng.normal(0, 0.05, v.size),
            "status": "measured",
            "frame": np.arange(v.size),
        }
    )
