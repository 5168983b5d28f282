"""Image-sequence folders as camera videos: ``frame_000000.png``, ``img_0001.tif``, ...

A camera's ``video`` in session.toml may name a folder of numbered images (docs/video.md):
every file ``<prefix><number>.<ext>`` with one prefix and one extension (``.png``,
``.tif``/``.tiff``; also ``.jpg``/``.bmp``), 8 or 16 bit grey (colour is converted to grey). Frames are ordered
by the number, which must count up by one (a missing number is a lost frame: the
sequence is refused, since the timestamp file has one row per frame).

16-bit frames are scaled to 8 bit for detection with ONE linear scale for the whole
sequence, ``v8 = round(v16 * 255 / (2**bits - 1))``, where ``bits`` is the number of
significant bits (:func:`significant_bits`: 8-16, from the brightest pixel of up to 5
frames spread over the sequence, so a 12-bit camera stored in 16-bit files maps 0-4095
onto 0-255). A per-frame scale would change the frames' mean grey level, which the
sync stage reads for the flash; a constant scale keeps it proportional.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from i2ris_calib.errors import CalibError

#: Image suffixes accepted in a sequence folder.
IMAGE_SUFFIXES = (".png", ".tif", ".tiff", ".jpg", ".jpeg", ".bmp")
_ALIASES = {".tiff": ".tif", ".jpeg": ".jpg"}
_NAME = re.compile(r"^(?P<prefix>.*?)(?P<num>\d+)$")


@dataclass(frozen=True)
class ImageSequence:
    """A validated image-sequence folder.

    Attributes
    ----------
    folder : Path
    prefix : str
        Common file-name part before the number (e.g. ``"frame_"``).
    suffix : str
        Common extension, lower case (e.g. ``".png"``).
    files : tuple of Path
        The frames in order (number ascending, consecutive).
    first : int
        Number of the first frame.
    """

    folder: Path
    prefix: str
    suffix: str
    files: tuple[Path, ...]
    first: int


def find_sequence(folder: Path) -> ImageSequence:
    """The numbered images of ``folder``; CalibError (what, where, fix) when not a sequence."""
    folder = Path(folder)
    images = [p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES]
    if not images:
        raise CalibError(
            f"{folder}: no .png/.tif/.jpg/.bmp images (an image-sequence video is a folder of "
            "frame_000000.png, frame_000001.png, ...: see docs/video.md)"
        )
    suffixes = {_ALIASES.get(p.suffix.lower(), p.suffix.lower()) for p in images}
    if len(suffixes) > 1:
        raise CalibError(
            f"{folder}: mixed image types {sorted(suffixes)} (keep one type per camera folder)"
        )
    parsed = []
    for p in images:
        m = _NAME.match(p.stem)
        if m is None:
            raise CalibError(
                f"{folder}: image '{p.name}' has no frame number at the end of its name "
                "(name frames like frame_000000.png)"
            )
        parsed.append((m["prefix"], int(m["num"]), p))
    prefixes = {pre for pre, _, _ in parsed}
    if len(prefixes) > 1:
        raise CalibError(
            f"{folder}: images with different name prefixes {sorted(prefixes)[:4]} "
            "(keep only one camera's frames in the folder)"
        )
    parsed.sort(key=lambda x: x[1])
    nums = np.array([n for _, n, _ in parsed])
    steps = np.diff(nums)
    if np.any(steps != 1):
        k = int(np.flatnonzero(steps != 1)[0])
        what = "duplicate" if steps[k] == 0 else "missing"
        raise CalibError(
            f"{folder}: frame numbers not consecutive ({what} after {parsed[k][2].name}); "
            "every frame needs its image, numbered without gaps"
        )
    return ImageSequence(
        folder, parsed[0][0], suffixes.pop(), tuple(p for _, _, p in parsed), int(nums[0])
    )


def read_image(path: Path) -> np.ndarray:
    """One frame as stored (uint8 or uint16, grey or colour); CalibError if unreadable."""
    img = cv2.imread(str(path), cv2.IMREAD_ANYDEPTH | cv2.IMREAD_ANYCOLOR)
    if img is None:
        raise CalibError(f"cannot read image {path} (corrupt or unsupported file)")
    if img.dtype not in (np.uint8, np.uint16):
        raise CalibError(
            f"{path}: {img.dtype} pixels (frames must be 8 or 16 bit integer grey levels)"
        )
    return img


def significant_bits(img: np.ndarray) -> int:
    """Bits needed for the brightest pixel of a uint16 image, between 8 and 16."""
    top = int(img.max()) if img.size else 0
    return int(min(max(top.bit_length(), 8), 16))


def sequence_bits(seq: ImageSequence, samples: int = 5) -> int:
    """Significant bits of a sequence: 8 for 8-bit files, else from ``samples`` spread frames."""
    idx = np.unique(np.linspace(0, len(seq.files) - 1, min(samples, len(seq.files))).astype(int))
    bits = 8
    for k in idx:
        img = read_image(seq.files[k])
        if img.dtype == np.uint8:
            return 8
        bits = max(bits, significant_bits(img))
    return bits


def to_uint8(img: np.ndarray, bits: int) -> np.ndarray:
    """uint16 grey levels ``0 .. 2**bits - 1`` mapped linearly onto uint8 ``0 .. 255``.

    Values above ``2**bits - 1`` saturate at 255.
    """
    scale = 255.0 / float(2**bits - 1)
    return cv2.convertScaleAbs(img, alpha=scale)  # rounds and saturates


def iter_sequence(seq: ImageSequence) -> Iterator[np.ndarray]:
    """The frames of a sequence as stored (uint8 or uint16), in order."""
    for p in seq.files:
        yield read_image(p)
