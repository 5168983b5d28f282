"""Load ``session.toml`` into a :class:`~i2ris_calib.session.SessionSpec`."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from i2ris_calib.errors import CalibError
from i2ris_calib.io.config_io import dataclass_from_mapping, load_toml
from i2ris_calib.session import CameraSpec, EncoderLogSpec, MarkerSpec, SessionSpec

SESSION_FILE = "session.toml"


def load_session(folder: str | Path) -> SessionSpec:
    """Read and validate ``folder/session.toml``; cameras become CameraSpec objects."""
    root = Path(folder)
    if not root.is_dir():
        raise CalibError(
            f"session folder not found: {root} (give a folder laid out as in docs/session.md)"
        )
    path = root / SESSION_FILE
    if not path.is_file():
        raise CalibError(
            f"{root}: no {SESSION_FILE} (every session folder needs one, see docs/session.md)"
        )
    data = load_toml(path)
    cams = data.pop("cameras", {})
    tables = {  # sub-tables built on their own, so messages say "session.toml [marker]"
        key: dataclass_from_mapping(cls, data.pop(key), where=f"{path} [{key}]")
        for key, cls in (("marker", MarkerSpec), ("encoder", EncoderLogSpec))
        if key in data
    }
    spec = replace(dataclass_from_mapping(SessionSpec, data, where=str(path)), **tables)
    if not isinstance(cams, dict) or not cams:
        raise CalibError(
            f"{path}: no [cameras.<name>] tables (a session needs two cameras, see docs/session.md)"
        )
    cameras = {
        name: dataclass_from_mapping(CameraSpec, table, where=f"{path} [cameras.{name}]")
        for name, table in cams.items()
    }
    return replace(spec, cameras=cameras)


def session_file(folder: str | Path, relative: str, what: str) -> Path:
    """Absolute path of a file named in session.toml; CalibError if it is missing."""
    p = Path(folder) / relative
    if not relative or not p.exists():
        raise CalibError(
            f"{Path(folder) / SESSION_FILE}: {what} '{relative}' not found in {folder} "
            "(fix the path in session.toml or add the file)"
        )
    return p
