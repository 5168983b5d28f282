"""Read the motor encoder log: CSV, ROS1 ``.bag`` or ROS2 bag (via ``rosbags``).

Formats and the ``[encoder]`` table of ``session.toml`` are documented in
``docs/sync.md``. Every problem the user can fix (missing file, missing column or
topic, gaps, a clock reset) is a one-line :class:`~i2ris_calib.errors.CalibError`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from rosbags.highlevel import AnyReader, AnyReaderError

from i2ris_calib.errors import CalibError
from i2ris_calib.session import EncoderLogSpec
from i2ris_calib.sync.log import EncoderLog, make_encoder_log, time_unit_hint


def encoder_log_path(session_dir: str | Path, spec: EncoderLogSpec) -> Path:
    """Absolute path of the encoder log named in session.toml; CalibError if missing."""
    p = Path(session_dir) / spec.file
    if not spec.file or not p.exists():
        raise CalibError(
            f"encoder log '{spec.file}' not found in {session_dir} "
            "(add it, or fix [encoder] file in session.toml; see docs/sync.md)"
        )
    return p


def read_encoder_log(session_dir: str | Path, spec: EncoderLogSpec, max_gap_s: float) -> EncoderLog:
    """Read and validate the session's encoder log.

    Parameters
    ----------
    session_dir : path
        Session folder; ``spec.file`` is relative to it.
    spec : EncoderLogSpec
        Format and column/topic names (``[encoder]`` in session.toml).
    max_gap_s : float
        Longest allowed interval between encoder samples, s (``sync.max_gap_s``).

    Returns
    -------
    EncoderLog
        Channels ``enc_yaw`` and ``enc_pitch`` (counts) on the controller clock (s),
        plus ``sync_flash`` when logged.
    """
    path = encoder_log_path(session_dir, spec)
    if spec.format == "csv":
        return read_encoder_csv(path, spec, max_gap_s)
    return read_encoder_bag(path, spec, max_gap_s)


def read_encoder_csv(path: Path, spec: EncoderLogSpec, max_gap_s: float) -> EncoderLog:
    """Encoder log from a CSV file (one row per sample, shared time column)."""
    try:
        df = pd.read_csv(path)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise CalibError(f"{path}: not a readable CSV file ({exc})") from None
    need = [spec.time_column, spec.yaw_column, spec.pitch_column]
    missing = [c for c in need if c not in df.columns]
    if missing:
        raise CalibError(
            f"{path}: missing column(s) {', '.join(missing)} (found: {', '.join(map(str, df.columns))}; "
            "rename them or set the [encoder] *_column names in session.toml)"
        )
    cols = need + ([spec.sync_column] if spec.sync_column in df.columns else [])
    values = {}
    for c in cols:
        v = pd.to_numeric(df[c], errors="coerce").to_numpy(dtype=float)
        if np.isnan(v).any():
            row = int(np.flatnonzero(np.isnan(v))[0])
            raise CalibError(
                f"{path}: column '{c}' has an empty or non-numeric value at data row {row + 1} "
                "(fix or remove that row)"
            )
        values[c] = v
    t = values[spec.time_column] * spec.time_unit_s
    unit = time_unit_hint(t)
    if unit is not None:
        step = float(np.median(np.diff(t)))
        name = {1e-3: "ms", 1e-6: "us", 1e-9: "ns"}[unit]
        raise CalibError(
            f"{path}: '{spec.time_column}' steps by {step:g} s per sample (median, with "
            f"[encoder] time_unit_s = {spec.time_unit_s:g}), slower than any encoder log: the "
            f"times look like {name}; set [encoder] time_unit_s = {spec.time_unit_s * unit:g} "
            "in session.toml"
        )
    channels = {
        "enc_yaw": (t, values[spec.yaw_column]),
        "enc_pitch": (t, values[spec.pitch_column]),
    }
    flash = (t, values[spec.sync_column]) if spec.sync_column in values else None
    return make_encoder_log(channels, flash, str(path), max_gap_s, spec.max_counts_per_s)


def read_encoder_bag(path: Path, spec: EncoderLogSpec, max_gap_s: float) -> EncoderLog:
    """Encoder log from a ROS1 ``.bag`` or a ROS2 bag (folder, ``.mcap`` or ``.db3``).

    One topic per motor (``yaw_topic``, ``pitch_topic``), optional ``sync_topic``.
    The count is ``msg.<value_field>`` (element ``value_index`` if it is an array,
    e.g. ``sensor_msgs/JointState.position``); the time is the bag's receive time
    (``time_source = "log"``) or ``msg.header.stamp`` (``"header"``).
    """
    topics = {"enc_yaw": spec.yaw_topic, "enc_pitch": spec.pitch_topic}
    if spec.sync_topic:
        topics["sync_flash"] = spec.sync_topic
    try:
        with AnyReader([path]) as reader:
            available = sorted({c.topic for c in reader.connections})
            for name, topic in topics.items():
                if topic not in available:
                    raise CalibError(
                        f"{path}: no topic '{topic}' for {name} (bag has: {', '.join(available) or 'none'}; "
                        "set [encoder] yaw_topic/pitch_topic/sync_topic in session.toml)"
                    )
            data = {
                name: _topic_series(reader, path, topic, spec, name == "sync_flash")
                for name, topic in topics.items()
            }
    except (AnyReaderError, FileNotFoundError, OSError) as exc:
        raise CalibError(f"{path}: cannot read the ROS bag ({exc})") from None
    flash = data.pop("sync_flash", None)
    return make_encoder_log(data, flash, f"{path}", max_gap_s, spec.max_counts_per_s)


def _topic_series(reader, path: Path, topic: str, spec: EncoderLogSpec, is_sync: bool):
    """(times s, values) of one topic, in bag order."""
    conns = [c for c in reader.connections if c.topic == topic]
    field = spec.sync_field if is_sync else spec.value_field
    times, values = [], []
    for conn, stamp_ns, raw in reader.messages(connections=conns):
        msg = reader.deserialize(raw, conn.msgtype)
        values.append(_field_value(msg, field, spec.value_index, path, topic))
        times.append(_stamp_s(msg, stamp_ns, spec.time_source, path, topic))
    if not times:
        raise CalibError(
            f"{path}: topic '{topic}' has no messages (record it, or pick another topic)"
        )
    return np.array(times, dtype=float), np.array(values, dtype=float)


def _field_value(msg, field: str, index: int, path: Path, topic: str) -> float:
    """``msg.<field>`` (dotted), element ``index`` of an array, as float."""
    obj = msg
    for part in field.split("."):
        if not hasattr(obj, part):
            names = [n for n in dir(obj) if not n.startswith("_")]
            raise CalibError(
                f"{path}: messages on '{topic}' have no field '{field}' (fields: {', '.join(names)}; "
                "set [encoder] value_field/sync_field in session.toml)"
            )
        obj = getattr(obj, part)
    if isinstance(obj, (bool, int, float, np.number)):
        return float(obj)
    arr = np.asarray(obj, dtype=float).ravel()
    if index >= arr.size:
        raise CalibError(
            f"{path}: '{field}' on '{topic}' has {arr.size} element(s), value_index = {index} "
            "(set [encoder] value_index in session.toml)"
        )
    return float(arr[index])


def _stamp_s(msg, stamp_ns: int, source: str, path: Path, topic: str) -> float:
    """Message time in seconds: bag receive time or header stamp."""
    if source == "log":
        return stamp_ns * 1e-9
    header = getattr(msg, "header", None)
    if header is None:
        raise CalibError(
            f"{path}: messages on '{topic}' have no header (set [encoder] time_source = \"log\")"
        )
    st = header.stamp
    nsec = getattr(st, "nanosec", getattr(st, "nsec", 0))
    return float(st.sec) + float(nsec) * 1e-9
