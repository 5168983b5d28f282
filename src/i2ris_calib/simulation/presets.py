"""Named simulation settings used by tests, benchmarks and the sample data.

Each preset is a mapping of ``[simulate]`` keys (docs/simulation.md), turned into a
:class:`SimulationConfig` by :func:`preset_config`; the same keys work in a TOML file.
"""

from __future__ import annotations

from dataclasses import replace

from i2ris_calib.simulation.config import SimulationConfig

PRESETS: dict[str, dict] = {
    # CI: tiny frames, two datasets, ~10 s; renders and tracks in seconds. The sample and
    # CI sessions take the exact whole-history truth (what the fit assumes).
    "ci": dict(width_px=320, height_px=256, marker_size_px=80.0, focal_px=20000.0,
               datasets=("yaw+", "pitch-"), cycles=1, cycle_fractions=(1.0,), ramp_s=1.2,
               pause_s=0.3, rest_s=1.0, settle_s=0.4, blur_sigma_px=1.0, noise_sigma=2.0,
               amplitude_counts=(4500.0, 4500.0), pivot_mm=0.8, truth="whole_history"),
    # sample_data/: 640x512, all four datasets, ~45 s, lossy mp4 (a few MB).
    "sample": dict(width_px=640, height_px=512, marker_size_px=110.0, video_format="mp4",
                   cycles=2, cycle_fractions=(0.6, 1.0), ramp_s=2.5, pause_s=0.6, rest_s=1.5,
                   settle_s=0.6, truth="whole_history"),
    # The tracking benchmark: 2 minutes, 1280x1024, 200 px markers, sigma 2, 3 deg.
    "benchmark": dict(width_px=1280, height_px=1024, marker_size_px=200.0, noise_sigma=2.0,
                      blur_sigma_px=1.2, misalignment_deg=3.0, focal_px=50000.0, ramp_s=7.0,
                      cycles=2, cycle_fractions=(0.6, 1.0), pause_s=1.0, rest_s=1.5,
                      settle_s=1.0, occlusions=3, occlusion_s=0.4),
    # Exact EGPI truth (the data layer's assumption, docs/simulation.md): random
    # excursions of all four directions with holds at zero, varied speeds, minor loops
    # and compound moves; 640x512 mp4, ~105 s. The model-stage benchmark's session.
    "exact": dict(width_px=640, height_px=512, marker_size_px=110.0, video_format="mp4",
                  motion="excursions", truth="whole_history", excursions=4, ramp_s=2.5,
                  pause_s=0.5, rest_s=1.5, settle_s=1.0),
    # The same at CI size (320x256), three excursions per direction, faster ramps (~50 s).
    "exact_ci": dict(width_px=320, height_px=256, marker_size_px=80.0, focal_px=20000.0,
                     blur_sigma_px=1.0, amplitude_counts=(4500.0, 4500.0), pivot_mm=0.8,
                     motion="excursions", truth="whole_history", excursions=3, ramp_s=1.5,
                     pause_s=0.4, rest_s=1.5, settle_s=0.6, hold_s=(0.3, 1.0)),
    # Robots as labs drive them (protocol = "lab", simulation/lab.py): both motors at once
    # in circles and figure-eights through zero with holds, two-tendon truth with offsets
    # at zero input, pitch coupled to the yaw joint, the recording starting mid-loop, the
    # encoder logged at the video's 30 Hz; 640x512 mp4, 50 s. [track] reference window:
    # simulation.lab.reference_window (2.8 s, 1.1 s).
    "lab": dict(protocol="lab", width_px=640, height_px=512, marker_size_px=110.0,
                video_format="mp4", lab_duration_s=50.0, encoder_rate_hz=30.0),
    # The same at CI size (320x256, 30 s, smaller range so the marker stays in view).
    "lab_ci": dict(protocol="lab", width_px=320, height_px=256, marker_size_px=80.0,
                   focal_px=20000.0, blur_sigma_px=1.0, amplitude_counts=(4000.0, 4000.0),
                   pivot_mm=0.8, lab_duration_s=30.0, encoder_rate_hz=30.0),
}  # fmt: skip


def preset_config(name: str, **overrides) -> SimulationConfig:
    """The validated SimulationConfig of preset ``name`` with ``overrides`` applied."""
    if name not in PRESETS:
        raise KeyError(f"unknown preset '{name}' (one of {', '.join(PRESETS)})")
    cfg = replace(SimulationConfig(), **{**PRESETS[name], **overrides})
    cfg.validate()
    return cfg
