"""CLI helpers of the robustness tests (the contract of issue 9)."""

from __future__ import annotations

import hashlib
from pathlib import Path

from i2ris_calib.cli import main


def run_cli(capsys, args: list[str]) -> tuple[int, str, str]:
    """``main(args)`` -> (exit code, stdout, stderr); clears captured output."""
    capsys.readouterr()
    rc = main([str(a) for a in args])
    cap = capsys.readouterr()
    return rc, cap.out, cap.err


def assert_one_line_error(rc: int, err: str, *needles: str) -> str:
    """Exit 2 and exactly one stderr line ``error: ...`` containing every needle."""
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2, err
    assert len(lines) == 1, err
    assert lines[0].startswith("error: "), err
    assert "Traceback" not in err
    for n in needles:
        assert n in lines[0], lines[0]
    return lines[0]


def tree_digest(folder: Path) -> dict[str, str]:
    """SHA-256 of every file under ``folder`` (relative path -> digest)."""
    return {
        str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def edit_toml(path: Path, old: str, new: str) -> None:
    """Replace one exact line fragment in a TOML file (asserting it was there)."""
    text = path.read_text()
    assert old in text, (old, text)
    path.write_text(text.replace(old, new, 1))
