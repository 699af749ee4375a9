"""The example workflow (workflow/Snakefile) as the tests run it, its command line written once.

snakemake_command  the command line over a folder of scene folders into a results folder, on the CPU
run_snakemake      that command run to its end, its output captured
ENV                the environment of the README's command, .venv/bin/snakemake with the venv not activated
with_programs      an environment with the venv's programs first on PATH
"""
from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterable, Mapping
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
# As the README runs it (.venv/bin/snakemake, venv not activated): the stage programs are not on PATH.
ENV = {**os.environ, "PATH": os.pathsep.join(p for p in os.environ["PATH"].split(os.pathsep)
                                             if Path(p).resolve() != BIN.resolve())}


def with_programs(env: Mapping[str, str]) -> dict[str, str]:
    """``env`` with the venv's programs (snakemake, pm-*) first on PATH."""
    return {**env, "PATH": f"{BIN}{os.pathsep}{env['PATH']}"}


def snakemake_command(scenes: Path, results: Path, *args: str, cores: int | None = 2, profile: str | None = None,
                      config: Iterable[str] = ()) -> list[str]:
    """The workflow's command line over the scene folders in ``scenes`` into ``results``, every stage on the
    CPU: ``cores`` local cores (None: none named, as a profile that submits jobs wants), the profile
    workflow/profiles/``profile`` where one is named, ``config`` more --config KEY=VALUE items, ``args`` more
    options."""
    command = [str(BIN / "snakemake"), "--snakefile", str(REPO / "workflow" / "Snakefile")]
    if cores is not None:
        command += ["--cores", str(cores)]
    if profile is not None:
        command += ["--profile", str(REPO / "workflow" / "profiles" / profile)]
    return [*command, "--config", f"scenes_dir={scenes}", f"results_dir={results}", "device=cpu", *config, *args]


def run_snakemake(scenes: Path, results: Path, *args: str, cores: int | None = 2, profile: str | None = None,
                  config: Iterable[str] = (), env: dict[str, str] = ENV, **options) -> subprocess.CompletedProcess:
    """snakemake_command run to its end from the folder that holds ``scenes``, in ``env``, its output captured
    as text; ``options`` go to subprocess.run (timeout, preexec_fn)."""
    return subprocess.run(snakemake_command(scenes, results, *args, cores=cores, profile=profile, config=config),
                          cwd=Path(scenes).parent, env=env, capture_output=True, text=True, **options)
