"""Load ``session.toml`` into a :class:`~i2ris_calib.session.SessionSpec`."""

from __future__ import annotations

import os
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


def _same_path(folder: Path, a: str, b: str) -> bool:
    """Whether session.toml paths ``a`` and ``b`` name one file (resolved: ``./x`` and
    ``x``, symlinks, hard links); empty paths are never the same."""
    if not a or not b:
        return False
    pa, pb = folder / a, folder / b
    if pa.exists() and pb.exists():
        return os.path.samefile(pa, pb)
    return pa.resolve() == pb.resolve()


def check_cameras(folder: str | Path, spec: SessionSpec) -> None:
    """Refuse two cameras that share a video, a timestamp file or a marker id.

    Each camera films its own face of the cube: a shared file or id would track one
    face twice and give wrong angles without any other error (issue 19). Called by
    ``track`` and ``run`` before any work (``sync`` does not read the cameras).

    Raises
    ------
    CalibError
        Naming session.toml, both ``[cameras.<name>]`` tables, the key and the fix.
    """
    root = Path(folder)
    where = root / SESSION_FILE
    names = list(spec.cameras)
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            ca, cb = spec.cameras[a], spec.cameras[b]
            for key in ("video", "timestamps"):
                va, vb = getattr(ca, key), getattr(cb, key)
                if _same_path(root, va, vb):
                    same = f"'{va}'" if va == vb else f"'{va}' and '{vb}', one file"
                    raise CalibError(
                        f"{where}: [cameras.{a}] and [cameras.{b}] have the same {key} "
                        f"({same}); each camera films its own face of the cube: give each "
                        "camera its own video and timestamps file"
                    )
            if ca.marker_id == cb.marker_id:
                raise CalibError(
                    f"{where}: [cameras.{a}] and [cameras.{b}] have the same marker_id = "
                    f"{ca.marker_id} (a missing marker_id is 0); the cube faces carry markers "
                    "with different ids: set each camera's marker_id to the id on the face it films"
                )
