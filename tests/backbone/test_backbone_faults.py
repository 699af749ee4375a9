"""Faults while writing: a full disk, a read-only folder, a killed or stopped program. Each ends in one
paragraph naming the file and the cause, and leaves no temporary file behind (or the next run removes it)."""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

from schemas import InputError
from schemas.artifacts import GaussiansArtifact, read_artifact, write_artifact
from schemas.files import check_writable, partial_name, write_file
from schemas.images import write_image
from schemas.video import write_video
from testing.tiny_scene import write_scene
from testing.workflow import BIN

from .mounts import tmpfs
from .test_backbone_artifacts import random_coarse, random_gaussians


def big_coarse():
    """About 3 MB on disk: rgb noise does not compress."""
    return random_coarse(T=12, h=128, w=160)


@pytest.fixture
def full_disk(tmp_path):
    with tmpfs(tmp_path / "small", "512k") as folder:
        yield folder


@pytest.fixture
def read_only(tmp_path):
    with tmpfs(tmp_path / "ro", "512k", read_only=True) as folder:
        yield folder


def test_an_artifact_too_big_for_the_disk_is_one_error_and_leaves_nothing(full_disk):
    with pytest.raises(InputError, match="No space left on device") as err:
        write_artifact(full_disk / "coarse.h5", big_coarse(), created_by="t", config_hash="h")
    assert err.value.file == str(full_disk / "coarse.h5") and "free space" in err.value.fix
    assert list(full_disk.iterdir()) == []


def test_a_disk_that_fills_during_the_write_is_one_error_and_leaves_nothing(full_disk, monkeypatch):
    """The free space looked enough (another writer took it meanwhile): the write itself fails."""
    import shutil

    monkeypatch.setattr(shutil, "disk_usage", lambda _: shutil._ntuple_diskusage(1 << 40, 0, 1 << 40))
    for write in (lambda p: write_artifact(p, big_coarse(), created_by="t", config_hash="h"),
                  lambda p: write_video(p, np.random.default_rng(0).integers(0, 255, (40, 128, 160, 3), np.uint8), 8),
                  lambda p: write_file(p, bytes(1 << 20))):
        with pytest.raises(InputError, match="No space left on device"):
            write(full_disk / "out")
        assert list(full_disk.iterdir()) == []


def test_a_read_only_folder_reports_the_write_not_the_cleanup(read_only):
    for write in (lambda p: write_artifact(p, random_gaussians(), created_by="t", config_hash="h"),
                  lambda p: write_image(p.with_suffix(".png"), np.zeros((8, 8, 3), np.uint8)),
                  lambda p: check_writable([p])):
        with pytest.raises(InputError, match="Read-only file system") as err:
            write(read_only / "gaussians.h5")
        assert "read-only" in err.value.fix


def test_an_image_that_cannot_be_written_raises(tmp_path):
    (tmp_path / "setup.png").mkdir()  # a folder where the image should go: cv2.imwrite would return False
    with pytest.raises(InputError, match="setup.png"):
        write_image(tmp_path / "setup.png", np.zeros((8, 8, 3), np.uint8))


def dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_the_next_write_removes_what_a_killed_writer_left(tmp_path):
    out = tmp_path / "gaussians.h5"
    stale, live = partial_name(out, dead_pid()), partial_name(out, os.getppid())
    stale.write_bytes(b"half an artifact")
    live.write_bytes(b"another process still writing")
    write_artifact(out, random_gaussians(), created_by="t", config_hash="h")
    assert not stale.exists() and live.exists()
    assert read_artifact(out, GaussiansArtifact).means.shape == (7, 3)


@pytest.mark.parametrize("path, dataset, value", [
    ("/gaussians/means", "means", np.nan), ("/gaussians/scales", "scales", np.inf),
    ("/image/depth_prior", "depth_prior", np.inf)])
def test_non_finite_arrays_are_refused_naming_file_and_dataset(tmp_path, path, dataset, value):
    out = tmp_path / "gaussians.h5"
    write_artifact(out, random_gaussians(), created_by="pm-reconstruct", config_hash="h")
    with h5py.File(out, "r+") as f:
        f[path][0, 0] = value
    with pytest.raises(InputError) as err:
        read_artifact(out, GaussiansArtifact)
    assert (err.value.file, err.value.field) == (str(out), path) and "1 of its" in err.value.problem


def test_nan_where_it_means_no_value_is_read(tmp_path):
    artifact = random_gaussians()
    artifact.depth_prior[0, 0] = np.nan  # off the objects
    write_artifact(tmp_path / "g.h5", artifact, created_by="t", config_hash="h")
    assert np.isnan(read_artifact(tmp_path / "g.h5", GaussiansArtifact).depth_prior[0, 0])


def test_zero_gaussians_are_refused(tmp_path):
    out = tmp_path / "gaussians.h5"
    write_artifact(out, random_gaussians(), created_by="pm-reconstruct", config_hash="h")
    with h5py.File(out, "r+") as f:
        for name in ("means", "scales", "rotations", "opacities", "colors", "object_id"):
            data = f[f"/gaussians/{name}"][()]
            del f[f"/gaussians/{name}"]
            f[f"/gaussians/{name}"] = data[:0]
    with pytest.raises(InputError, match="holds no G"):
        read_artifact(out, GaussiansArtifact)


def test_a_writer_may_not_write_inf(tmp_path):
    artifact = random_gaussians()
    artifact.scales[1, 2] = np.inf
    with pytest.raises(ValueError, match="/gaussians/scales"):
        write_artifact(tmp_path / "g.h5", artifact, created_by="t", config_hash="h")
    assert list(tmp_path.iterdir()) == []


def slow_scene(folder: Path) -> Path:
    scene = write_scene(folder)
    raw = yaml.safe_load(scene.read_text())
    raw["reconstruct"]["iterations"] = 100000
    scene.write_text(yaml.safe_dump(raw))
    return scene


@pytest.mark.slow
def test_a_stopped_program_says_so_in_one_paragraph_and_leaves_nothing(tmp_path):
    out = tmp_path / "r" / "gaussians.h5"
    proc = subprocess.Popen([str(BIN / "pm-reconstruct"), "--scene", str(slow_scene(tmp_path / "s")), "--out",
                             str(out), "--device", "cpu"], stderr=subprocess.PIPE, text=True)
    for line in proc.stderr:
        if "iteration" in line:  # optimising
            break
    proc.send_signal(signal.SIGTERM)
    _, rest = proc.communicate(timeout=60)
    assert proc.returncode == 128 + signal.SIGTERM
    assert "stopped by SIGTERM" in rest and "Traceback" not in rest
    assert list(out.parent.iterdir()) == []


@pytest.fixture(scope="module")
def tiny_gaussians(tmp_path_factory) -> tuple[Path, Path]:
    """The tiny scene, with a simulation long enough that failing after it would take a while, and its
    gaussians.h5."""
    folder = tmp_path_factory.mktemp("tiny")
    scene = write_scene(folder / "s")
    raw = yaml.safe_load(scene.read_text())
    raw["physics"]["duration_s"] = 20.0
    scene.write_text(yaml.safe_dump(raw))
    gaussians = folder / "gaussians.h5"
    subprocess.run([str(BIN / "pm-reconstruct"), "--scene", str(scene), "--out", str(gaussians), "--device", "cpu"],
                   check=True, capture_output=True)
    return scene, gaussians


def program_args(program: str, scene: Path, gaussians: Path, out: Path) -> list[str]:
    inputs = [] if program == "pm-reconstruct" else ["--gaussians", str(gaussians)]
    return [str(BIN / program), "--scene", str(scene), *inputs, "--out", str(out), "--device", "cpu"]


@pytest.mark.slow
@pytest.mark.parametrize("program", ["pm-reconstruct", "pm-simulate"])
def test_programs_on_a_read_only_folder_fail_before_the_work(tiny_gaussians, read_only, program):
    started = time.perf_counter()
    proc = subprocess.run(program_args(program, *tiny_gaussians, read_only / "out.h5"), capture_output=True,
                          text=True)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert f"error in {read_only / 'out.h5'}: cannot write this output: Read-only file system" in proc.stderr
    assert "optimising" not in proc.stderr and "frame 1/" not in proc.stderr
    assert time.perf_counter() - started < 30


@pytest.mark.slow
def test_a_setup_image_that_cannot_be_written_stops_the_simulation_before_it_runs(tiny_gaussians, tmp_path):
    (tmp_path / "setup.png").mkdir()  # cv2.imwrite returned False here, and the log said "wrote setup.png"
    proc = subprocess.run(program_args("pm-simulate", *tiny_gaussians, tmp_path / "trajectories.h5"),
                          capture_output=True, text=True)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert f"error in {tmp_path / 'setup.png'}" in proc.stderr
    assert "a folder stands where this program writes setup.png" in proc.stderr
    assert "wrote" not in proc.stderr and "frame 1/" not in proc.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["setup.png"]
