"""Where a command may write: the one rule for every ``--out`` (docs/formats.md, "Outputs").

An output **folder** is written only when it is new, empty, or was written by this tool
for the same command: its marker file ``.i2ris-calib.json`` names the command and lists
the files it wrote. An output **file** is replaced only when this tool wrote it. An
``--out`` that is an input, contains an input or lies inside an input file is refused.
Every check runs before any work (:func:`claim_output_dir`, :func:`claim_output_file`)
and again just before the outputs are moved into place.

Writing (:func:`output_dir`) happens in a temporary folder beside the target; on success
a new folder is renamed into place as a whole, and into an existing folder each new file
is renamed over the old one, files this command wrote last time and not this time are
removed, and files it did not write (a user's notes) are left alone. Nothing the tool
did not write is ever renamed, moved or deleted.
"""

from __future__ import annotations

import contextlib
import fnmatch
import json
import os
import shutil
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

from i2ris_calib import __version__
from i2ris_calib.errors import CalibError

MARKER = ".i2ris-calib.json"
#: Files in an output folder that the pipeline itself writes besides a command's outputs.
TOOL_DOTFILES = frozenset({MARKER, ".stamp.json", ".session.json"})


def _is_tool_leftover(name: str) -> bool:
    """A temporary or stamp file this tool writes (``.x.tmp-*``, ``.stamp.json``, ...)."""
    return name in TOOL_DOTFILES or (name.startswith(".") and (".tmp-" in name or ".old-" in name))


def _resolved(p: Path) -> Path:
    try:
        return p.resolve()
    except OSError:  # pragma: no cover - a loop of symlinks
        return p.absolute()


def _inside(child: Path, parent: Path) -> bool:
    return child == parent or parent in child.parents


def check_not_input(out: str | Path, inputs: Iterable[str | Path], what: str = "--out") -> None:
    """Refuse an output path that is, contains, or lies inside an input file.

    A folder input (a session or run folder) may hold the outputs in a subfolder (the
    default ``SESSION/track``), but ``out`` must not be that folder itself nor contain it.
    """
    o = _resolved(Path(out))
    for raw in inputs:
        p = Path(raw)
        if not p.exists():
            continue
        r = _resolved(p)
        if o == r:
            raise CalibError(
                f"{what} {out}: is the input {p}; give a new folder for the outputs, "
                "the input is never overwritten"
            )
        if _inside(r, o):
            raise CalibError(
                f"{what} {out}: contains the input {p}; give a new folder outside it "
                "(its contents would be mixed with the outputs)"
            )
        if p.is_file() and _inside(o, r):  # pragma: no cover - a file has no children
            raise CalibError(f"{what} {out}: lies inside the input file {p}")


def _check_parents(out: Path, what: str) -> None:
    for parent in out.parents:
        if parent.exists() and not parent.is_dir():
            raise CalibError(
                f"{what} {out}: {parent} is a file, not a folder; give a folder path for the outputs"
            )


def _check_writable(out: Path, what: str) -> None:
    """The nearest existing folder of ``out`` can take new entries (nothing is created)."""
    base = next((p for p in (out, *out.parents) if p.exists()), Path("."))
    if not os.access(base, os.W_OK | os.X_OK):
        raise CalibError(
            f"{what} {out}: cannot write in {base} (permission denied); "
            "choose a folder you can write to"
        )


def read_marker(folder: Path) -> dict | None:
    """The marker of an output folder (command, version, files), or None."""
    try:
        rec = json.loads((folder / MARKER).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(rec, dict) or not isinstance(rec.get("command"), str):
        return None
    files = rec.get("files")
    rec["files"] = [f for f in files if isinstance(f, str)] if isinstance(files, list) else []
    return rec


def _is_output_name(name: str, outputs: Iterable[str]) -> bool:
    return any(fnmatch.fnmatchcase(name, pat) for pat in outputs)


def _foreign_entries(folder: Path, outputs: Iterable[str]) -> list[str]:
    """Entries of an unmarked folder that are not among the command's own output names."""
    outputs = tuple(outputs)
    return sorted(
        p.name
        for p in folder.iterdir()
        if not _is_output_name(p.name, outputs) and not _is_tool_leftover(p.name)
    )


def claim_output_dir(
    out: str | Path,
    command: str,
    inputs: Iterable[str | Path] = (),
    outputs: Iterable[str] = (),
    what: str = "--out",
) -> Path:
    """Check, before any work, that folder ``out`` may take ``command``'s outputs.

    Parameters
    ----------
    out : path
        The output folder; nothing is created here.
    command : str
        The command that writes it (``track``, ``fit``, ...), recorded in the marker.
    inputs : iterable of path
        Files and folders the command reads: ``out`` must not be, contain or lie in one.
    outputs : iterable of str
        The names (or ``fnmatch`` patterns) the command writes. A folder without a
        marker (written by an older version) is accepted when it holds only these.

    Returns
    -------
    Path
        ``out``.

    Raises
    ------
    CalibError
        ``out`` or a parent is a file, ``out`` is or contains an input, ``out`` holds
        files this tool did not write for ``command``, or it cannot be written.
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise CalibError(
            f"{what} {out}: is a file; give a folder path (new or empty) for the outputs"
        )
    _check_parents(out, what)
    check_not_input(out, inputs, what)
    if out.is_dir():
        marker = read_marker(out)
        if marker is not None and marker["command"] != command:
            raise CalibError(
                f"{what} {out}: holds the output of '{marker['command']}', not of '{command}'; "
                "give a new or empty folder (nothing was changed)"
            )
        if marker is None:
            foreign = _foreign_entries(out, outputs)
            if foreign:
                more = f" and {len(foreign) - 3} more" if len(foreign) > 3 else ""
                raise CalibError(
                    f"{what} {out}: holds files this tool did not write ({', '.join(foreign[:3])}"
                    f"{more}); give a new or empty folder (nothing was changed)"
                )
    _check_writable(out, what)
    return out


def _tool_wrote_file(path: Path) -> bool:
    """Whether this tool wrote file ``path`` (its JSON provenance, or the JSON beside a
    CSV naming it, or the tag in a camera YAML)."""
    try:
        if path.suffix.lower() == ".json":
            doc = json.loads(path.read_text(encoding="utf-8"))
            prov = doc.get("provenance") if isinstance(doc, dict) else None
            return isinstance(prov, dict) and prov.get("package") == "i2ris-calib"
        if path.suffix.lower() in (".yaml", ".yml", ".xml"):
            head = path.read_text(encoding="utf-8", errors="replace")[:4000]
            return "written_by" in head and "i2ris-calib" in head
        side = path.with_name("compensate.json")  # a COMMANDS.csv: the JSON that names it
        if side.is_file():
            doc = json.loads(side.read_text(encoding="utf-8"))
            if isinstance(doc, dict) and doc.get("commands_csv") == path.name:
                return _tool_wrote_file(side)
    except (OSError, ValueError):
        return False
    return False


def claim_output_file(
    out: str | Path,
    inputs: Iterable[str | Path] = (),
    what: str = "--out",
    companions: Iterable[str | Path] = (),
) -> Path:
    """Check, before any work, that file ``out`` (and ``companions`` written beside it)
    may be written: not a folder, not an input, and new or written by this tool."""
    out = Path(out)
    _check_parents(out, what)
    for p in (out, *(Path(c) for c in companions)):
        if p.is_dir():
            raise CalibError(f"{what} {out}: {p} is a folder; give a file name")
        check_not_input(p, inputs, what)
        if p.exists() and not _tool_wrote_file(p):
            raise CalibError(
                f"{what} {out}: {p} exists and was not written by i2ris-calib; "
                "give a new file name (it is never overwritten)"
            )
    _check_writable(out.parent, what)
    return out


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _files_below(folder: Path) -> list[str]:
    return sorted(
        p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file() or p.is_symlink()
    )


def _made_parents(out: Path) -> list[Path]:
    """Create the missing parents of ``out``; return the ones created (deepest first)."""
    made = [p for p in out.parents if not p.exists()]
    out.parent.mkdir(parents=True, exist_ok=True)
    return made


def _remove_empty(folders: Iterable[Path]) -> None:
    for d in folders:
        with contextlib.suppress(OSError):
            d.rmdir()


def _legacy_outputs(out: Path, outputs: Iterable[str]) -> list[str]:
    """The files of an unmarked output folder that bear the command's output names."""
    outputs = tuple(outputs)
    return [p.name for p in out.iterdir() if p.is_file() and _is_output_name(p.name, outputs)]


def _merge_into(tmp: Path, out: Path, new: list[str], old: list[str]) -> None:
    """Move ``new`` files from ``tmp`` into existing ``out``; remove ``old`` ones not renewed.

    The marker is removed first and written last, so a crash in between leaves a
    folder that is not marked complete (a ``run`` stage then re-runs).
    """
    (out / MARKER).unlink(missing_ok=True)
    for rel in new:
        if rel == MARKER:
            continue
        dest = out / rel
        dest.parent.mkdir(parents=True, exist_ok=True)
        if dest.is_dir() and not dest.is_symlink():
            raise CalibError(f"{out}: {dest} is a folder where a file is to be written; remove it")
        os.replace(tmp / rel, dest)
    for rel in set(old) - set(new):
        victim = out / rel
        if victim.is_file() and _inside(_resolved(victim), _resolved(out)):
            victim.unlink()
            _remove_empty(p for p in victim.parents if _inside(p, out) and p != out)
    os.replace(tmp / MARKER, out / MARKER)


@contextlib.contextmanager
def output_dir(
    out: str | Path,
    command: str,
    inputs: Iterable[str | Path] = (),
    outputs: Iterable[str] = (),
    what: str = "--out",
) -> Iterator[Path]:
    """Yield a temporary folder; on success its files become ``out``'s (module doc).

    ``out`` is checked with :func:`claim_output_dir` on entry and again before the
    files are moved. On an error or Ctrl-C the temporary folder is removed and ``out``
    is untouched.
    """
    out = Path(out)
    outputs = tuple(outputs)
    inputs = tuple(inputs)
    claim_output_dir(out, command, inputs, outputs, what)
    try:
        made = _made_parents(out)
        tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-", dir=out.parent))
    except OSError as exc:
        raise CalibError(
            f"{what} {out}: cannot write ({exc.strerror or type(exc).__name__}); "
            "choose another folder, free disk space or fix permissions"
        ) from None
    os.chmod(tmp, 0o777 & ~_umask())  # mkdtemp creates 0700
    try:
        yield tmp
        claim_output_dir(out, command, inputs, outputs, what)
        new = _files_below(tmp)
        record = {"tool": "i2ris-calib", "command": command, "version": __version__, "files": new}
        (tmp / MARKER).write_text(json.dumps(record, indent=2) + "\n", encoding="utf-8")
        if not out.exists():
            os.replace(tmp, out)
        else:
            marker = read_marker(out)
            old = marker["files"] if marker else _legacy_outputs(out, outputs)
            _merge_into(tmp, out, new, old)
            shutil.rmtree(tmp, ignore_errors=True)
    except OSError as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        _remove_empty(made)
        raise CalibError(
            f"{what} {out}: cannot write ({exc.strerror or type(exc).__name__}); "
            "choose another folder, free disk space or fix permissions"
        ) from None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        _remove_empty(made)
        raise
