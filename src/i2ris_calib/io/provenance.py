"""Provenance block recorded in every output: version, config, input hashes."""

from __future__ import annotations

import hashlib
import platform
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from i2ris_calib import __version__
from i2ris_calib.io.config_io import dataclass_to_dict


def file_sha256(path: str | Path, chunk: int = 1 << 20) -> str:
    """Hex SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()


def provenance(inputs: Iterable[str | Path], config: Any = None, **extra: Any) -> dict[str, Any]:
    """Dict with package version, Python/platform, config and input file hashes.

    Parameters
    ----------
    inputs : iterable of paths
        Files the output was computed from; each is hashed (SHA-256).
    config : dataclass or mapping, optional
        The effective configuration, recorded in full.
    """
    return {
        "package": "i2ris-calib",
        "version": __version__,
        "python": platform.python_version(),
        "config": dataclass_to_dict(config) if config is not None else None,
        "inputs": {str(p): file_sha256(p) for p in inputs},
        **extra,
    }
