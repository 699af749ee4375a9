"""Helpers for the backbone tests: a tiny scene folder per test, its refusals, and one workflow run of the tiny
scene per session (testing/tiny_scene.py)."""
import fcntl
import os
from pathlib import Path

import pytest

from schemas import InputError, load_scene
from testing.tiny_scene import write_scene
from testing.workflow import run_snakemake


def scene_refusal(folder: Path, scene: dict | None = None, text: str | None = None) -> InputError:
    """The InputError that loading the scene written by write_scene(folder, scene, text) raises."""
    with pytest.raises(InputError) as info:
        load_scene(write_scene(folder, scene, text))
    return info.value


@pytest.fixture
def scene_dir(tmp_path: Path) -> Path:
    folder = tmp_path / "scenes" / "tiny"
    write_scene(folder)
    return folder


def snakemake(workdir: Path, *args: str) -> str:
    """The workflow over workdir/scenes into workdir/results on 2 cores; its output (it must succeed)."""
    proc = run_snakemake(workdir / "scenes", workdir / "results", *args)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return proc.stdout + proc.stderr


@pytest.fixture(scope="session")
def tiny_run(tmp_path_factory) -> Path:
    """A folder holding one complete workflow run of the tiny scene (scenes/tiny, results/tiny), made once per
    test session: under pytest-xdist the first worker to ask makes it under a file lock in the session's own
    temporary folder, and the others wait for it. Tests only read it, or edit its scene in place and restore it
    (test_backbone_workflow.jobs_after_edit)."""
    base = tmp_path_factory.getbasetemp()
    shared = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base  # xdist: <session>/popen-gwN
    workdir, done = shared / "tiny_run", shared / "tiny_run.done"
    with open(shared / "tiny_run.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not done.exists():
            write_scene(workdir / "scenes" / "tiny")
            snakemake(workdir)
            done.touch()
    return workdir
