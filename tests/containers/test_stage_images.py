"""The stage images, built and run (opt-in: PHYSMOTION_TEST_IMAGES=1, see stage_images.py): each holds
only its stage's extra with its program as entry point, and the tiny scene run through them, stage by
stage as the workflow's rules run, gives the same artifacts and videos as the local environment."""
import json
import os
import subprocess
from importlib.metadata import version
from pathlib import Path

import h5py
import numpy as np
import pytest

from schemas.video import read_video
from testing.tiny_scene import write_scene
from testing.workflow import with_programs

from .stage_images import build_images, docker, run_in_image, why_unavailable

TAG = version("physmotion")
S, R = "scenes/tiny/scene.yaml", "results/tiny"
# The workflow's commands for one scene, grouped by the image their rules name.
CHAIN = {
    "reconstruct": [["pm-reconstruct", "--scene", S, "--out", f"{R}/gaussians.h5"]],
    "simulate": [["pm-simulate", "--scene", S, "--gaussians", f"{R}/gaussians.h5", "--out", f"{R}/trajectories.h5"]],
    "render": [["pm-render", "--scene", S, "--gaussians", f"{R}/gaussians.h5", "--trajectories",
                f"{R}/trajectories.h5", "--out", f"{R}/coarse.h5", "--video", f"{R}/coarse.mp4"]],
    "enhance": [["pm-enhance", "--scene", S, "--coarse", f"{R}/coarse.h5", "--gaussians", f"{R}/gaussians.h5",
                 "--out", f"{R}/video.mp4"]],
}
# Each image's programs: every image has the scripts of all six (one pyproject), but only these run.
PROGRAMS = {"reconstruct": ["pm-reconstruct"], "simulate": ["pm-simulate"], "render": ["pm-render"],
            "enhance": ["pm-enhance", "pm-lora", "pm-invert"]}
# Which stage packages and whether diffusers the image holds, as one JSON line.
PROBE = ("import importlib.util as u, json; print(json.dumps({'stages': [s for s in %r if u.find_spec('stages.' + s)], "
         "'diffusers': u.find_spec('diffusers') is not None}))" % sorted(PROGRAMS))


@pytest.fixture(scope="module")
def images():
    reason = why_unavailable()
    if reason:
        pytest.skip(f"stage images not built here: {reason}")
    build_images()


def with_device(cmd: list[str]) -> list[str]:
    return cmd + ["--device", "cpu"]


@pytest.mark.slow
@pytest.mark.parametrize("stage", sorted(PROGRAMS))
def test_image_holds_its_stage_only(images, stage, tmp_path):
    image = f"physmotion/{stage}:{TAG}"
    inspect = docker("image", "inspect", "--format", "{{json .Config.Entrypoint}}", image)
    assert json.loads(inspect.stdout) == [f"pm-{stage}"], inspect.stdout + inspect.stderr
    helps = [[program, "--help"] for program in PROGRAMS[stage]]
    proc = run_in_image(image, tmp_path, helps + [["python", "-c", PROBE]])
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert all(f"usage: {program}" in proc.stdout for program in PROGRAMS[stage]), proc.stdout[-2000:]
    held = json.loads(proc.stdout.strip().splitlines()[-1])
    assert held["stages"] == [stage], "an image holds its own stage's code only"
    assert held["diffusers"] == (stage in ("enhance", "reconstruct")), \
        "only the enhance and reconstruct (prior lgm) images may hold diffusers"


def datasets(path: Path) -> dict[str, np.ndarray]:
    with h5py.File(path) as f:
        found = {}
        f.visititems(lambda name, obj: found.update({name: np.asarray(obj[()])})
                     if isinstance(obj, h5py.Dataset) else None)
    return found


@pytest.mark.slow
def test_images_make_the_same_artifacts_and_videos_as_the_local_environment(images, tmp_path):
    local, contained = tmp_path / "local", tmp_path / "docker"
    for workdir in (local, contained):
        write_scene(workdir / "scenes" / "tiny")
        (workdir / R).mkdir(parents=True)
    env = with_programs(os.environ)
    for stage, commands in CHAIN.items():
        for cmd in commands:
            proc = subprocess.run(with_device(cmd), cwd=local, env=env, capture_output=True, text=True)
            assert proc.returncode == 0, proc.stderr[-2000:]
        proc = run_in_image(f"physmotion/{stage}:{TAG}", contained, [with_device(cmd) for cmd in commands])
        assert proc.returncode == 0, proc.stderr[-2000:]
    for name in ("gaussians.h5", "trajectories.h5", "coarse.h5"):
        ours, theirs = datasets(local / R / name), datasets(contained / R / name)
        assert ours.keys() == theirs.keys(), name
        differ = [key for key in ours if not np.array_equal(ours[key], theirs[key],
                                                            equal_nan=ours[key].dtype.kind == "f")]
        assert not differ, f"{name}: the image's datasets {differ} differ from the local run's"
    for name in ("coarse.mp4", "video.mp4"):
        ours, _, _ = read_video(local / R / name)
        theirs, _, _ = read_video(contained / R / name)
        assert ours.shape == theirs.shape and np.array_equal(ours, theirs), name
