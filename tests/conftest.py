"""How `make test` spreads the suite over pytest-xdist's workers (one per core).

A module whose tests share a module- or class-scoped fixture (a simulated scene, a reconstruction,
a workflow run) is one unit of work, so its fixture is built once, on one worker. Every other test
is a unit of its own, so the two cores stay busy to the end. xdist's own `--dist loadgroup` would
need an `xdist_group` mark on each of those modules, and on pytest 9 it distributes marked tests
as if unmarked (pytest-dev/pytest-xdist#1386); `--dist loadfile` keeps every module whole, the
long modules without shared fixtures too.
"""
from __future__ import annotations

import re
from functools import lru_cache
from pathlib import Path

import pytest

SHARED_FIXTURE = re.compile(r"""scope\s*=\s*["'](module|class|package)["']""")


@lru_cache(maxsize=None)
def shares_fixtures(module: Path) -> bool:
    """Whether a test module, or a conftest.py beside or above it under tests/, defines a fixture that
    outlives one test (scope module, class or package)."""
    sources = [module] + [folder / "conftest.py" for folder in module.parents
                          if folder.name and (folder / "conftest.py").is_file() and "tests" in folder.parts]
    return any(SHARED_FIXTURE.search(path.read_text(errors="replace")) for path in sources if path.is_file())


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """Under `-n` (xdist's default `--dist load`), a scheduler whose unit of work is a module that
    shares fixtures, else one test; another `--dist` given on the command line is left to xdist."""
    if config.getvalue("dist") != "load":
        return None
    from xdist.scheduler import LoadScopeScheduling  # noqa: PLC0415 (only where xdist runs the suite)

    class SharedFixtureScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            module = nodeid.split("::", 1)[0]
            return module if shares_fixtures(config.rootpath / module) else nodeid

    return SharedFixtureScheduling(config, log)
