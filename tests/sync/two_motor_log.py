"""A two-motor recording (simulation.two_motor) as sync's inputs: the per-axis frame
series on the camera clock and the encoder log on a controller clock ``offset_s`` later."""

from __future__ import annotations

from i2ris_calib.sync.log import make_encoder_log
from i2ris_calib.sync.xcorr import AxisSeries


def series_and_log(rec, offset_s: float = 3.0):
    """``([yaw series, pitch series], EncoderLog)`` of ``rec`` (a TwoMotorRecording), the
    log's times ``offset_s`` after the camera's."""
    t = rec.t_s
    log = make_encoder_log(
        {"enc_yaw": (t + offset_s, rec.enc_yaw), "enc_pitch": (t + offset_s, rec.enc_pitch)},
        None, "two-motor", max_gap_s=1.0,
    )  # fmt: skip
    series = [AxisSeries("yaw", "enc_yaw", t, rec.yaw_deg),
              AxisSeries("pitch", "enc_pitch", t, rec.pitch_deg)]  # fmt: skip
    return series, log
