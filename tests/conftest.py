"""Shared fixtures. Stage-specific fixtures live in tests/<stage>/conftest.py."""

from __future__ import annotations

import os

import numpy as np
import pytest
from hypothesis import settings

# Property tests draw the same examples on every run (a fresh CI machine included): a
# failure is reproducible, never a matter of the day's draw. Explore new examples with
# HYPOTHESIS_PROFILE=explore.
settings.register_profile("ci", derandomize=True, print_blob=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded generator: every random choice in the tests is reproducible."""
    return np.random.default_rng(20261123)


# -- "N slow tests not run" at the end of a default run (pyproject: -m 'not slow') --------

_SLOW_NOT_RUN = pytest.StashKey[int]()


def pytest_configure(config: pytest.Config) -> None:
    config.stash[_SLOW_NOT_RUN] = 0


def pytest_deselected(items) -> None:
    if items:
        config = items[0].config
        config.stash[_SLOW_NOT_RUN] += sum(1 for i in items if i.get_closest_marker("slow"))


def pytest_sessionfinish(session: pytest.Session) -> None:
    """On a pytest-xdist worker: hand the count to the controller."""
    workeroutput = getattr(session.config, "workeroutput", None)
    if workeroutput is not None:
        workeroutput["slow_not_run"] = session.config.stash.get(_SLOW_NOT_RUN, 0)


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node, error) -> None:
    """pytest-xdist controller: every worker collects every test, so take one count."""
    n = getattr(node, "workeroutput", {}).get("slow_not_run", 0)
    node.config.stash[_SLOW_NOT_RUN] = max(node.config.stash.get(_SLOW_NOT_RUN, 0), n)


def pytest_terminal_summary(terminalreporter, config: pytest.Config) -> None:
    n = config.stash.get(_SLOW_NOT_RUN, 0)
    if n and not hasattr(config, "workerinput"):
        terminalreporter.write_line(
            f"{n} slow test{'s' if n != 1 else ''} not run; "
            "run them with: bash scripts/test.sh -m slow"
        )
