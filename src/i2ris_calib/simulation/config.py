"""Configuration of the simulation stage (TOML section ``[simulate]``, see docs/simulation.md)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

from i2ris_calib._validate import validated_config

DATASETS = ("yaw+", "yaw-", "pitch+", "pitch-")


@dataclass(frozen=True)
class SimulationConfig:
    """Settings of ``i2ris-calib simulate``. Units are in the field names.

    Grouped as: video/optics, scene, image degradations, motion (Fig-5-like input),
    clocks and events, hidden effects. Every field is documented in docs/simulation.md.
    """

    seed: int = 0
    # --- video and optics -------------------------------------------------------
    width_px: int = 1280
    height_px: int = 1024
    fps: float = 30.0
    video_format: Literal["mkv", "mp4"] = "mkv"  # mkv = lossless FFV1, mp4 = lossy mp4v
    focal_px: float = 50000.0  # pinhole focal length; long = near-orthographic microscope
    marker_size_px: float = 200.0  # marker edge in pixels at the straight pose
    misalignment_deg: float = 3.0  # each camera's axis tilted by this, about a random axis
    write_calibration: bool = True  # write <camera>.yaml with the true intrinsics
    # --- scene ------------------------------------------------------------------
    dictionary: str = "DICT_4X4_50"
    marker_ids: tuple[int, int] = (0, 1)  # (top, side)
    marker_size_mm: float = 0.8
    cube_size_mm: float = 1.0
    pivot_mm: float = 1.5  # cube centre is this far distal of the bending pivot
    background_gray: float = 70.0
    face_gray: float = 215.0
    ink_gray: float = 30.0
    # --- image degradations -----------------------------------------------------
    blur_sigma_px: float = 1.2  # defocus (Gaussian) at the focal plane
    depth_blur_px_per_mm: float = 1.0  # extra blur per mm out of the focal plane
    noise_sigma: float = 2.0  # sensor noise, grey levels (0-255)
    illumination_falloff: float = 0.25  # relative brightness loss at the image corners
    illumination_gradient: float = 0.10  # left-right brightness ramp (fraction)
    motion_blur_samples: int = 1  # sub-frame renders averaged per frame (1 = off)
    exposure_s: float = 0.03  # exposure time, centred on the frame time (motion blur, flash edges)
    # --- motion: Fig-5-like encoder input per dataset ---------------------------
    datasets: tuple[str, ...] = DATASETS
    amplitude_counts: tuple[float, float] = (6000.0, 6000.0)  # (yaw, pitch) peak |input|
    cycles: int = 2  # ramp out and back this many times per dataset
    cycle_fractions: tuple[float, ...] = (0.6, 1.0)  # peak of each cycle / amplitude
    ramp_s: float = 5.0  # duration of one full ramp 0 -> amplitude
    pause_s: float = 1.0  # pause at each peak and after each return
    rest_s: float = 1.5  # rest at zero at the start of each dataset
    settle_s: float = 1.0  # end-of-dataset residual angle relaxed to 0 over this time
    encoder_rate_hz: float = 1000.0
    models: dict = field(default_factory=dict)  # per-dataset parameter overrides
    # --- motion: alternative random excursions (motion = "excursions") -----------
    motion: Literal["fig5", "excursions"] = "fig5"  # fig5 = the datasets one after another
    excursions: int = 4  # excursions per axis and direction (of `datasets`); >= 2
    excursion_fractions: tuple[float, float] = (0.4, 1.0)  # peak range / amplitude
    speed_factors: tuple[float, float] = (0.5, 1.6)  # ramp speed / (amplitude / ramp_s)
    hold_s: tuple[float, float] = (0.3, 1.5)  # hold at zero between excursions (range)
    compound_fraction: float = 0.3  # chance an excursion runs together with the next one
    minor_loop_fraction: float = 0.25  # chance an excursion turns back up on its way down
    # --- protocol: "paper" (the motions above) or "lab" (simulation/lab.py) -------
    protocol: Literal["paper", "lab"] = "paper"
    lab_duration_s: float = 30.0  # lab: seconds of video (the driving began lab_burn_in_s before)
    lab_burn_in_s: float = 20.0  # lab: driving before the first frame (a mid-loop start)
    lab_period_s: tuple[float, float] = (4.0, 12.0)  # lab: range of a loop's period (s)
    lab_hold_fraction: float = 0.15  # lab: chance that a segment is a hold (0.5-2 s)
    lab_offset_deg: tuple[float, float] = (-9.0, 4.0)  # lab: (yaw, pitch) angle at zero input
    lab_coupling: float = 0.6  # lab: pitch's gain on the yaw motor / its own gain
    lab_reference_s: float = 2.0  # lab: video time the tip is driven straight (reference)
    lab_reference_hold_s: float = 1.5  # lab: how long it is held straight there
    # --- truth ------------------------------------------------------------------
    # blocks = per dataset block, faded in/out (the Fig-5 sample); whole_history = the data
    # layer's assumption exactly: per axis and direction one EGPI over the whole history
    truth: Literal["blocks", "whole_history"] = "blocks"
    zero_start: bool = True  # whole_history: shift a4, a6 so the model starts at 0 deg
    # --- clocks and events ------------------------------------------------------
    offset_s: float = 12.5  # t_ctrl = offset_s + (1 + drift_ppm 1e-6) t_cam
    drift_ppm: float = 80.0
    camera_start_s: float = 0.0  # camera-clock time of the first frame
    second_camera_phase_s: float = 0.0  # side-camera frame times lag the top camera by this
    timestamp_jitter_s: float = 0.0  # Gaussian jitter of frame times (s)
    sync_flash: bool = True
    flash_times_s: tuple[float, ...] = ()  # camera clock; () = n_flashes spread over the video
    n_flashes: int = 4  # used when flash_times_s is empty
    flash_duration_s: float = 0.2
    flash_gain: float = 0.15  # relative brightness increase while the LED is on (face stays < 255)
    drop_fraction: float = 0.0  # fraction of frames missing from each video
    occlusions: int = 0  # number of occlusion events per camera
    occlusion_s: float = 0.4  # duration of one occlusion event
    # --- hidden effects (applied by i2ris_calib.hysteresis.effects) ----------------
    effects: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        """Validated on construction, not only when loaded from TOML: field types, then
        :meth:`validate`; a CalibError either way."""
        validated_config(self)

    def validate(self) -> None:
        """Raise ValueError on inconsistent settings."""
        self._validate_numbers()
        if self.width_px < 64 or self.height_px < 64:
            raise ValueError("width_px and height_px must be >= 64")
        if self.fps <= 0 or self.encoder_rate_hz <= 0:
            raise ValueError("fps and encoder_rate_hz must be > 0")
        if self.focal_px <= 0 or self.marker_size_px < 12:
            raise ValueError("focal_px must be > 0 and marker_size_px >= 12")
        if not 0 < self.marker_size_mm < self.cube_size_mm:
            raise ValueError("marker_size_mm must be > 0 and smaller than cube_size_mm")
        bad = [d for d in self.datasets if d not in DATASETS]
        if bad or not self.datasets:
            raise ValueError(f"datasets must be taken from {', '.join(DATASETS)}; got {bad}")
        if self.cycles < 1 or len(self.cycle_fractions) < 1:
            raise ValueError("cycles must be >= 1 and cycle_fractions non-empty")
        if min(self.ramp_s, self.pause_s, self.rest_s, self.settle_s) < 0 or self.ramp_s == 0:
            raise ValueError("ramp_s must be > 0; pause_s, rest_s, settle_s >= 0")
        if not 0 < self.exposure_s <= 1.0 / self.fps:
            raise ValueError("exposure_s must be > 0 and at most the frame interval 1/fps")
        if self.n_flashes < 1:
            raise ValueError("n_flashes must be >= 1 (set sync_flash = false for none)")
        if not 0 <= self.drop_fraction < 0.5:
            raise ValueError("drop_fraction must be in [0, 0.5)")
        if self.noise_sigma < 0 or self.blur_sigma_px < 0 or self.motion_blur_samples < 1:
            raise ValueError("noise_sigma, blur_sigma_px >= 0 and motion_blur_samples >= 1")
        if len(set(self.marker_ids)) != 2:
            raise ValueError("marker_ids must be two different ids")
        if self.motion not in ("fig5", "excursions"):
            raise ValueError(f"motion must be 'fig5' or 'excursions', got {self.motion!r}")
        if self.truth not in ("blocks", "whole_history"):
            raise ValueError(f"truth must be 'blocks' or 'whole_history', got {self.truth!r}")
        if self.excursions < 2:
            raise ValueError("excursions must be >= 2 (two full-scale excursions per direction)")
        lo, hi = self.excursion_fractions
        s_lo, s_hi = self.speed_factors
        h_lo, h_hi = self.hold_s
        if not (0 < lo <= hi <= 1 and 0 < s_lo <= s_hi and 0 <= h_lo <= h_hi):
            raise ValueError(
                "need 0 < excursion_fractions[0] <= [1] <= 1, 0 < speed_factors[0] <= [1], "
                "0 <= hold_s[0] <= [1]"
            )
        if not (0 <= self.compound_fraction <= 1 and 0 <= self.minor_loop_fraction <= 1):
            raise ValueError("compound_fraction and minor_loop_fraction must be in [0, 1]")
        if self.protocol not in ("paper", "lab"):
            raise ValueError(f"protocol must be 'paper' or 'lab', got {self.protocol!r}")
        if self.protocol == "lab":
            self._validate_lab()
        if not -0.99 < self.illumination_falloff < 0.99:
            raise ValueError("illumination_falloff must be in (-0.99, 0.99)")

    def _validate_lab(self) -> None:
        """The lab protocol's settings (docs/simulation.md, "Lab protocol")."""
        p_lo, p_hi = self.lab_period_s
        if not (math.isfinite(p_hi) and 1.0 <= p_lo <= p_hi):
            raise ValueError("lab_period_s must be two finite periods with 1 <= [0] <= [1]")
        if not 0 <= self.lab_hold_fraction < 1:
            raise ValueError("lab_hold_fraction must be in [0, 1)")
        if not all(math.isfinite(o) and abs(o) <= 20 for o in self.lab_offset_deg):
            raise ValueError("lab_offset_deg must be two angles within +-20 deg")
        if not (math.isfinite(self.lab_coupling) and 0 <= self.lab_coupling <= 1.5):
            raise ValueError("lab_coupling must be in [0, 1.5] (a fraction of pitch's own gain)")
        if not (math.isfinite(self.lab_burn_in_s) and 0 <= self.lab_burn_in_s <= 600):
            raise ValueError("lab_burn_in_s must be in [0, 600] s")
        if not (math.isfinite(self.lab_duration_s) and 8 <= self.lab_duration_s <= 3600):
            raise ValueError("lab_duration_s must be in [8, 3600] s")
        ref_end = self.lab_reference_s + 0.6 + self.lab_reference_hold_s
        if not (0 <= self.lab_reference_s and 1.0 <= self.lab_reference_hold_s
                and ref_end <= self.lab_duration_s - 1.0):  # fmt: skip
            raise ValueError(
                "lab_reference_s >= 0 and lab_reference_hold_s >= 1 s, ending (after a 0.6 s "
                "ramp) at least 1 s before the end of lab_duration_s"
            )

    def _validate_numbers(self) -> None:
        """Finite, in-range numbers (NaN/inf and negative sizes or times are refused)."""
        positive = ("fps", "focal_px", "marker_size_px", "marker_size_mm", "cube_size_mm",
                    "exposure_s", "ramp_s", "encoder_rate_hz", "flash_duration_s",
                    "occlusion_s")  # fmt: skip
        non_negative = ("misalignment_deg", "pivot_mm", "blur_sigma_px", "depth_blur_px_per_mm",
                        "noise_sigma", "pause_s", "rest_s", "settle_s", "timestamp_jitter_s",
                        "flash_gain", "occlusions", "n_flashes", "drop_fraction")  # fmt: skip
        for name in positive + non_negative:
            v = getattr(self, name)
            if not math.isfinite(v) or v < 0 or (v == 0 and name in positive):
                need = "> 0" if name in positive else ">= 0"
                raise ValueError(f"{name} = {v} must be a finite number {need}")
        for name in ("background_gray", "face_gray", "ink_gray"):
            v = getattr(self, name)
            if not (math.isfinite(v) and 0 <= v <= 255):
                raise ValueError(f"{name} = {v} must be a grey level in [0, 255]")
        for name in (
            "offset_s",
            "drift_ppm",
            "illumination_gradient",
            "camera_start_s",
            "second_camera_phase_s",
        ):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"{name} must be a finite number")
        if not (self.misalignment_deg < 30):
            raise ValueError("misalignment_deg must be < 30 (each camera must still see its face)")
        if min(self.marker_ids) < 0:
            raise ValueError("marker_ids must be >= 0 (ArUco ids)")
        if any(not (math.isfinite(a) and a > 0) for a in self.amplitude_counts):
            raise ValueError("amplitude_counts must be finite numbers > 0")
        if any(not (math.isfinite(f) and 0 < f <= 1) for f in self.cycle_fractions):
            raise ValueError("cycle_fractions must be in (0, 1]")
        if any(not math.isfinite(t) for t in self.flash_times_s):
            raise ValueError("flash_times_s must be finite numbers")
