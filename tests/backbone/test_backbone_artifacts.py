"""The HDF5 artifacts: round trips, identical bytes, refusals with a clear message, atomic writes."""
import hashlib
import os
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest

from schemas import InputError
from schemas.artifacts import (CoarseArtifact, GaussiansArtifact, LatentsArtifact, TrajectoriesArtifact,
                               read_artifact, read_header, write_artifact)
from schemas.solid import SolidGrid, solid_fields


def random_gaussians(G=7, H=5, W=6, seed=0) -> GaussiansArtifact:
    r = np.random.default_rng(seed)
    return GaussiansArtifact(
        K=r.random((3, 3)), world_to_camera=np.eye(4), width=W, height=H, means=r.random((G, 3)),
        scales=r.random((G, 3)), rotations=r.random((G, 4)), opacities=r.random(G), colors=r.random((G, 3)),
        object_id=r.integers(0, 3, G), photo=r.integers(0, 255, (H, W, 3)), mask=r.integers(0, 3, (H, W)),
        background=r.integers(0, 255, (H, W, 3)), depth_prior=r.random((H, W)),
        **solid_fields([None, SolidGrid(r.random((4, 4, 4)), r.random(3), np.eye(3), 0.01), None]), loss=r.random((4, 2)),
        loss_terms=["colour", "hard_depth"])


def random_trajectories(T=3, P=9, G=4, seed=1) -> TrajectoriesArtifact:
    r = np.random.default_rng(seed)
    return TrajectoriesArtifact(
        rest_positions=r.random((P, 3)), volumes=r.random(P), masses=r.random(P), material_id=np.zeros(P),
        object_id=np.zeros(P), is_gaussian=np.arange(P) < G, positions=r.random((T, P, 3)),
        F=r.random((T, P, 3, 3)), time_s=np.arange(T) / 8, substeps=np.full(T, 5.0), kinetic_energy=r.random(T),
        potential_energy=r.random(T), momentum=r.random((T, 3)), angular_momentum=r.random((T, 3)),
        max_speed=r.random(T), lattice_spacing=0.01, fps=8.0, duration_s=0.25)


def random_coarse(T=2, h=4, w=6, seed=2) -> CoarseArtifact:
    r = np.random.default_rng(seed)
    return CoarseArtifact(rgb=r.integers(0, 255, (T, h, w, 3)), alpha=r.random((T, h, w)), depth=r.random((T, h, w)),
                          source_uv=r.random((T, h, w, 2)), source_coherence=r.random((T, h, w)),
                          source_confidence=r.random((T, h, w)), normal=r.random((T, h, w, 3)), K=np.eye(3),
                          width=w, height=h, fps=24.0)


def random_latents(T=2, steps=3, seed=3) -> LatentsArtifact:
    r = np.random.default_rng(seed)
    return LatentsArtifact(latents=r.standard_normal((T, steps + 1, 4, 2, 3)), timesteps=np.arange(steps + 1) * 20,
                           scheduler='{"name": "DDIM"}', prompt="a cup")


MAKERS = [random_gaussians, random_trajectories, random_coarse, random_latents]


@pytest.mark.parametrize("make", MAKERS)
def test_round_trip(tmp_path, make):
    artifact = make()
    write_artifact(tmp_path / "a.h5", artifact, created_by="test", config_hash="abc")
    back = read_artifact(tmp_path / "a.h5", type(artifact))
    for name, spec in type(artifact).layout().items():
        a, b = getattr(artifact, name), getattr(back, name)
        if spec.dtype:
            assert b.dtype == np.dtype(spec.dtype) and np.array_equal(a, b, equal_nan=spec.nan), name
        else:
            assert a == b, name
    header = read_header(tmp_path / "a.h5")
    assert header["schema"] == artifact.SCHEMA and header["config_hash"] == "abc"
    assert header["created_by"].startswith("test")


@pytest.mark.parametrize("make", MAKERS)
def test_same_inputs_same_bytes(tmp_path, make):
    write_artifact(tmp_path / "a.h5", make(), created_by="t", config_hash="h")
    time.sleep(1.1)  # a timestamp anywhere in the file would now differ
    write_artifact(tmp_path / "b.h5", make(), created_by="t", config_hash="h")
    digest = lambda p: hashlib.sha256(p.read_bytes()).hexdigest()  # noqa: E731
    assert digest(tmp_path / "a.h5") == digest(tmp_path / "b.h5")


def test_layout_follows_design(tmp_path):
    write_artifact(tmp_path / "t.h5", random_trajectories(), created_by="t", config_hash="h")
    with h5py.File(tmp_path / "t.h5") as f:
        assert f["/frames/positions"].chunks == (1, 9, 3) and f["/frames/positions"].compression is None
        assert f["/particles/is_gaussian"].dtype == bool and f.attrs["fps"] == 8.0
    write_artifact(tmp_path / "c.h5", random_coarse(), created_by="t", config_hash="h")
    with h5py.File(tmp_path / "c.h5") as f:
        assert f["/frames/rgb"].chunks == (1, 4, 6, 3) and f["/frames/rgb"].compression == "gzip"
        assert f["/camera"].attrs["fps"] == 24.0


def test_inconsistent_shapes_are_refused():
    with pytest.raises(ValueError, match="dimension G"):
        GaussiansArtifact(**{**random_gaussians().__dict__, "opacities": np.ones(3)})


def test_wrong_schema_names_writer(tmp_path):
    write_artifact(tmp_path / "c.h5", random_coarse(), created_by="pm-render", config_hash="h")
    with pytest.raises(InputError) as info:
        read_artifact(tmp_path / "c.h5", GaussiansArtifact)
    assert "physmotion.coarse" in info.value.problem and "pm-render" in info.value.problem


def test_wrong_version_is_refused(tmp_path):
    write_artifact(tmp_path / "g.h5", random_gaussians(), created_by="pm-reconstruct", config_hash="h")
    with h5py.File(tmp_path / "g.h5", "a") as f:
        f.attrs["schema_version"] = 99
    with pytest.raises(InputError) as info:
        read_artifact(tmp_path / "g.h5", GaussiansArtifact)
    assert info.value.field == "schema_version" and "99" in info.value.problem


def test_trajectories_of_the_gaussians_only_layout_are_refused(tmp_path):
    """Version 1 held F for the G Gaussians only (T,G,3,3); later versions hold it for every particle."""
    write_artifact(tmp_path / "t.h5", random_trajectories(), created_by="pm-simulate", config_hash="h")
    with h5py.File(tmp_path / "t.h5", "a") as f:
        f.attrs["schema_version"] = 1
        del f["/frames/F"]
        f["/frames/F"] = np.zeros((3, 4, 3, 3), np.float32)
    with pytest.raises(InputError) as info:
        read_artifact(tmp_path / "t.h5", TrajectoriesArtifact)
    assert info.value.field == "schema_version" and "version 1" in info.value.problem
    assert f"reads version {TrajectoriesArtifact.VERSION}" in info.value.problem and "rerun" in info.value.fix


def test_missing_dataset_is_named(tmp_path):
    write_artifact(tmp_path / "g.h5", random_gaussians(), created_by="pm-reconstruct", config_hash="h")
    with h5py.File(tmp_path / "g.h5", "a") as f:
        del f["/image/background"]
    with pytest.raises(InputError) as info:
        read_artifact(tmp_path / "g.h5", GaussiansArtifact)
    assert info.value.field == "/image/background"


def test_not_hdf5_and_missing_file(tmp_path):
    (tmp_path / "x.h5").write_text("hello")
    for path in (tmp_path / "x.h5", tmp_path / "absent.h5"):
        with pytest.raises(InputError):
            read_artifact(path, GaussiansArtifact)


WRITE_SLOWLY = """
import sys, numpy as np
from schemas.artifacts import write_artifact, CoarseArtifact
T = 400  # large enough that the write takes a while
a = CoarseArtifact(rgb=np.random.default_rng(0).integers(0, 255, (T, 256, 256, 3)), alpha=np.zeros((T, 256, 256)),
    depth=np.zeros((T, 256, 256)), source_uv=np.zeros((T, 256, 256, 2)), source_coherence=np.zeros((T, 256, 256)),
    source_confidence=np.zeros((T, 256, 256)), normal=np.zeros((T, 256, 256, 3)),
    K=np.eye(3), width=256, height=256, fps=24.0)
print("writing", flush=True)
write_artifact(sys.argv[1], a, created_by="t", config_hash="h")
"""


def test_killed_writer_leaves_no_finished_file(tmp_path):
    out = tmp_path / "coarse.h5"
    proc = subprocess.Popen([sys.executable, "-c", WRITE_SLOWLY, str(out)], stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "writing"
    time.sleep(0.5)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not out.exists()
    assert all(p.name.startswith(".coarse.h5.partial") for p in tmp_path.iterdir())
