"""Encoder log readers: CSV, ROS1 and ROS2 bags (written here with rosbags' writers)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from i2ris_calib.errors import CalibError
from i2ris_calib.io.encoders import read_encoder_log
from i2ris_calib.session import EncoderLogSpec


def _log_arrays(rng, n=400, rate_hz=200.0):
    t = 1000.0 + np.arange(n) / rate_hz
    yaw = np.round(3000 * np.sin(np.linspace(0, 3, n))).astype(int)
    pitch = rng.integers(-50, 50, n)
    flash = ((t > 1000.5) & (t < 1000.8)).astype(int)
    return t, yaw, pitch, flash


def _write_csv(folder: Path, t, yaw, pitch, flash=None, name="encoders.csv"):
    df = pd.DataFrame({"time_s": t, "enc_yaw": yaw, "enc_pitch": pitch})
    if flash is not None:
        df["sync_flash"] = flash
    df.to_csv(folder / name, index=False, float_format="%.9f")
    return folder / name


def test_csv_reads_all_channels(tmp_path, rng):
    t, yaw, pitch, flash = _log_arrays(rng)
    _write_csv(tmp_path, t, yaw, pitch, flash)
    log = read_encoder_log(tmp_path, EncoderLogSpec(), max_gap_s=0.1)
    np.testing.assert_allclose(log.channels["enc_yaw"].t_s, t, atol=1e-9)
    np.testing.assert_array_equal(log.channels["enc_yaw"].values, yaw)
    np.testing.assert_array_equal(log.channels["enc_pitch"].values, pitch)
    np.testing.assert_array_equal(log.flash.values, flash)


def test_csv_without_sync_column_has_no_flash(tmp_path, rng):
    t, yaw, pitch, _ = _log_arrays(rng)
    _write_csv(tmp_path, t, yaw, pitch)
    assert read_encoder_log(tmp_path, EncoderLogSpec(), 0.1).flash is None


def test_csv_custom_columns_and_time_unit(tmp_path, rng):
    t, yaw, pitch, _ = _log_arrays(rng)
    df = pd.DataFrame({"stamp_ms": np.round(t * 1000, 3), "m1": yaw, "m2": pitch})
    df.to_csv(tmp_path / "log.csv", index=False)
    spec = EncoderLogSpec(
        file="log.csv", time_column="stamp_ms", time_unit_s=1e-3, yaw_column="m1", pitch_column="m2"
    )
    log = read_encoder_log(tmp_path, spec, 0.1)
    np.testing.assert_allclose(log.channels["enc_pitch"].t_s, t, atol=1e-6)


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        ("missing_file", "not found"),
        ("missing_column", "missing column"),
        ("gap", "gap of"),
        ("reset", "clock reset"),
        ("duplicate", "repeated timestamp"),
        ("nonnumeric", "non-numeric"),
    ],
)
def test_csv_problems_are_one_line_errors(tmp_path, rng, mutate, message):
    t, yaw, pitch, flash = _log_arrays(rng)
    yaw = yaw.astype(object)
    if mutate == "gap":
        t = np.where(t > 1001.0, t + 2.0, t)
    elif mutate == "reset":
        t = np.where(np.arange(t.size) >= 200, t - 1.5, t)
    elif mutate == "duplicate":
        t[150] = t[149]
    elif mutate == "nonnumeric":
        yaw[17] = "oops"
    if mutate != "missing_file":
        path = _write_csv(tmp_path, t, yaw, pitch, flash)
        if mutate == "missing_column":
            pd.read_csv(path).drop(columns=["enc_pitch"]).to_csv(path, index=False)
    with pytest.raises(CalibError, match=message) as exc:
        read_encoder_log(tmp_path, EncoderLogSpec(), max_gap_s=0.5)
    assert "\n" not in str(exc.value)


def test_gap_tolerance_is_configurable(tmp_path, rng):
    t, yaw, pitch, _ = _log_arrays(rng)
    t = np.where(t > 1001.0, t + 0.3, t)
    _write_csv(tmp_path, t, yaw, pitch)
    with pytest.raises(CalibError, match="max_gap_s"):
        read_encoder_log(tmp_path, EncoderLogSpec(), max_gap_s=0.2)
    assert read_encoder_log(tmp_path, EncoderLogSpec(), max_gap_s=0.5).time_range()[1] > 1002


# ---------------------------------------------------------------- ROS bags


def _write_ros1_int32(path: Path, series: dict[str, tuple[np.ndarray, np.ndarray]]):
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    int32 = ts.types["std_msgs/msg/Int32"]
    with Writer(path) as w:
        for topic, (t, v) in series.items():
            conn = w.add_connection(topic, "std_msgs/msg/Int32", typestore=ts)
            for ti, vi in zip(t, v, strict=True):
                msg = ts.serialize_ros1(int32(data=int(vi)), "std_msgs/msg/Int32")
                w.write(conn, int(round(ti * 1e9)), msg)


def _write_ros2_jointstate(path: Path, series: dict[str, tuple[np.ndarray, np.ndarray]], lag_s=0.0):
    """JointState messages whose header stamp is ``lag_s`` (scalar or per message) before the bag time."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    js = ts.types["sensor_msgs/msg/JointState"]
    header = ts.types["std_msgs/msg/Header"]
    stamp = ts.types["builtin_interfaces/msg/Time"]
    empty = np.array([], dtype=float)
    with Writer(path, version=9) as w:
        for topic, (t, v) in series.items():
            conn = w.add_connection(topic, "sensor_msgs/msg/JointState", typestore=ts)
            lags = np.broadcast_to(lag_s, t.shape)
            for ti, vi, lag in zip(t, v, lags, strict=True):
                ns = int(round((ti - lag) * 1e9))
                msg = js(
                    header=header(stamp=stamp(sec=ns // 10**9, nanosec=ns % 10**9), frame_id=""),
                    name=["motor"],
                    position=np.array([float(vi)]),
                    velocity=empty,
                    effort=empty,
                )
                w.write(
                    conn, int(round(ti * 1e9)), ts.serialize_cdr(msg, "sensor_msgs/msg/JointState")
                )


def test_ros1_bag_int32_topics(tmp_path, rng):
    t, yaw, pitch, flash = _log_arrays(rng)
    t_pitch = t[::2] + 0.001  # each motor on its own topic and rate
    _write_ros1_int32(
        tmp_path / "enc.bag",
        {
            "/i2ris/yaw/encoder": (t, yaw),
            "/i2ris/pitch/encoder": (t_pitch, pitch[::2]),
            "/i2ris/sync": (t, flash),
        },
    )
    spec = EncoderLogSpec(file="enc.bag", format="rosbag", sync_topic="/i2ris/sync")
    log = read_encoder_log(tmp_path, spec, 0.1)
    np.testing.assert_allclose(log.channels["enc_yaw"].t_s, t, atol=1e-9)
    np.testing.assert_array_equal(log.channels["enc_yaw"].values, yaw)
    np.testing.assert_allclose(log.channels["enc_pitch"].t_s, t_pitch, atol=1e-9)
    np.testing.assert_array_equal(log.flash.values, flash)
    # interpolation at a time between samples of the sparser channel
    mid = 0.5 * (t_pitch[10] + t_pitch[11])
    assert log.interpolate("enc_pitch", np.array([mid]))[0] == pytest.approx(
        0.5 * (pitch[20] + pitch[22])
    )


def test_ros2_bag_jointstate_header_time(tmp_path, rng):
    t, yaw, pitch, _ = _log_arrays(rng)
    _write_ros2_jointstate(
        tmp_path / "enc_ros2", {"/yaw": (t, yaw), "/pitch": (t, pitch)}, lag_s=0.004
    )
    spec = EncoderLogSpec(
        file="enc_ros2",
        format="rosbag",
        yaw_topic="/yaw",
        pitch_topic="/pitch",
        value_field="position",
        time_source="header",
    )
    log = read_encoder_log(tmp_path, spec, 0.1)
    np.testing.assert_allclose(log.channels["enc_yaw"].t_s, t - 0.004, atol=1e-8)
    np.testing.assert_array_equal(log.channels["enc_pitch"].values, pitch)
    log_time = read_encoder_log(tmp_path, replace(spec, time_source="log"), 0.1)
    np.testing.assert_allclose(log_time.channels["enc_yaw"].t_s, t, atol=1e-8)


def test_bag_without_configured_topic(tmp_path, rng):
    t, yaw, pitch, _ = _log_arrays(rng)
    _write_ros1_int32(tmp_path / "enc.bag", {"/i2ris/yaw/encoder": (t, yaw), "/other": (t, pitch)})
    spec = EncoderLogSpec(file="enc.bag", format="rosbag")
    with pytest.raises(CalibError, match="no topic '/i2ris/pitch/encoder'.*/other"):
        read_encoder_log(tmp_path, spec, 0.1)


def test_bag_without_configured_field(tmp_path, rng):
    t, yaw, pitch, _ = _log_arrays(rng)
    _write_ros1_int32(
        tmp_path / "enc.bag", {"/i2ris/yaw/encoder": (t, yaw), "/i2ris/pitch/encoder": (t, pitch)}
    )
    spec = EncoderLogSpec(file="enc.bag", format="rosbag", value_field="position")
    with pytest.raises(CalibError, match="no field 'position'"):
        read_encoder_log(tmp_path, spec, 0.1)


def test_bag_clock_reset_in_header_stamps(tmp_path, rng):
    t, yaw, pitch, _ = _log_arrays(rng)
    # receive times stay monotonic (the bag orders by them); header stamps jump back 0.5 s
    reset = np.where(np.arange(t.size) > 300, 0.5, 0.0)
    _write_ros2_jointstate(tmp_path / "b", {"/yaw": (t, yaw), "/pitch": (t, pitch)}, lag_s=reset)
    spec = EncoderLogSpec(
        file="b", format="rosbag", yaw_topic="/yaw", pitch_topic="/pitch", value_field="position"
    )
    assert read_encoder_log(tmp_path, spec, 0.1).time_range()[0] == pytest.approx(t[0])
    with pytest.raises(CalibError, match="clock reset in 'enc_yaw'"):
        read_encoder_log(tmp_path, replace(spec, time_source="header"), 0.1)
