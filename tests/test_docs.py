"""Every ```python block of README.md and docs/*.md runs as written.

A page's blocks run in order in one namespace, as a reader would paste them into one
notebook: a ``>>>`` block as a doctest (ELLIPSIS), any other block with ``exec``. The
working folder is the repository (the examples read ``sample_data/``), except for a
page that reads the README demo's outputs (``runs/sample/...``): it runs in a
temporary folder where the demo's command has run once per test session.

A page whose blocks diagnose (10-20 s a dataset) or need the demo is ``slow``; its
blocks before the first such block still run in the default (fast) suite.
"""

from __future__ import annotations

import doctest
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
FENCE = re.compile(r"^```python\n(.*?)^```", re.S | re.M)
DEMO = "runs/sample/"  # what scripts/demo.sh writes (README: "The two commands")
#: a block that calls one of these, or reads the demo's outputs, takes more than seconds
SLOW = ("diagnose(", "diagnose_from_starts(", DEMO)


def python_blocks(page: Path) -> list[tuple[int, str]]:
    """``(line, code)`` of the page's ```python blocks, in order."""
    text = page.read_text()
    return [(text.count("\n", 0, m.start()) + 2, m.group(1)) for m in FENCE.finditer(text)]


def is_slow(code: str) -> bool:
    return any(s in code for s in SLOW)


def run_block(page: Path, line: int, code: str, ns: dict) -> None:
    name = f"{page.relative_to(ROOT)}:{line}"
    if code.lstrip().startswith(">>>"):
        test = doctest.DocTestParser().get_doctest(code, ns, name, str(page), line - 1)
        runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
        runner.run(test, clear_globs=False)
        ns.update(test.globs)
        assert runner.failures == 0, f"{name}: {runner.failures} doctest example(s) failed"
    else:
        exec(compile(code, name, "exec"), ns)


@pytest.fixture(scope="session")
def demo_folder(tmp_path_factory) -> Path:
    """A folder where the README demo's pipeline command has run on sample_data/."""
    cwd = tmp_path_factory.mktemp("demo")
    cmd = [sys.executable, "-m", "i2ris_calib.cli", "run", str(ROOT / "sample_data" / "session")]
    subprocess.run([*cmd, "--out", DEMO.rstrip("/")], cwd=cwd, check=True, capture_output=True)
    return cwd


CASES = []
for _page in PAGES:
    _blocks = python_blocks(_page)
    if not _blocks:
        continue
    _first_slow = next((i for i, (_, c) in enumerate(_blocks) if is_slow(c)), len(_blocks))
    _id = str(_page.relative_to(ROOT))
    if _first_slow > 0:
        CASES.append(pytest.param(_page, _first_slow, id=f"{_id}[fast]"))
    if _first_slow < len(_blocks):
        CASES.append(pytest.param(_page, len(_blocks), id=f"{_id}[all]", marks=pytest.mark.slow))


@pytest.mark.parametrize(("page", "n_blocks"), CASES)
def test_python_blocks_run(page, n_blocks, request, monkeypatch):
    blocks = python_blocks(page)[:n_blocks]
    needs_demo = any(DEMO in code for _, code in blocks)
    monkeypatch.chdir(request.getfixturevalue("demo_folder") if needs_demo else ROOT)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    ns: dict = {"__name__": "__main__"}
    for line, code in blocks:
        run_block(page, line, code, ns)


def test_every_block_is_tested():
    """Each page with Python blocks is in a case, and the count matches the pages."""
    n = sum(len(python_blocks(p)) for p in PAGES)
    assert n >= 6
    covered = {c.values[0] for c in CASES}
    assert covered == {p for p in PAGES if python_blocks(p)}


# --------------------------------------------------------------- the README's commands


def _cli_help(*command: str) -> str:
    out = subprocess.run(
        [sys.executable, "-m", "i2ris_calib.cli", *command, "--help"],
        capture_output=True, text=True, env={"COLUMNS": "200", "TERM": "dumb", "NO_COLOR": "1",
                                             "PATH": "/usr/bin:/bin"},
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    return out.stdout


def _invocations(text: str) -> list[list[str]]:
    """The ``i2ris-calib CMD ...`` calls written in ``text`` (code spans and blocks)."""
    found = []
    for span in re.findall(r"`(i2ris-calib [^`]+)`", text) + re.findall(
        r"^(?:\.venv/bin/)?(i2ris-calib .+?)(?:\s+#.*)?$", text, re.M
    ):
        words = shlex.split(span.replace("...", ""))
        found.append(words[1:])
    return found


def test_readme_invocations_name_existing_commands_and_options():
    """Every ``i2ris-calib CMD --option`` the README shows is a command and option that
    ``i2ris-calib CMD --help`` lists."""
    text = (ROOT / "README.md").read_text()
    calls = _invocations(text)
    assert len(calls) >= 10
    helps: dict[str, str] = {}
    for words in calls:
        cmd = words[0]
        if cmd.startswith("-"):  # `i2ris-calib --debug ...`
            assert cmd in _cli_help(), cmd
            continue
        helps.setdefault(cmd, _cli_help(cmd))
        for w in words[1:]:
            if w.startswith("--"):
                opt = w.split("=")[0].strip("[]")
                assert re.search(rf"(?<![\w-]){re.escape(opt)}(?![\w-])", helps[cmd]), (cmd, opt)


def test_readme_scripts_exist():
    """The README's two commands name scripts the repository has."""
    text = (ROOT / "README.md").read_text()
    scripts = re.findall(r"^bash (\S+)", text, re.M)
    assert scripts == ["scripts/demo.sh", "scripts/test.sh"]
    assert all((ROOT / s).is_file() for s in scripts)


# --------------------------------------------------------------- relative links


LINK_PAGES = [ROOT / "README.md", ROOT / "CONTRIBUTING.md", *sorted((ROOT / "docs").rglob("*.md"))]
#: ``[text](target)``; the target ends at the first space or ``)`` (no titles are used)
LINK = re.compile(r"(?<!!)\[[^\]\n]*\]\(([^)\s]+)\)|!\[[^\]\n]*\]\(([^)\s]+)\)")
FENCED = re.compile(r"^(```|~~~).*?^\1", re.S | re.M)


def heading_anchors(text: str) -> set[str]:
    """GitHub's anchors of a page's Markdown headings (``-1``, ``-2`` for repeats)."""
    seen: dict[str, int] = {}
    anchors = set()
    for title in re.findall(r"^#{1,6}\s+(.+?)\s*#*\s*$", FENCED.sub("", text), re.M):
        title = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", title)  # a link's text only
        slug = re.sub(r"[^\w\- ]", "", title.strip().lower().replace("`", "")).replace(" ", "-")
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        anchors.add(slug if n == 0 else f"{slug}-{n}")
    return anchors


def relative_links(page: Path) -> list[str]:
    """The relative link targets of ``page`` outside code blocks and code spans."""
    text = re.sub(r"`[^`\n]*`", "", FENCED.sub("", page.read_text()))
    targets = [a or b for a, b in LINK.findall(text)]
    return [t for t in targets if not re.match(r"[a-z][a-z0-9+.-]*:", t)]  # http:, mailto:


def broken_links(pages=LINK_PAGES) -> list[str]:
    anchors: dict[Path, set[str]] = {}
    bad = []
    for page in pages:
        for target in relative_links(page):
            path, _, anchor = target.partition("#")
            dest = (page.parent / path).resolve() if path else page
            where = f"{page.relative_to(ROOT)}: ({target})"
            if not dest.exists():
                bad.append(f"{where}: no such file")
            elif anchor and dest.suffix == ".md":
                if dest not in anchors:
                    anchors[dest] = heading_anchors(dest.read_text())
                if anchor not in anchors[dest]:
                    bad.append(f"{where}: no heading #{anchor} in {dest.relative_to(ROOT)}")
    return bad


def test_heading_anchors_follow_github():
    text = "# Starting model (`--start auto`)\n## In the pipeline (`[run] diagnose = true`)\n## A\n## A\n"
    assert heading_anchors(text) == {"starting-model---start-auto",
                                     "in-the-pipeline-run-diagnose--true", "a", "a-1"}  # fmt: skip


def test_relative_links_resolve():
    """Every relative link in README.md, CONTRIBUTING.md and docs/**/*.md names an existing
    file and, with ``#anchor``, a heading of that page."""
    assert len(LINK_PAGES) > 10
    bad = broken_links()
    assert not bad, "\n".join(bad)
