"""Every ``i2ris_calib`` name the benchmarks and scripts import exists.

The benchmarks are run by hand (``python benchmarks/run_all.py``), not by the default
test run, and many import inside a function: a name moved by a refactor (issue 34 moved
``max_input_rate`` to ``compensation.rate``) broke ``bench_compensate.py`` after 4
minutes of work and went unseen. This reads their imports with ``ast`` (late imports
inside functions too) and resolves each one, without running a benchmark.
"""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FILES = sorted([*ROOT.glob("benchmarks/*.py"), *ROOT.glob("scripts/*.py")])


def _imports(path: Path) -> list[tuple[int, str, str]]:
    """(line, module, name) of every ``from i2ris_calib... import name`` in ``path``."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("i2ris_calib"):
            out += [(node.lineno, node.module, a.name) for a in node.names]
    return out


def _missing(module: str, name: str) -> bool:
    """True when ``from module import name`` would fail."""
    mod = importlib.import_module(module)
    if hasattr(mod, name):
        return False
    try:
        importlib.import_module(f"{module}.{name}")
    except ImportError:
        return True
    return False


@pytest.mark.parametrize("path", FILES, ids=[f"{p.parent.name}/{p.name}" for p in FILES])
def test_every_imported_name_exists(path):
    bad = [f"{path.name}:{line}: {m}.{n}" for line, m, n in _imports(path) if _missing(m, n)]
    assert not bad, "imports of names that no longer exist: " + ", ".join(bad)


def test_the_check_finds_a_missing_name(tmp_path):
    """The check itself: a moved name is found (the case that broke bench_compensate)."""
    f = tmp_path / "b.py"
    f.write_text("def g():\n    from i2ris_calib.compensation.safety import max_input_rate\n")
    ((line, module, name),) = _imports(f)
    assert (line, module, name) == (2, "i2ris_calib.compensation.safety", "max_input_rate")
    assert _missing(module, name)
