"""The figures a benchmark measured: one JSON file per table in benchmarks/results/, from which
benchmarks/report.py writes benchmarks/RESULTS.md.

Each benchmark script ends with :func:`write_figures`, which records with the table the commit
(``git rev-parse --short HEAD``) and the machine it was measured on, then regenerates RESULTS.md.
A file holds::

    {"title": ..., "description": one paragraph, present tense, of what is measured,
     "command": the command that produces it, "commit": ..., "machine": ..., "measured": UTC date,
     "columns": [...], "rows": [[...], ...], "notes": [...]}
"""
from __future__ import annotations

import datetime
import json
import os
import platform
import shlex
import subprocess
import sys
from importlib import metadata
from pathlib import Path
from typing import Iterable, Sequence

ROOT = Path(__file__).resolve().parents[1]
RESULTS_DIR = ROOT / "benchmarks" / "results"
COMMIT_COLUMN = "commit"
"""The last column of a table whose rows come from several runs (``merge_on``): each row's commit."""
KEYS = ("title", "description", "command", "commit", "machine", "measured", "columns", "rows", "notes")


def commit() -> str:
    """The checkout's short commit, with ``+changes`` when tracked files differ from it."""
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown (not a git checkout)"
    changed = subprocess.run(["git", "diff", "--quiet", "HEAD", "--"], cwd=ROOT).returncode != 0
    return head + ("+changes" if changed else "")


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _version(package: str) -> str | None:
    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return None


def machine(device: str = "cpu") -> str:
    """The machine in words: CPU and core count, system, Python, torch and warp-lang, and the GPU
    when ``device`` is a CUDA device (read from torch if the benchmark imported it)."""
    parts = [f"{_cpu_model()}, {os.cpu_count()} cores", f"{platform.system()} {platform.release()}",
             f"Python {platform.python_version()}"]
    parts += [f"{name} {v}" for name, v in (("torch", _version("torch")), ("warp-lang", _version("warp-lang"))) if v]
    if str(device).startswith("cuda") and "torch" in sys.modules:
        torch = sys.modules["torch"]
        if torch.cuda.is_available():
            parts.insert(0, torch.cuda.get_device_name())
    try:
        parts.append(f"load average {os.getloadavg()[0]:.1f} at the end")
    except OSError:
        pass
    return "; ".join(parts)


def invocation(script: str) -> str:
    """The command that ran ``script`` (a benchmark's ``__file__``), as a module from the repository root."""
    return shlex.join(["python", "-m", f"benchmarks.{Path(script).stem}",
                       *(a for a in sys.argv[1:] if a != "--no-figures")])


def add_arguments(parser) -> None:
    """The option every benchmark script shares: ``--no-figures`` leaves benchmarks/results alone."""
    parser.add_argument("--no-figures", action="store_true",
                        help="print the tables only; do not write benchmarks/results/*.json and RESULTS.md")


def read_figures(path: Path) -> dict:
    """One figures file, checked to hold every key, rows as wide as the columns."""
    data = json.loads(Path(path).read_text())
    missing = [k for k in KEYS if k not in data]
    if missing:
        raise ValueError(f"{path}: missing {', '.join(missing)}")
    for row in data["rows"]:
        if len(row) != len(data["columns"]):
            raise ValueError(f"{path}: row {row} has {len(row)} cells for {len(data['columns'])} columns")
    return data


def write_figures(name: str, title: str, description: str, command: str, columns: Sequence[str],
                  rows: Iterable[Sequence], *, notes: Sequence[str] = (), device: str = "cpu", merge_on: int = 0,
                  results_dir: Path = RESULTS_DIR, report: bool = True, measured_commit: str = "") -> Path:
    """Write benchmarks/results/<name>.json and regenerate RESULTS.md from every such file.

    Cells are written as strings (format numbers before). ``merge_on`` > 0: the table collects rows
    from several runs (one scene or model per run): rows already in the file whose first ``merge_on``
    cells match no new row's are kept with the file's notes, and a last column names each row's commit.
    ``measured_commit``: the commit measured, where it is not the checkout's (a clone made earlier).
    """
    columns, rows = [str(c) for c in columns], [[str(c) for c in row] for row in rows]
    notes = [" ".join(str(n).split()) for n in notes]
    head = measured_commit or commit()
    path = Path(results_dir) / f"{name}.json"
    if merge_on:
        columns, rows = columns + [COMMIT_COLUMN], [row + [head] for row in rows]
        old = json.loads(path.read_text()) if path.exists() else {}
        if old.get("columns") == columns:
            new = {tuple(row[:merge_on]): row for row in rows}
            merged = [new.pop(tuple(row[:merge_on]), row) for row in old["rows"]]  # re-measured rows in place
            if len(merged) > len(rows) - len(new):  # rows of other runs kept, and the notes on them
                notes = [*old["notes"], *(n for n in notes if n not in old["notes"])]
            rows = merged + list(new.values())
    data = {"title": title, "description": " ".join(description.split()), "command": command, "commit": head,
            "machine": machine(device),
            "measured": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
            "columns": columns, "rows": rows, "notes": notes}
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=1, ensure_ascii=False) + "\n")
    print(f"figures written to {path}", file=sys.stderr)
    if report and Path(results_dir).resolve() == RESULTS_DIR.resolve():
        from benchmarks.report import write_report  # noqa: PLC0415 (report imports this module)

        print(f"{write_report()} regenerated", file=sys.stderr)
    return path
