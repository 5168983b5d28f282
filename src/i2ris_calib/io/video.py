"""Video inputs: open a reader by the stream's codec, decode ahead in a thread, grey frames.

A camera's ``video`` in session.toml may be a video file or an image-sequence folder
(:mod:`i2ris_calib.io.frames`). Formats read (docs/video.md): FFV1 (``.mkv``/``.avi``,
lossless, 8 or 16 bit), MJPG ``.avi``, mp4v and H.264 ``.mp4`` (H.264 where the OpenCV
wheel's FFmpeg decodes it), and anything else OpenCV's FFmpeg decodes.

The choice of output format is made from the stream, not the file name: only a
stream whose codec pixel format is grey (``Y800``/``Y16``, e.g. FFV1 gray) is read with
``CAP_PROP_CONVERT_RGB = 0`` (one channel straight from the decoder, no BGR
conversion). A YUV stream (MJPG ``yuvj420p``, mp4v/H.264 ``yuv420p``) keeps OpenCV's
conversion; with it turned off OpenCV would print
``Unknown/unsupported picture format`` for every frame and, for limited-range YUV,
hand back the raw luma plane (grey levels 16-235 instead of 0-255).

``CAP_PROP_FRAME_COUNT`` comes from the container header and may be wrong, so
readers count decoded frames instead.

The two kinds of input are two :class:`FrameSource` implementations, chosen once by
:func:`frame_source` (a folder is an :class:`ImageFolder`, anything else a
:class:`VideoFile`); the functions below ask the source and never test the path again.
"""

from __future__ import annotations

import os
import queue
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Protocol

import cv2
import numpy as np

from i2ris_calib.errors import CalibError
from i2ris_calib.io import frames
from i2ris_calib.io.frames import to_uint8

#: Codec chosen by :func:`open_writer` from the suffix (simulator output, tests).
FOURCC = {".mkv": "FFV1", ".avi": "FFV1", ".mp4": "mp4v"}
#: Codec pixel formats (``CAP_PROP_CODEC_PIXEL_FORMAT`` as text) that decode to one channel.
GREY_PIXEL_FORMATS = {"Y800", "GREY", "Y8  ", "Y16 ", "Y1\x00\x10", "\x10\x001Y"}
#: Frames decoded ahead of the consumer by :func:`iter_frames` (bounded memory).
DECODE_AHEAD = 8


def fourcc_text(code: float) -> str:
    """Four-character text of an OpenCV FOURCC property value ('' if unknown/zero)."""
    n = int(code)
    if n <= 0:
        return ""
    return n.to_bytes(4, "little").decode("latin-1")


def sync_log_level() -> None:
    """Apply ``OPENCV_LOG_LEVEL`` to an already imported cv2 (CLI: quiet unless --debug).

    OpenCV reads the variable once, when cv2 is imported; the CLI sets it (and
    ``OPENCV_FFMPEG_LOGLEVEL``, which is read when the first capture/writer opens) before
    running a command, but a library or test may have imported cv2 earlier. Without the
    variable nothing is changed.
    """
    name = os.environ.get("OPENCV_LOG_LEVEL", "").strip().upper()
    levels = {
        "SILENT": cv2.utils.logging.LOG_LEVEL_SILENT,
        "FATAL": cv2.utils.logging.LOG_LEVEL_FATAL,
        "ERROR": cv2.utils.logging.LOG_LEVEL_ERROR,
        "WARNING": cv2.utils.logging.LOG_LEVEL_WARNING,
        "INFO": cv2.utils.logging.LOG_LEVEL_INFO,
        "DEBUG": cv2.utils.logging.LOG_LEVEL_DEBUG,
        "VERBOSE": cv2.utils.logging.LOG_LEVEL_VERBOSE,
    }
    if name in levels:
        cv2.utils.logging.setLogLevel(levels[name])


def open_writer(path: Path, fps: float, size_wh: tuple[int, int], codec: str | None = None):
    """A grey-level ``cv2.VideoWriter`` for ``path``.

    Parameters
    ----------
    path : Path
        Output file; the suffix picks the codec (:data:`FOURCC`) unless ``codec`` is given.
    fps : float
        Frame rate written to the container (frames/s).
    size_wh : (int, int)
        Frame width and height (px).
    codec : str, optional
        Four-character code (e.g. ``"MJPG"``, ``"FFV1"``), overriding the suffix.
    """
    sync_log_level()
    code = codec or FOURCC.get(Path(path).suffix.lower())
    if code is None:
        raise CalibError(f"{path}: unsupported video suffix (use .mkv for FFV1 or .mp4 for mp4v)")
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*code), float(fps), size_wh, False)
    if not w.isOpened():
        raise CalibError(f"{path}: OpenCV could not open a {code} writer")
    return w


def _check_file(p: Path) -> None:
    if not p.exists():
        raise CalibError(f"video not found: {p} (check the path in session.toml)")
    if p.is_file() and p.stat().st_size == 0:
        raise CalibError(f"video is empty: {p} (re-export the recording)")


def open_reader(path: Path, threads: int = 0):
    """A ``cv2.VideoCapture`` of a video file; CalibError when unreadable.

    Parameters
    ----------
    path : Path
        A video file (an image-sequence folder is read by :func:`iter_frames`).
    threads : int
        FFmpeg decoder threads (``CAP_PROP_N_THREADS``); 0 = FFmpeg's default (one per
        CPU; frame threading where the codec supports it, e.g. FFV1, H.264).

    Returns
    -------
    cv2.VideoCapture
        With ``CAP_PROP_CONVERT_RGB = 0`` only when the stream's pixel format is grey
        (frames come out (h, w)); other streams deliver BGR (h, w, 3). Use
        :func:`as_gray` on every frame.
    """
    sync_log_level()
    p = Path(path)
    _check_file(p)
    if p.is_dir():
        raise CalibError(f"{p} is a folder: read image sequences with iter_frames (docs/video.md)")
    params = [cv2.CAP_PROP_N_THREADS, int(threads)] if threads > 0 else []
    cap = cv2.VideoCapture(str(p), cv2.CAP_FFMPEG, params)
    if not cap.isOpened():
        cap = cv2.VideoCapture(str(p))  # another backend (e.g. a GStreamer build)
    if not cap.isOpened():
        raise CalibError(
            f"cannot decode video {p} (corrupt or unsupported codec; use FFV1 .mkv, MJPG .avi, "
            "an .mp4 your OpenCV decodes, or an image-sequence folder: docs/video.md)"
        )
    if stream_is_grey(cap):
        # grey streams decode straight to one channel: skips a BGR conversion per frame
        cap.set(cv2.CAP_PROP_CONVERT_RGB, 0)
    return cap


def stream_is_grey(cap) -> bool:
    """Whether the opened stream's codec pixel format is single-channel grey."""
    return fourcc_text(cap.get(cv2.CAP_PROP_CODEC_PIXEL_FORMAT)) in GREY_PIXEL_FORMATS


def video_info(path: Path) -> dict:
    """Codec, pixel format, size and header frame count of a video file or sequence."""
    return frame_source(path).info()


def _file_info(p: Path) -> dict:
    """:func:`video_info` of a video file."""
    cap = open_reader(p)
    try:
        return {
            "codec": fourcc_text(cap.get(cv2.CAP_PROP_FOURCC)),
            "pixel_format": fourcc_text(cap.get(cv2.CAP_PROP_CODEC_PIXEL_FORMAT)),
            "grey": stream_is_grey(cap),
            "size_wh": (
                int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)),
                int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)),
            ),
            "frames": int(cap.get(cv2.CAP_PROP_FRAME_COUNT)),
        }
    finally:
        cap.release()


def as_gray(frame: np.ndarray, bits: int = 16) -> np.ndarray:
    """Grey uint8 image of a decoded frame (grey, BGR, BGRA, single-channel 3-D, 16 bit).

    Parameters
    ----------
    frame : ndarray (h, w) or (h, w, c), uint8 or uint16
    bits : int
        Significant bits of a uint16 frame: grey levels ``0 .. 2**bits - 1`` map
        linearly onto ``0 .. 255`` (:func:`i2ris_calib.io.frames.to_uint8`). Ignored for uint8.
    """
    if frame.ndim == 3:
        if frame.shape[2] == 1:
            frame = frame[:, :, 0]
        elif frame.shape[2] == 4:
            frame = cv2.cvtColor(frame, cv2.COLOR_BGRA2GRAY)
        else:
            frame = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
    if frame.dtype == np.uint8:
        return frame

    return to_uint8(frame, bits)


def _decode_file(path: Path, threads: int) -> Iterator[np.ndarray]:
    """Raw decoded frames of a video file, in order (grey, BGR or 16 bit)."""
    cap = open_reader(path, threads)
    try:
        while True:
            ok, frame = cap.read()
            if not ok or frame is None:
                break
            yield frame
    finally:
        cap.release()


class FrameSource(Protocol):
    """Where a camera's frames come from: one implementation per kind of input
    (CONTRIBUTING.md, "adding a frame source"), chosen once by :func:`frame_source`."""

    path: Path

    def info(self) -> dict:
        """Codec, pixel format, frame count (and size, grey) as :func:`video_info`."""
        ...

    def header_count(self) -> int:
        """Frames the input claims before decoding (-1 if unknown)."""
        ...

    def files(self) -> list[Path]:
        """The files the input consists of (the run's stamps hash them)."""
        ...

    def known_bits(self) -> int | None:
        """Significant bits of its 16-bit frames known before decoding, or None (then
        estimated from the first frame)."""
        ...

    def raw_frames(self, threads: int) -> Iterator[np.ndarray]:
        """Decoded frames in order (grey, BGR or 16 bit), before :func:`as_gray`."""
        ...


@dataclass(frozen=True)
class VideoFile:
    """A video file decoded by OpenCV's FFmpeg (:func:`open_reader`)."""

    path: Path

    def info(self) -> dict:
        return _file_info(self.path)

    def header_count(self) -> int:
        cap = open_reader(self.path)
        try:
            n = cap.get(cv2.CAP_PROP_FRAME_COUNT)
        finally:
            cap.release()
        return int(n) if n and n > 0 else -1

    def files(self) -> list[Path]:
        return [self.path]

    def known_bits(self) -> int | None:
        return None

    def raw_frames(self, threads: int) -> Iterator[np.ndarray]:
        _check_file(self.path)
        return _decode_file(self.path, threads)


@dataclass(frozen=True)
class ImageFolder:
    """A folder of ``<prefix><number>.<png|tif|tiff>`` frames (:mod:`i2ris_calib.io.frames`)."""

    path: Path

    @cached_property
    def sequence(self) -> frames.ImageSequence:
        """The folder's image sequence (found once)."""
        return frames.find_sequence(self.path)

    def info(self) -> dict:
        seq = self.sequence
        return {
            "codec": f"image sequence ({seq.suffix})",
            "pixel_format": "",
            "frames": len(seq.files),
        }

    def header_count(self) -> int:
        return len(self.sequence.files)

    def files(self) -> list[Path]:
        return list(self.sequence.files)

    def known_bits(self) -> int | None:
        return frames.sequence_bits(self.sequence)

    def raw_frames(self, threads: int) -> Iterator[np.ndarray]:
        return frames.iter_sequence(self.sequence)


def frame_source(path: Path) -> FrameSource:
    """The :class:`FrameSource` of a camera's ``video``: an :class:`ImageFolder` for a
    folder, else a :class:`VideoFile` (a missing file fails when it is read)."""
    p = Path(path)
    return ImageFolder(p) if p.is_dir() else VideoFile(p)


_DONE = object()


def _ahead(source: Iterator[np.ndarray], depth: int) -> Iterator[np.ndarray]:
    """Run ``source`` in a background thread, ``depth`` items ahead of the consumer.

    OpenCV releases the GIL while it decodes, so decoding the next frames overlaps
    whatever the consumer does with the current one (marker detection). Exceptions
    of the producer are re-raised in the consumer; closing the generator early stops
    the producer.
    """
    q: queue.Queue = queue.Queue(maxsize=max(depth, 1))
    stop = threading.Event()

    def put(item) -> bool:
        while not stop.is_set():
            try:
                q.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def produce() -> None:
        try:
            for item in source:
                if not put(item):
                    break
        except BaseException as exc:  # noqa: BLE001 - handed to the consumer
            put((_DONE, exc))
            return
        finally:
            close = getattr(source, "close", None)
            if close is not None:
                close()
        put((_DONE, None))

    th = threading.Thread(target=produce, name="video-decode", daemon=True)
    th.start()
    try:
        while True:
            item = q.get()
            if isinstance(item, tuple) and len(item) == 2 and item[0] is _DONE:
                if item[1] is not None:
                    raise item[1]
                return
            yield item
    finally:
        stop.set()
        th.join(timeout=5.0)


def iter_frames(
    path: Path, ahead: int = DECODE_AHEAD, threads: int = 0, bits: int | None = None
) -> Iterator[np.ndarray]:
    """Decoded grey uint8 frames of a video file or image-sequence folder, in order.

    Parameters
    ----------
    path : Path
        Video file or folder of ``<prefix><number>.<png|tif|tiff>`` frames (docs/video.md).
    ahead : int
        Frames decoded ahead in a background thread (0 = decode in the caller's thread).
    threads : int
        FFmpeg decoder threads (0 = FFmpeg's default), see :func:`open_reader`.
    bits : int, optional
        Significant bits of 16-bit frames (16-bit video or images); default: estimated
        from the data (:func:`i2ris_calib.io.frames.significant_bits`; for a sequence
        from up to 5 frames spread over it, for a video from its first frame).

    Yields
    ------
    ndarray (h, w) uint8
    CalibError if no frame decodes.
    """
    source = frame_source(path)
    if bits is None:
        bits = source.known_bits()
    raw = source.raw_frames(threads)
    src = _ahead(raw, ahead) if ahead > 0 else raw
    n = 0
    try:
        for frame in src:
            if frame.dtype != np.uint8 and bits is None:
                bits = frames.significant_bits(frame)
            n += 1
            yield as_gray(frame, bits or 16)
    finally:
        close = getattr(src, "close", None)
        if close is not None:
            close()
    if n == 0:
        raise CalibError(f"no frame could be decoded from {path} (corrupt or truncated video)")


def header_frame_count(path: Path) -> int:
    """Frame count claimed by the container header, or the number of sequence images (-1 if unknown)."""
    return frame_source(path).header_count()


def input_files(path: Path) -> list[Path]:
    """The files a video input consists of: the file itself, or a sequence's images."""
    return frame_source(path).files()
