"""The example workflow through a real one-node SLURM cluster (slurm-wlm on loopback, started and
stopped here) with the SLURM profile: the same videos as a local run (the session's run of the tiny
scene, tests/backbone/conftest.tiny_run, which the workflow tests read too)."""
import numpy as np
import pytest

from schemas.video import read_video
from testing.tiny_scene import write_scene
from testing.workflow import run_snakemake, with_programs

from ..backbone.conftest import tiny_run  # noqa: F401 (a fixture)
from .slurm_cluster import slurm_cluster, why_unavailable

# This cluster has no accounting database (sacct cannot answer) and one user with no account.
SLURM_ARGS = ["--slurm-status-command", "squeue", "--slurm-no-account", "--slurm-init-seconds-before-status-checks",
              "1", "--slurm-keep-successful-logs", "--latency-wait", "5"]


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    reason = why_unavailable()
    if reason:
        pytest.skip(f"no single-node SLURM on this machine: {reason}")
    with slurm_cluster(tmp_path_factory.mktemp("slurm")) as env:
        yield env


@pytest.mark.slow
def test_slurm_run_makes_the_same_videos_as_a_local_run(cluster, tmp_path, request):
    write_scene(tmp_path / "slurm" / "scenes" / "tiny")
    proc = run_snakemake(tmp_path / "slurm" / "scenes", tmp_path / "slurm" / "results", *SLURM_ARGS, cores=None,
                         profile="slurm", env=with_programs(cluster), timeout=900)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    # asked for only now: under xdist the other worker is likely making it meanwhile, so this one need not wait
    local_run = request.getfixturevalue("tiny_run")
    # Every stage ran as its own SLURM job (the executor keeps one log folder per rule).
    slurm_logs = tmp_path / "slurm" / ".snakemake" / "slurm_logs"
    assert {p.name for p in slurm_logs.iterdir()} >= {f"rule_{r}" for r in ("reconstruct", "simulate", "render",
                                                                             "enhance")}
    for name in ("coarse.mp4", "video.mp4"):
        local, _, _ = read_video(local_run / "results" / "tiny" / name)
        slurm, _, _ = read_video(tmp_path / "slurm" / "results" / "tiny" / name)
        assert local.shape == slurm.shape and np.array_equal(local, slurm), name
