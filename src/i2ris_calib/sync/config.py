"""Configuration of the sync stage (TOML section ``[sync]``, see docs/sync.md)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from i2ris_calib._validate import validated_config
from i2ris_calib.hysteresis.kinds import PAPER_KINDS, PAPER_MODEL


@dataclass(frozen=True)
class SyncConfig:
    """Settings of the sync stage. Units are in the field names.

    Clock convention (docs/sync.md): ``t_ctrl = offset_s + (1 + drift_ppm*1e-6) * t_cam``.
    """

    # "auto": event when the encoder log has a sync_flash edge and the video shows it,
    # else "model". "xcorr" exists for comparison only (biased by hysteresis).
    method: Literal["auto", "event", "model", "xcorr"] = "auto"

    # --- encoder log validation
    max_gap_s: float = 0.25  # longest allowed interval between two encoder samples
    min_overlap_frames: int = 10  # fewer mapped frames inside the log range is an error

    # encoder values between log samples: "corners" = linear, with the corners of
    # piecewise-linear motion (a reversal or stop between two samples) restored;
    # "linear" = plain linear interpolation (cuts those corners)
    encoder_interpolation: Literal["corners", "linear"] = "corners"

    # --- sync event (LED flash seen as a jump of the mean grey level)
    flash_cameras: tuple[str, ...] = ()  # cameras whose mean_gray_<camera> to use; () = all
    flash_min_contrast_gray: float = 8.0  # min jump of mean grey level (0-255) for a flash
    # exposure time; 0 = unknown: marginalised over 3-100 % of the frame interval, weighted
    # by how well each explains the flash frames (a wrong value biases the edge times)
    exposure_s: float = 0.0
    frame_time_ref: Literal["start", "middle", "end"] = "middle"  # where in the exposure time_s is
    # edge time in the log: "midpoint" = the LED switched somewhere between the last off and the
    # first on sample (state sampled by the logger); "first_on" = at the first on sample
    log_edge_at: Literal["first_on", "midpoint"] = "midpoint"
    # likelihood of a logged edge given the frames: "integral" = probability that the edge
    # lies in its log interval (interval-censored, uniform within the tick), "profile" = its
    # best misfit inside the interval
    event_likelihood: Literal["integral", "profile"] = "profile"
    # event point estimate: "midrange" = smallest worst-case clock error over the recording
    # (mid-ranges of the posterior at its first and last frame), "mean" = posterior mean
    event_estimate: Literal["midrange", "mean"] = "mean"
    use_falling_edges: bool = True  # use LED-off edges as well as LED-on edges
    max_edge_residual_s: float = 0.02  # a camera edge farther than this from its log edge: no match
    min_drift_span_s: float = 5.0  # fit drift only if the matched edges span this long
    # auto: an event clock coarser than this (offset sd, s) is combined with the model profile
    # searched within the event's +-4 sd (product of likelihoods; the event alone when they
    # disagree; 0 = never)
    auto_refine_stderr_s: float = 0.0002

    # --- offset search (model and xcorr)
    offset_guess_s: float = 0.0  # prior offset (ctrl - cam); used when offset_search_s > 0
    offset_search_s: float = 0.0  # search +- this around offset_guess_s; 0 = whole overlap
    xcorr_rate_hz: float = 200.0  # resampling rate of the derivative cross-correlation
    xcorr_smooth_s: float = 0.2  # Savitzky-Golay window of the derivatives
    drift_windows: int = 3  # windows for the drift estimate of xcorr/model (1 = no drift)
    estimate_drift: bool = True  # False: drift fixed at 0 ppm for model/xcorr

    # --- joint offset + hysteresis model profile
    model: str = PAPER_MODEL  # one of the paper's two models (PAPER_KINDS)
    profile_halfwidth_s: float = (
        0.12  # coarse profile +- around the xcorr offset (extended if needed)
    )
    profile_step_s: float = 0.01  # coarse grid step
    profile_tol_s: float = 0.00005  # golden-section refinement tolerance
    min_axis_range_counts: float = 50.0  # an axis whose encoder spans less is not used

    seed: int = 0  # reserved for randomised starts of the model fits

    def __post_init__(self) -> None:
        """Validated on construction, not only when loaded from TOML: field types, then
        :meth:`validate`; a CalibError either way."""
        validated_config(self)

    def validate(self) -> None:
        """Raise ValueError on inconsistent settings."""
        positive = {
            "max_gap_s": self.max_gap_s,
            "xcorr_rate_hz": self.xcorr_rate_hz,
            "xcorr_smooth_s": self.xcorr_smooth_s,
            "profile_halfwidth_s": self.profile_halfwidth_s,
            "profile_step_s": self.profile_step_s,
            "profile_tol_s": self.profile_tol_s,
            "max_edge_residual_s": self.max_edge_residual_s,
        }
        for name, value in positive.items():
            if not value > 0:
                raise ValueError(f"{name} must be > 0, got {value}")
        if self.exposure_s < 0:
            raise ValueError(f"exposure_s must be >= 0 (0 = unknown), got {self.exposure_s}")
        if self.offset_search_s < 0:
            raise ValueError(f"offset_search_s must be >= 0, got {self.offset_search_s}")
        if self.profile_step_s > self.profile_halfwidth_s:
            raise ValueError("profile_step_s must not exceed profile_halfwidth_s")
        if self.model not in PAPER_KINDS:
            raise ValueError(f"model '{self.model}' is not one of {', '.join(PAPER_KINDS)}")
        if self.drift_windows < 1:
            raise ValueError(f"drift_windows must be >= 1, got {self.drift_windows}")
        if self.min_overlap_frames < 1:
            raise ValueError(f"min_overlap_frames must be >= 1, got {self.min_overlap_frames}")
        if self.flash_min_contrast_gray <= 0:
            raise ValueError("flash_min_contrast_gray must be > 0")
