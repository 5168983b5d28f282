"""Video files: open a writer by extension, read grey frames with clear errors.

Formats that work in the OpenCV 5 wheel: FFV1 in ``.mkv`` (lossless) and mp4v in
``.mp4`` (lossy). ``CAP_PROP_FRAME_COUNT`` comes from the container header and may
be wrong, so readers count decoded frames instead.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from i2ris_calib.errors import CalibError

FOURCC = {".mkv": "FFV1", ".avi": "FFV1", ".mp4": "mp4v"}


def open_writer(path: Path, fps: float, size_wh: tuple[int, int]):
    """A grey-level ``cv2.VideoWriter`` for ``path`` (codec chosen by the suffix)."""
    import cv2

    code = FOURCC.get(path.suffix.lower())
    if code is None:
        raise CalibError(f"{path}: unsupported video suffix (use .mkv for FFV1 or .mp4 for mp4v)")
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*code), float(fps), size_wh, False)
    if not w.isOpened():
        raise CalibError(f"{path}: OpenCV could not open a {code} writer")
    return w


def open_reader(path: Path):
    """A ``cv2.VideoCapture`` delivering grey frames; CalibError when unreadable."""
    import cv2

    p = Path(path)
    if not p.is_file():
        raise CalibError(f"video not found: {p} (check the path in session.toml)")
    if p.stat().st_size == 0:
        raise CalibError(f"video is empty: {p} (re-export the recording)")
    cap = cv2.VideoCapture(str(p))
    if not cap.isOpened():
        raise CalibError(
            f"cannot decode video {p} (corrupt or unsupported codec; use FFV1 .mkv or mp4v .mp4)"
        )
    if p.suffix.lower() in (".mkv", ".avi"):
        # FFV1 grey decodes straight to one channel: skips a BGR conversion per frame
        cap.set(cv2.CAP_PROP_CONVERT_RGB, 0)
    return cap


def as_gray(frame: np.ndarray) -> np.ndarray:
    """Grey uint8 view of a decoded frame (grey, BGR or single-channel 3-D)."""
    import cv2

    if frame.ndim == 2:
        return frame
    if frame.shape[2] == 1:
        return frame[:, :, 0]
    if frame.shape[2] == 4:
        return cv2.cvtColor(frame, cv2.COLOR_BGRA2GRAY)
    return cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)


def iter_frames(path: Path) -> Iterator[np.ndarray]:
    """Decoded grey frames of a video, in order; CalibError if none decode."""
    cap = open_reader(path)
    n = 0
    try:
        while True:
            ok, frame = cap.read()
            if not ok or frame is None:
                break
            n += 1
            yield as_gray(frame)
    finally:
        cap.release()
    if n == 0:
        raise CalibError(f"no frame could be decoded from {path} (corrupt or truncated video)")


def header_frame_count(path: Path) -> int:
    """Frame count claimed by the container header (may be wrong; -1 if unknown)."""
    import cv2

    cap = open_reader(path)
    try:
        n = cap.get(cv2.CAP_PROP_FRAME_COUNT)
    finally:
        cap.release()
    return int(n) if n and n > 0 else -1
