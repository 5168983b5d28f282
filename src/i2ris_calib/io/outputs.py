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

A folder without a marker (written by an older version) is taken as the command's
only when it holds nothing but the command's output names *and* one of them is a
JSON (or HTML) file this tool wrote (:func:`_tool_wrote_file`: its ``provenance``
names i2ris-calib): names alone do not make a folder ours (a recording has a
``session.toml`` and videos too, a user may keep a ``fit.json`` of their own).

One command at a time writes an ``--out``: :func:`output_lock` creates a lock file
beside it (``.<name>.i2ris-calib.lock``) with exclusive creation, held from the
up-front check until the outputs are in place; a second command refuses while it is
held, and it is removed on exit (also on an error or Ctrl-C).
"""

from __future__ import annotations

import contextlib
import fnmatch
import json
import os
import shutil
import socket
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

from i2ris_calib import __version__
from i2ris_calib.errors import CalibError

MARKER = ".i2ris-calib.json"
#: Files in an output folder that the pipeline itself writes besides a command's outputs.
TOOL_DOTFILES = frozenset({MARKER, ".stamp.json", ".session.json"})
#: The end of a lock file's name (:func:`output_lock`): ``.<out name>.i2ris-calib.lock``.
LOCK_SUFFIX = ".i2ris-calib.lock"


def _is_tool_leftover(name: str) -> bool:
    """A temporary, stamp or lock file this tool writes (``.x.tmp-*``, ``.stamp.json``, ...)."""
    return name in TOOL_DOTFILES or (
        name.startswith(".") and (".tmp-" in name or ".old-" in name or name.endswith(LOCK_SUFFIX))
    )


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


def _dangling(p: Path) -> bool:
    """``p`` is a symbolic link to nothing (or into a loop)."""
    return p.is_symlink() and not p.exists()


def _check_parents(out: Path, what: str) -> None:
    """No parent of ``out`` is a file or a link to nothing; nor is ``out`` itself such
    a link (it can be neither written through nor replaced: it is not the tool's)."""
    for p in (out, *out.parents):
        if _dangling(p):
            raise CalibError(
                f"{what} {out}: {p} is a symbolic link to {os.readlink(p)}, which does not "
                "exist; create its target, remove the link or give another path "
                "(nothing was changed)"
            )
    for parent in out.parents:
        if parent.exists() and not parent.is_dir():
            raise CalibError(
                f"{what} {out}: {parent} is a file, not a folder; give a folder path for the outputs"
            )


def check_out_path(out: str | Path, what: str = "--out") -> None:
    """Refuse an ``out`` that is, or lies under, a link to nothing, or lies under a file."""
    _check_parents(Path(out), what)


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
            _check_legacy_folder(out, outputs, command, what)
    _check_lock_free(out, what)
    _check_writable(out, what)
    return out


def _legacy_files(out: Path, outputs: Iterable[str]) -> list[Path]:
    """The files of an unmarked folder bearing the command's output names (and the files
    below a folder so named, e.g. simulate's ``truth/``)."""
    outputs = tuple(outputs)
    found: list[Path] = []
    for p in sorted(out.iterdir()):
        if not _is_output_name(p.name, outputs):
            continue
        if p.is_dir() and not p.is_symlink():
            found.extend(sorted(f for f in p.rglob("*") if f.is_file()))
        elif p.is_file():
            found.append(p)
    return found


def _check_legacy_folder(out: Path, outputs: Iterable[str], command: str, what: str) -> None:
    """An unmarked folder with the command's output names is the command's (an older
    version's) only when a JSON or HTML file among them was written by this tool; the
    names alone prove nothing (a recording has a session.toml and videos too)."""
    files = _legacy_files(out, outputs)
    if not files:
        return
    if any(f.suffix.lower() in (".json", ".html") and _tool_wrote_file(f) for f in files):
        return
    names = [f.relative_to(out).as_posix() for f in files]
    more = f" and {len(names) - 3} more" if len(names) > 3 else ""
    raise CalibError(
        f"{what} {out}: holds {', '.join(names[:3])}{more} but no sign that i2ris-calib "
        f"wrote them (no {MARKER}, no JSON with its provenance), so they are taken as yours; "
        f"give a new or empty folder for '{command}' (nothing was changed)"
    )


def lock_path(out: str | Path) -> Path:
    """The lock file of ``out`` (:func:`output_lock`): ``.<name>.i2ris-calib.lock`` beside it."""
    out = Path(out)
    return _resolved(out.parent) / f".{out.name}{LOCK_SUFFIX}"


#: Lock files this process holds, with how many nested :func:`output_lock` hold each.
_HELD: dict[Path, int] = {}


def _lock_holder(lock: Path) -> dict | None:
    """The record of a lock held by a live process (None: no lock, or a stale one whose
    process on this machine has ended)."""
    try:
        rec = json.loads(lock.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return None
    except (OSError, ValueError):
        return {}  # being written, or unreadable: taken as held
    if not isinstance(rec, dict):
        return {}
    pid = rec.get("pid")
    if rec.get("host") == socket.gethostname() and isinstance(pid, int) and pid > 0:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return None
        except OSError:  # pragma: no cover - alive, another user's
            pass
    return rec


def _busy_error(out: Path, lock: Path, rec: dict, what: str) -> CalibError:
    who = f"'{rec['command']}' (process {rec.get('pid', '?')})" if rec.get("command") else (
        "another i2ris-calib command")  # fmt: skip
    return CalibError(
        f"{what} {out}: {who} is writing there now; wait until it ends or give another "
        f"--out (nothing was changed; if none is running, remove {lock})"
    )


def _check_lock_free(out: Path, what: str) -> None:
    """Refuse ``out`` while another process holds its lock (:func:`output_lock`)."""
    lock = lock_path(out)
    if lock in _HELD:
        return
    rec = _lock_holder(lock)
    if rec is not None:
        raise _busy_error(out, lock, rec, what)


@contextlib.contextmanager
def output_lock(*outs: str | Path, command: str = "", what: str = "--out") -> Iterator[None]:
    """Hold the lock of every path in ``outs`` for the block: one command at a time.

    Each lock is a file created with exclusive creation beside its path, recording the
    process; it is removed when the block ends (also on an error or Ctrl-C). A lock
    this process already holds is re-entered; a lock of a process on this machine that
    has ended is taken over. Missing parent folders are created for the lock and
    removed again when still empty.

    Raises
    ------
    CalibError
        Another command holds one of the locks, or the lock cannot be created.
    """
    taken: list[Path] = []
    made: list[Path] = []
    try:
        for out in dict.fromkeys(Path(o) for o in outs):
            lock = lock_path(out)
            if lock in _HELD:
                _HELD[lock] += 1
                taken.append(lock)
                continue
            _check_parents(out, what)
            try:
                made.extend(p for p in lock.parents if not p.exists())
                lock.parent.mkdir(parents=True, exist_ok=True)
                fd = _create_lock(lock)
                if fd is None:
                    rec = _lock_holder(lock)
                    if rec is not None:
                        raise _busy_error(out, lock, rec, what)
                    lock.unlink(missing_ok=True)  # stale: its process has ended
                    fd = _create_lock(lock)
                    if fd is None:
                        raise _busy_error(out, lock, _lock_holder(lock) or {}, what)
            except OSError as exc:
                raise CalibError(
                    f"{what} {out}: cannot write ({exc.strerror or type(exc).__name__}); "
                    "choose another folder, free disk space or fix permissions"
                ) from None
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                rec = {"pid": os.getpid(), "host": socket.gethostname(), "command": command}
                json.dump(rec, f)
            _HELD[lock] = 1
            taken.append(lock)
        yield
    finally:
        for lock in reversed(taken):
            _HELD[lock] -= 1
            if not _HELD[lock]:
                del _HELD[lock]
                lock.unlink(missing_ok=True)
        _remove_empty(sorted(made, key=lambda p: len(p.parts), reverse=True))


def _create_lock(lock: Path) -> int | None:
    """A new lock file's descriptor, or None when it exists."""
    try:
        return os.open(lock, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
    except FileExistsError:
        return None


def _tool_wrote_file(path: Path) -> bool:
    """Whether this tool wrote file ``path`` (its JSON provenance, or the JSON beside a
    CSV naming it, or the tag in a camera YAML)."""
    try:
        if path.suffix.lower() == ".json":
            doc = json.loads(path.read_text(encoding="utf-8"))
            prov = doc.get("provenance") if isinstance(doc, dict) else None
            schema = doc.get("schema", "i2ris-calib.") if isinstance(doc, dict) else None
            return (
                isinstance(prov, dict)
                and prov.get("package") == "i2ris-calib"
                and isinstance(schema, str)
                and schema.startswith("i2ris-calib.")
            )
        if path.suffix.lower() in (".html", ".htm"):
            head = path.read_text(encoding="utf-8", errors="replace")[:4000]
            return '<meta name="generator" content="i2ris-calib' in head
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
    for p in (out, *(Path(c) for c in companions)):
        _check_parents(p, what)
        if p.is_dir():
            raise CalibError(f"{what} {out}: {p} is a folder; give a file name")
        check_not_input(p, inputs, what)
        if p.exists() and not _tool_wrote_file(p):
            raise CalibError(
                f"{what} {out}: {p} exists and was not written by i2ris-calib; "
                "give a new file name (it is never overwritten)"
            )
        _check_companion_of(out, p, what)
        _check_lock_free(p, what)
    _check_writable(out.parent, what)
    return out


def _check_companion_of(out: Path, companion: Path, what: str) -> None:
    """Refuse to replace a JSON written with another output file (a compensate.json
    naming another COMMANDS.csv that is still there): that file would lose its record."""
    if companion == out or companion.suffix.lower() != ".json" or not companion.is_file():
        return
    try:
        doc = json.loads(companion.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return
    other = doc.get("commands_csv") if isinstance(doc, dict) else None
    if isinstance(other, str) and other != out.name and (companion.parent / other).is_file():
        raise CalibError(
            f"{what} {out}: {companion} belongs to {companion.parent / other} (written with "
            f"it); give each commands file its own folder, e.g. "
            f"{out.parent / out.stem / out.name} (nothing was changed)"
        )


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
    with output_lock(out, command=command, what=what):
        yield from _write_dir(out, command, inputs, outputs, what)


def _write_dir(out: Path, command: str, inputs: tuple, outputs: tuple, what: str) -> Iterator[Path]:
    """The body of :func:`output_dir`, under its lock."""
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
