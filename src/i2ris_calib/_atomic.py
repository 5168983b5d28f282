"""Write a file under a temporary name and rename it when complete (the package's one
atomic write; io/atomic.py builds the file formats on it, FitResult.save uses it too).

A crash or Ctrl-C never leaves a half-written file under the final name, so a re-run
never reuses a truncated output.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

from i2ris_calib.errors import CalibError


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success.

    The temporary keeps the final suffix (``.tmp-XXXX.csv``) so writers that choose
    a format by extension (OpenCV, matplotlib) still work.
    """
    final = Path(path)
    if final.is_dir():
        raise CalibError(f"{final}: is a folder where a file is to be written; remove or rename it")
    try:
        final.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(
            prefix=f".{final.stem}.tmp-", suffix=final.suffix, dir=final.parent
        )
    except OSError as exc:
        raise _write_error(final, exc) from None
    os.close(fd)
    tmp_path = Path(tmp)
    os.chmod(tmp_path, 0o666 & ~_umask())  # mkstemp creates 0600; outputs get normal permissions
    try:
        yield tmp_path
        os.replace(tmp_path, final)
    except OSError as exc:
        tmp_path.unlink(missing_ok=True)
        raise _write_error(final, exc) from None
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise


def _write_error(path: Path, exc: OSError) -> CalibError:
    """One-line CalibError for a failed write of ``path`` (disk full, permission, ...)."""
    why = exc.strerror or type(exc).__name__
    return CalibError(
        f"{path}: cannot write ({why}); choose another --out, free disk space or fix permissions"
    )


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_text(path: str | Path, text: str) -> None:
    """Atomically write UTF-8 text."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
