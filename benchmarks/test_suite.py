"""The test suite's time on a clean clone: `make test` in a fresh `git clone` of this checkout's commit.

    python -m benchmarks.test_suite                       # clone, install a venv there, make test
    python -m benchmarks.test_suite --venv .venv          # the suite only, with an installed venv
    python -m benchmarks.test_suite --venv .venv tests/splat   # a part of the suite (not written
                                                              # to results unless --write-part)

The clone runs the Makefile's own test command (one pytest-xdist worker per core), with
PYTEST_ARGS adding a JUnit report, from which come the counts, the pytest time and the slowest
tests (setup, call and teardown together). Without --venv the time includes the venv's install
(torch and the project's extras from PyPI). With --venv that venv is used as installed: its
editable install points at its own checkout, so programs the tests start as subprocesses
(pm-simulate, snakemake) run that checkout's code, which takes the same time when it is the same
commit. --cold-kernel-cache gives Warp an empty kernel cache, so the kernels' compile time counts.

Writes benchmarks/results/test_suite.json (the whole suite) and test_suite_slowest.json (its
slowest tests), then RESULTS.md.
"""
from __future__ import annotations

import argparse
import os
import shlex
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

if __package__ in (None, ""):  # run as a script: the repository, not benchmarks/, on the path
    sys.path[0] = str(Path(__file__).resolve().parents[1])

from benchmarks.figures import ROOT, add_arguments, commit, invocation, write_figures  # noqa: E402

SLOWEST = 25
"""Tests listed in the slowest-tests table."""


def minutes(seconds: float) -> str:
    return f"{int(seconds // 60)} min {seconds % 60:.0f} s"


def junit_cases(report: Path) -> tuple[dict, list[tuple[str, float, str]]]:
    """(counts: tests, failures, errors, skipped and pytest's time in s; [(test id, s, outcome)]) of a
    pytest JUnit XML report."""
    root = ET.parse(report).getroot()
    suite = root if root.tag == "testsuite" else root.find("testsuite")
    counts = {k: int(suite.get(k, 0)) for k in ("tests", "failures", "errors", "skipped")}
    counts["time"] = float(suite.get("time", 0.0))
    cases = []
    for case in suite.iter("testcase"):
        outcome = next((child.tag for child in case if child.tag in ("failure", "error", "skipped")), "passed")
        module = case.get("classname", "").replace(".", "/")
        cases.append((f"{module}.py::{case.get('name')}", float(case.get("time", 0.0)), outcome))
    return counts, cases


def run_suite(clone: Path, venv: Path | None, pytest_args: list[str], env: dict) -> tuple[float, Path, int]:
    """`make test` in the clone with a JUnit report: (wall s, the report, make's exit status)."""
    report = clone / "junit.xml"
    extra = shlex.join(["--junitxml", str(report), "-p", "no:cacheprovider", *pytest_args])
    command = ["make", "test", f"PYTEST_ARGS={extra}"]
    if venv is not None:  # the venv as installed: make neither creates nor reinstalls it
        command += [f"VENV={venv}", "-o", f"{venv}/.installed"]
    started = time.perf_counter()
    status = subprocess.run(command, cwd=clone, env=env).returncode
    return time.perf_counter() - started, report, status


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("paths", nargs="*", help="test paths (default: the whole suite, pytest's testpaths)")
    parser.add_argument("--venv", type=Path, help="an installed venv to run the suite with (default: make installs "
                        "one in the clone, which counts in the time)")
    parser.add_argument("--cold-kernel-cache", action="store_true", help="an empty Warp kernel cache")
    parser.add_argument("--write-part", action="store_true", help="write the figures of a part of the suite too")
    add_arguments(parser)
    args = parser.parse_args()
    venv = args.venv.resolve() if args.venv else None
    head = commit()
    if head.endswith("+changes"):
        print(f"note: the clone holds {head.split('+')[0]}, not the checkout's uncommitted changes", file=sys.stderr)

    with tempfile.TemporaryDirectory(prefix="physmotion-suite-") as tmp:
        clone = Path(tmp) / "physmotion"
        subprocess.run(["git", "clone", "--quiet", str(ROOT), str(clone)], check=True)
        env = dict(os.environ)
        if args.cold_kernel_cache:
            env["WARP_CACHE_PATH"] = str(Path(tmp) / "warp-cache")
        wall, report, status = run_suite(clone, venv, args.paths, env)
        if not report.exists():
            sys.exit(f"make test wrote no JUnit report (exit status {status})")
        counts, cases = junit_cases(report)

    passed = counts["tests"] - counts["failures"] - counts["errors"] - counts["skipped"]
    busy = sum(seconds for _, seconds, _ in cases)
    workers = os.cpu_count() or 1  # make test: pytest -n auto
    print(f"{passed} passed, {counts['skipped']} skipped, {counts['failures']} failed, {counts['errors']} errors; "
          f"pytest {minutes(counts['time'])}, make test {minutes(wall)} (exit status {status}); "
          f"the tests' times sum to {minutes(busy)}")
    slowest = sorted(cases, key=lambda c: -c[1])[:SLOWEST]
    for name, seconds, outcome in slowest:
        print(f"{seconds:8.1f} s  {name}  {outcome}")
    if args.no_figures or (args.paths and not args.write_part):
        return
    part = f" ({' '.join(args.paths)} only)" if args.paths else ""
    setup = "an installed venv" if venv else "the venv's install included"
    cache = "a cold Warp kernel cache" if args.cold_kernel_cache else "Warp's kernel cache as it was"
    command = invocation(__file__)
    write_figures(
        "test_suite", "The test suite on a clean clone" + part,
        "`make test` on a fresh `git clone` (one pytest-xdist worker per core): tests passed, skipped and failed, "
        "the pytest run and the whole make command, in minutes.",
        command, ["passed", "skipped", "failed", "pytest", "make test"],
        [[passed, counts["skipped"], counts["failures"] + counts["errors"], minutes(counts["time"]), minutes(wall)]],
        notes=[f"With {setup} and {cache}.",
               f"The tests' own times (setup, call and teardown, on all workers) sum to {minutes(busy)}: "
               f"{100 * busy / (workers * counts['time']):.0f} % of {workers} workers' pytest time; the rest is the "
               "workers' start and collection, and a worker waiting for the other's last test."],
        measured_commit=head.split("+")[0])
    write_figures(
        "test_suite_slowest", f"The {SLOWEST} slowest tests" + part,
        "The tests of the run above that took longest, setup, call and teardown together (on a worker that shares "
        "the CPU with the other), in seconds.",
        command, ["test", "s", "outcome"], [[name, f"{seconds:.1f}", outcome] for name, seconds, outcome in slowest],
        measured_commit=head.split("+")[0])


if __name__ == "__main__":
    main()
