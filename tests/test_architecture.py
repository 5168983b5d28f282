"""The package's layers (CONTRIBUTING.md): imports run down, never up, and never in a circle.

Every ``import`` of ``i2ris_calib`` in ``src/i2ris_calib`` (at module level or inside a
function: a late import is still a dependency) is read with :mod:`ast`. A file belongs
to a *unit*: its subpackage (``fitting/fit.py`` -> ``fitting``) or, for a module at the
package root, the module (``config.py`` -> ``config``). ``model.py`` is the vocabulary
every layer speaks (``Signals``, ``Parameter``, the ``Model`` protocol; numpy only),
below the argument checks that test for ``Signals``.
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src" / "i2ris_calib"

#: bottom to top; a unit may import its own layer's units and lower ones, never higher
LAYERS: tuple[tuple[str, ...], ...] = (
    # plain types, no i2ris_calib import (but errors)
    ("errors", "interrupts", "session", "_display", "_atomic"),
    ("model",),  # Signals, Parameter, Model: what models and data share
    ("_validate",),  # argument checks of the public functions (one-line CalibError)
    ("hysteresis",),  # the models: kernels, GPI/EGPI, registry, starts, effects, the codec
    ("data",),  # synced recording -> motion-direction datasets, loading cycles
    ("fitting",),  # least squares, metrics, fit(model, data)
    # the stages built on a fit (diagnosis names effects; compensation inverts models,
    # sync fits one jointly with the clock, simulation renders the catalogue's effects)
    ("diagnosis", "compensation", "sync", "tracking", "simulation", "report"),
    ("config",),  # PipelineConfig: every stage's section
    ("io",),  # readers and writers of file formats
    ("commands",),  # stage runners, one module per command: open files, call a stage, write
    ("cli",),  # the command line
)
LAYER = {unit: i for i, units in enumerate(LAYERS) for unit in units}
#: the package face: loads the public names lazily; its ``__version__`` may be imported
FACE = "__init__"


def unit_of_file(path: Path) -> str:
    return path.relative_to(SRC).with_suffix("").parts[0]


def unit_of_module(module: str) -> str | None:
    """The unit of an ``i2ris_calib`` module name; None for another package."""
    parts = module.split(".")
    if parts[0] != "i2ris_calib":
        return None
    if len(parts) == 1:
        return FACE
    return parts[1]


def _is_module(name: str) -> bool:
    parts = name.split(".")
    if parts[0] != "i2ris_calib":
        return False
    where = SRC.joinpath(*parts[1:])
    return where.with_suffix(".py").is_file() or (where / "__init__.py").is_file()


def imported_modules(path: Path) -> list[tuple[int, str]]:
    """``(line, module)`` of every import in ``path``, relative ones resolved."""
    package = ["i2ris_calib", *path.relative_to(SRC).parent.parts]
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1]
                module = ".".join([*base, *([node.module] if node.module else [])])
            else:
                module = node.module or ""
            for alias in node.names:  # `from pkg import submodule` imports the submodule
                sub = f"{module}.{alias.name}"
                found.append((node.lineno, sub if _is_module(sub) else module))
    return found


def unit_imports() -> dict[tuple[str, str], list[str]]:
    """``{(importer unit, imported unit): ["file:line", ...]}`` between different units."""
    edges: dict[tuple[str, str], list[str]] = defaultdict(list)
    for path in sorted(SRC.rglob("*.py")):
        src = FACE if path == SRC / "__init__.py" else unit_of_file(path)
        for line, module in imported_modules(path):
            dst = unit_of_module(module)
            where = f"{path.relative_to(SRC.parent)}:{line}"
            if dst is not None and dst != src and where not in edges[src, dst]:
                edges[src, dst].append(where)
    return edges


def test_every_unit_has_a_layer():
    units = {unit_of_file(p) for p in SRC.rglob("*.py") if p != SRC / "__init__.py"}
    assert units - set(LAYER) == set(), "declare the new unit's layer in LAYERS"
    assert set(LAYER) - units == set(), "a declared unit no longer exists"


def test_no_import_runs_up_a_layer():
    upward = []
    for (src, dst), where in sorted(unit_imports().items()):
        if dst == FACE:  # only `from i2ris_calib import __version__` is allowed
            continue
        if src != FACE and LAYER[dst] > LAYER[src]:
            upward.append(f"{src} -> {dst} (layer {LAYER[src]} -> {LAYER[dst]}): {where}")
    assert not upward, "imports running up:\n" + "\n".join(upward)


def test_the_face_hands_out_only_the_version():
    """Inside the package, ``from i2ris_calib import ...`` takes ``__version__`` alone:
    the other public names load their modules lazily, and a stage must name its home."""
    bad = []
    for path in SRC.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module == "i2ris_calib":
                names = {a.name for a in node.names}
                if names - {"__version__"}:
                    bad.append(f"{path.relative_to(SRC.parent)}:{node.lineno} {names}")
    assert not bad, bad


def _cycles(edges: set[tuple[str, str]]) -> list[list[str]]:
    """Strongly connected components with more than one node (Tarjan)."""
    graph: dict[str, list[str]] = defaultdict(list)
    for a, b in edges:
        graph[a].append(b)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in list(graph):
        if v not in index:
            visit(v)
    return out


def test_no_circle_between_units():
    edges = unit_imports()
    cycles = _cycles({e for e in edges if FACE not in e})
    detail = [
        f"{c}: " + "; ".join(f"{a}->{b} {edges[a, b][0]}" for a in c for b in c if (a, b) in edges)
        for c in cycles
    ]
    assert not cycles, "\n".join(detail)


def test_no_circle_between_files():
    """Within a unit too: no two files import each other, directly or round a loop."""
    modules = {}
    for path in SRC.rglob("*.py"):
        rel = path.relative_to(SRC.parent).with_suffix("")
        name = ".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)
        modules[name] = path
    edges = set()
    for name, path in modules.items():
        for _, module in imported_modules(path):
            if module in modules and module != name and name != "i2ris_calib":
                edges.add((name, module))
    cycles = _cycles(edges)
    assert not cycles, cycles


#: Units that name no effect through the diagnosis: the effects, their kernels and the
#: model codec are the model layer's (``hysteresis/``), so reading or inverting a model
#: with effects, or rendering one, does not load the diagnosis stage.
WITHOUT_DIAGNOSIS = ("io", "compensation", "simulation")


def test_effects_are_read_from_the_model_layer():
    edges = unit_imports()
    found = [f"{src} -> diagnosis: {edges[src, 'diagnosis']}" for src in WITHOUT_DIAGNOSIS
             if (src, "diagnosis") in edges]  # fmt: skip
    assert not found, "import the effects from hysteresis/:\n" + "\n".join(found)


#: Files outside hysteresis/ that may still write kind names out (none since the
#: codec moved into the model layer, hysteresis/codec.py).
KIND_LITERAL_EXEMPT: set[str] = set()
#: At most this many other files outside hysteresis/ may write a kind name out (issue 34).
MAX_KIND_LITERAL_FILES = 1


def _docstrings(tree: ast.AST) -> set[int]:
    """The ids of the docstring constants of a module, its classes and its functions."""
    owners = (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)
    return {
        id(node.body[0].value)
        for node in ast.walk(tree)
        if isinstance(node, owners)
        and node.body
        and isinstance(node.body[0], ast.Expr)
        and isinstance(node.body[0].value, ast.Constant)
    }


def kind_literals(source: str) -> list[tuple[int, str]]:
    """(line, name) of every string constant in code that is a kind name (docstrings
    and comments are not code)."""
    from i2ris_calib.hysteresis.kinds import NAMES

    names = {k.kind for k in NAMES}
    tree = ast.parse(source)
    docs = _docstrings(tree)
    return sorted(
        (node.lineno, node.value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Constant) and node.value in names and id(node) not in docs
    )


def test_kind_names_are_written_out_in_the_names_table():
    """Kind names as code literals in at most one file outside hysteresis/: the others
    read them from hysteresis/kinds.py (its constants and columns) or the registry."""
    files = {}
    for path in sorted(SRC.rglob("*.py")):
        rel = path.relative_to(SRC).as_posix()
        if rel.startswith("hysteresis/") or rel in KIND_LITERAL_EXEMPT:
            continue
        found = kind_literals(path.read_text())
        if found:
            files[rel] = found
    assert len(files) <= MAX_KIND_LITERAL_FILES, f"kind names written out in {files}"


def test_the_kind_literal_counter_reads_code_not_docs():
    source = '''"""Module doc: "gpi"."""
def f(kind="egpi"):  # "agpi" in a comment
    """Starting model ``"gpi"``."""
    return "gpi_like", {"maxwell_slip": 1}
'''
    assert kind_literals(source) == [(2, "egpi"), (4, "maxwell_slip")]


@pytest.mark.parametrize(
    ("src", "dst"),
    [
        ("data", "fitting"),
        ("hysteresis", "data"),
        ("config", "io"),
        ("_validate", "data"),
        ("io", "commands"),
        ("model", "hysteresis"),
        ("_validate", "hysteresis"),
    ],
)
def test_the_checker_sees_an_upward_import(src, dst):
    """The rule is live: the imports this layering removed would be caught."""
    assert LAYER[dst] > LAYER[src]
