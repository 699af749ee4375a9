"""Helpers for the backbone tests: tiny scene folders made on the fly, and one workflow run of the tiny scene."""
import fcntl
import os
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from schemas import InputError, load_scene
from testing.workflow import run_snakemake


def make_photo(folder: Path, width: int = 64, height: int = 48, name: str = "photo.png") -> Path:
    """A textured disc on a plain background, with its mask (mask.png)."""
    rows, cols = np.mgrid[0:height, 0:width]
    disc = (cols - width / 2) ** 2 + (rows - height * 0.55) ** 2 < (height * 0.3) ** 2
    rgb = np.full((height, width, 3), (90, 120, 160), np.uint8)
    stripes = ((cols // 3) % 2 == 0)
    rgb[disc & stripes] = (230, 60, 40)
    rgb[disc & ~stripes] = (250, 210, 70)
    cv2.imwrite(str(folder / name), rgb[..., ::-1])
    cv2.imwrite(str(folder / "mask.png"), disc.astype(np.uint8) * 255)
    return folder / name


def tiny_scene_dict() -> dict:
    """A scene that runs end to end in seconds: 64 px, few iterations, coarse grid, few frames."""
    return {
        "image": "photo.png",
        "camera": {"fov_deg": 40, "pitch_deg": 0},
        "objects": [{"mask": "mask.png", "size_m": 0.2,
                     "material": {"preset": "jelly", "youngs_modulus": 2.0e4}}],
        "reconstruct": {"resolution": 64, "iterations": 10},
        "physics": {"duration_s": 0.25, "fps": 8, "grid": 16, "particles_per_cell": 2,
                    "conditions": [{"type": "impulse", "velocity": [0.5, -0.5, 0.0]}]},
        "render": {"width": 64},
        "enhance": {"backend": "flow"},
    }


def write_scene(folder: Path, scene: dict | None = None, text: str | None = None) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    if not (folder / "photo.png").exists():
        make_photo(folder)
    path = folder / "scene.yaml"
    path.write_text(text if text is not None else yaml.safe_dump(scene or tiny_scene_dict(), sort_keys=False))
    return path


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
