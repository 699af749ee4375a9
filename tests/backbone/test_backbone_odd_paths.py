"""The workflow from folders with spaces, brackets, dots and unicode in their names; the same bytes from a
second run on one core; and a rerun that recovers after the disk was full."""
import os
import subprocess
from pathlib import Path

import pytest

from testing.tiny_scene import write_scene
from testing.workflow import ENV, run_snakemake

from .mounts import resize, tmpfs

ODD_SCENE = "my ball (v2) [ü].x"
OUTPUTS = ("gaussians.h5", "trajectories.h5", "setup.png", "coarse.h5", "coarse.mp4", "video.mp4",
           "contact_sheet.png")


def run_workflow(scenes: Path, results: Path, one_core: bool = False) -> subprocess.CompletedProcess:
    """Snakemake over ``scenes`` into ``results``; with ``one_core`` every job is pinned to one CPU and one
    thread, so that anything that follows the thread count or the load would come out different."""
    env = {**ENV, **({"OMP_NUM_THREADS": "1"} if one_core else {})}
    pin = (lambda: os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})) if one_core else None
    return run_snakemake(scenes, results, cores=1 if one_core else 2, env=env, preexec_fn=pin)


@pytest.fixture(scope="module")
def odd_run(tmp_path_factory):
    """The tiny scene in an oddly named folder, run into an oddly named results folder."""
    top = tmp_path_factory.mktemp("work") / "a folder (with) [brackets] and ünïcode.d"
    scenes = top / "my scenes"
    write_scene(scenes / ODD_SCENE)
    proc = run_workflow(scenes, top / "res ults")
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return top


@pytest.mark.slow
def test_odd_folder_names_run_end_to_end(odd_run):
    out = odd_run / "res ults" / ODD_SCENE
    assert all((out / name).is_file() for name in OUTPUTS)
    assert sorted(p.name for p in (odd_run / "res ults").iterdir()) == [ODD_SCENE]  # no stray 'my'


@pytest.mark.slow
def test_same_inputs_give_the_same_bytes_on_one_core(odd_run):
    """Every output of a second run, each job pinned to one core with one thread, is byte for byte the first's."""
    proc = run_workflow(odd_run / "my scenes", odd_run / "again", one_core=True)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    for name in OUTPUTS:
        first = (odd_run / "res ults" / ODD_SCENE / name).read_bytes()
        assert (odd_run / "again" / ODD_SCENE / name).read_bytes() == first, name


@pytest.mark.slow
def test_a_rerun_recovers_after_the_disk_was_full(odd_run, tmp_path):
    with tmpfs(tmp_path / "results", "200k") as results:
        proc = run_workflow(odd_run / "my scenes", results)
        assert proc.returncode != 0
        logs = "".join(p.read_text() for p in results.glob("*/logs/*.log"))
        assert "No space left on device" in logs and "Traceback" not in logs
        assert not list(results.rglob(".*partial*"))
        resize(results, "20m")  # space freed
        proc = run_workflow(odd_run / "my scenes", results)
        assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
        for name in OUTPUTS:
            assert (results / ODD_SCENE / name).read_bytes() == (odd_run / "res ults" / ODD_SCENE / name).read_bytes()
