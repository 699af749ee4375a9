"""How `make test` spreads the suite over pytest-xdist's workers (one per core).

A module whose tests share a module- or class-scoped fixture (a simulated scene, a reconstruction,
a workflow run) is one unit of work, so its fixture is built once, on one worker. Every other test
is a unit of its own, so the two cores stay busy to the end. The longest units start first, so the
run does not end on one long test while the other worker waits: each test of the last measured run's
slowest (benchmarks/results/test_suite_slowest.json, written by `python -m benchmarks.test_suite`)
counts its seconds, every other test one second. xdist's own `--dist loadgroup` would need an
`xdist_group` mark on each of those modules, and on pytest 9 it distributes marked tests as if
unmarked (pytest-dev/pytest-xdist#1386); `--dist loadfile` keeps every module whole, the
long modules without shared fixtures too.
"""
from __future__ import annotations

import json
import re
from collections import OrderedDict
from functools import lru_cache
from pathlib import Path

import pytest

SHARED_FIXTURE = re.compile(r"""scope\s*=\s*["'](module|class|package)["']""")
SLOWEST = Path(__file__).resolve().parents[1] / "benchmarks" / "results" / "test_suite_slowest.json"


def measured_seconds() -> dict[str, float]:
    """Test id -> seconds of the slowest tests of the last measured suite run (empty where there is none)."""
    try:
        return {row[0]: float(row[1]) for row in json.loads(SLOWEST.read_text())["rows"]}
    except (OSError, ValueError, KeyError, IndexError):
        return {}


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
        ordered = False

        def _split_scope(self, nodeid: str) -> str:
            module = nodeid.split("::", 1)[0]
            return module if shares_fixtures(config.rootpath / module) else nodeid

        def _assign_work_unit(self, node) -> None:
            if not self.ordered:  # the first assignment: the queue holds every unit
                seconds = measured_seconds()
                expected = {scope: sum(seconds.get(test, 1.0) for test in tests)
                            for scope, tests in self.workqueue.items()}
                self.workqueue = OrderedDict(sorted(self.workqueue.items(), key=lambda unit: -expected[unit[0]]))
                self.ordered = True
            super()._assign_work_unit(node)

    return SharedFixtureScheduling(config, log)
