"""The stages of `make demo`, one after the other: seconds of each stage program per example, and the
workflow's time on 2 cores estimated from them.

    .venv/bin/python -m benchmarks.demo [--scenes ball coffee] [--out DIR] [--no-figures]

Each example (every folder of scenes/, or those named) runs pm-reconstruct, pm-simulate, pm-render and
pm-enhance into --out (a temporary folder by default), each with OMP_NUM_THREADS set to its workflow
rule's threads as Snakemake sets it. Per stage: wall seconds and CPU seconds (user + system of the
program). Wall seconds follow the machine's load (printed beside them); CPU seconds much less so. The
estimate places the jobs as `snakemake --cores 2` does (each scene's stages in order, a job starting when
its threads are free), each taking its CPU seconds over its threads: a lower bound for a stage that
keeps its threads busy only part of the time. Rows go to benchmarks/results/demo_stages.json (merged by
example) and RESULTS.md is regenerated.
"""
from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.figures import add_arguments, invocation, write_figures  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
CORES = 2
THREADS = {"reconstruct": 1, "simulate": 2, "render": 1, "enhance": 1}
"""Each stage's threads in workflow/rules/*.smk (enhance: the flow backend's)."""
COLUMNS = ["example", *(f"{stage} s (CPU s)" for stage in THREADS), "load"]


def stage_commands(scene: Path, out: Path) -> dict[str, list[str]]:
    """The four stage programs as the workflow's rules call them, writing into ``out``."""
    g, t, c = str(out / "gaussians.h5"), str(out / "trajectories.h5"), str(out / "coarse.h5")
    common = ["--scene", str(scene), "--device", "cpu"]
    return {"reconstruct": ["pm-reconstruct", *common, "--out", g],
            "simulate": ["pm-simulate", *common, "--gaussians", g, "--out", t],
            "render": ["pm-render", *common, "--gaussians", g, "--trajectories", t, "--out", c,
                       "--video", str(out / "coarse.mp4")],
            "enhance": ["pm-enhance", *common, "--coarse", c, "--gaussians", g, "--out", str(out / "video.mp4")]}


def run_stage(command: list[str], threads: int, log: Path) -> tuple[float, float]:
    """(wall s, CPU s) of one stage program, its output in ``log``; raises if it fails."""
    env = dict(os.environ, OMP_NUM_THREADS=str(threads))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    with open(log, "w") as out:
        status = subprocess.run([str(Path(sys.executable).parent / command[0]), *command[1:]], env=env,
                                stdout=out, stderr=subprocess.STDOUT).returncode
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if status != 0:
        raise RuntimeError(f"{command[0]} exited with {status}: see {log}")
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def estimate_makespan(cpu: dict[str, dict[str, float]], cores: int = CORES) -> float:
    """Seconds for every scene's stages in order on ``cores`` cores, each job taking its CPU seconds over its
    threads, started in scene order whenever its threads are free (list scheduling, as Snakemake's)."""
    pending = {name: list(THREADS) for name in cpu}
    running: list[tuple[float, str, int]] = []  # (end, scene, threads)
    now, free = 0.0, cores
    while pending or running:
        for name in list(pending):
            stage = pending[name][0]
            if THREADS[stage] <= free and all(scene != name for _, scene, _ in running):
                running.append((now + cpu[name][stage] / THREADS[stage], name, THREADS[stage]))
                free -= THREADS[stage]
                pending[name].pop(0)
                if not pending[name]:
                    del pending[name]
        running.sort()
        end, _, threads = running.pop(0)
        now, free = end, free + threads
    return now


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", nargs="*", help="example names (default: every folder of scenes/)")
    parser.add_argument("--out", type=Path, help="where the stages write, a folder per example, emptied first (default: a temporary folder)")
    add_arguments(parser)
    args = parser.parse_args()
    names = args.scenes or sorted(p.parent.name for p in (ROOT / "scenes").glob("*/scene.yaml"))
    rows, cpu = [], {}
    with tempfile.TemporaryDirectory(prefix="physmotion-demo-") as tmp:
        base = args.out or Path(tmp)
        for name in names:
            out = base / name
            shutil.rmtree(out, ignore_errors=True)  # the stages refuse to overwrite an earlier run's files
            out.mkdir(parents=True)
            times = {}
            for stage, command in stage_commands(ROOT / "scenes" / name / "scene.yaml", out).items():
                times[stage] = run_stage(command, THREADS[stage], out / f"{stage}.log")
                print(f"{name} {stage}: {times[stage][0]:.1f} s, CPU {times[stage][1]:.1f} s, "
                      f"load {os.getloadavg()[0]:.1f}", flush=True)
            cpu[name] = {stage: c for stage, (_, c) in times.items()}
            rows.append([name, *(f"{w:.1f} ({c:.1f})" for w, c in times.values()), f"{os.getloadavg()[0]:.1f}"])
    makespan = estimate_makespan(cpu)
    total_cpu = sum(sum(stages.values()) for stages in cpu.values())
    print(f"{total_cpu:.0f} CPU s in all; on {CORES} cores, as snakemake places the jobs: about {makespan:.0f} s")
    if args.no_figures:
        return
    write_figures(
        "demo_stages", "make demo's stages, one after the other",
        f"""Each example's four stage programs run one after the other as `make demo`'s workflow calls them
        (OMP_NUM_THREADS as each rule's threads: reconstruct, render and enhance 1, simulate 2): wall seconds
        and, in brackets, CPU seconds (user + system). The workflow's time on {CORES} cores is estimated from
        the CPU seconds by placing the jobs as Snakemake does, each taking its CPU seconds over its
        threads.""", invocation(__file__), COLUMNS, rows, merge_on=1,
        notes=[f"Examples {', '.join(names)}: {total_cpu:.0f} CPU s in all; estimated workflow time on {CORES} "
               f"cores {makespan:.0f} s, without the install and pm-plots."])


if __name__ == "__main__":
    main()
