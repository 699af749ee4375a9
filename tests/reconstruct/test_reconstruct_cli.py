"""pm-reconstruct end to end on a tiny synthetic scene: the artifact, determinism, bad input, extra views, PLY."""
import cv2
import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

import splat
from schemas.artifacts import GaussiansArtifact, read_artifact
from schemas.ply import GaussianCloud, write_ply
from stages.reconstruct.cli import main
from stages.reconstruct.geometry import intrinsics_from_fov
from stages.reconstruct.metrics import iou
from stages.reconstruct.optimize import LOSS_TERMS
from testing.photographs import Capsule, photograph, side_view, write_scene

ITERATIONS = 24  # hard depth from iteration 4 at multiples of 10: iterations 10 and 20


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    return write_scene(tmp_path_factory.mktemp("capsule"), Capsule.tilted(), width=64, height=48,
                       iterations=ITERATIONS)


@pytest.fixture(scope="module")
def artifact_path(scene, tmp_path_factory):
    out = tmp_path_factory.mktemp("out") / "gaussians.h5"
    main(["--scene", str(scene), "--out", str(out), "--device", "cpu"])
    return out


def test_artifact_holds_the_scene(artifact_path, scene):
    g = read_artifact(artifact_path, GaussiansArtifact)
    mask = cv2.imread(str(scene.parent / "mask.png"), cv2.IMREAD_GRAYSCALE) > 0
    assert (g.width, g.height) == (64, 48)
    assert np.allclose(g.K, intrinsics_from_fov(40, 64, 48)) and np.allclose(g.world_to_camera, np.eye(4))
    assert ((g.mask == 1) == mask).all()
    assert np.isnan(g.depth_prior[~mask]).all() and (g.depth_prior[mask] > 0).all()
    assert g.loss.shape == (ITERATIONS, len(LOSS_TERMS)) and g.loss_terms == LOSS_TERMS
    assert g.loss[-1, 1] < g.loss[0, 1]  # the colour loss went down
    assert (np.flatnonzero(np.isfinite(g.loss[:, 3])) == [10, 20]).all() and (g.loss[[10, 20], 3] > 0).all()
    assert np.allclose(np.linalg.norm(g.rotations, axis=1), 1, atol=1e-5)
    assert (g.opacities >= 0.05).all() and (g.object_id == 0).all()
    assert np.abs(g.background.astype(int) - g.photo[0, 0]).max() <= 6  # the flat backdrop, object removed


def differing_entries(a, b) -> list[str]:
    """The datasets and attributes whose values differ between two HDF5 files, with their largest difference,
    so that a failure says what changed rather than dumping a megabyte of bytes."""
    import h5py

    def entries(f) -> dict:
        found = {f"@{k}": v for k, v in f.attrs.items()}
        f.visititems(lambda name, obj: found.update({f"{name}@{k}": v for k, v in obj.attrs.items()},
                                                     **({name: obj[()]} if isinstance(obj, h5py.Dataset) else {})))
        return found

    with h5py.File(a, "r") as fa, h5py.File(b, "r") as fb:
        left, right = entries(fa), entries(fb)
    named = sorted(set(left) ^ set(right))
    for name in sorted(set(left) & set(right)):
        x, y = np.asarray(left[name]), np.asarray(right[name])
        if x.shape != y.shape:
            named.append(f"{name}: shape {x.shape} against {y.shape}")
        elif not np.array_equal(x, y, equal_nan=x.dtype.kind == "f"):
            largest = np.nanmax(np.abs(x.astype(np.float64) - y)) if x.dtype.kind in "fiu" else "-"  # no uint wrap
            named.append(f"{name}: {int(np.sum(x != y))} values differ, by up to {largest}")
    return named


def test_same_inputs_give_the_same_bytes(artifact_path, scene, tmp_path):
    again = tmp_path / "again.h5"
    main(["--scene", str(scene), "--out", str(again), "--device", "cpu"])
    same = again.read_bytes() == artifact_path.read_bytes()
    assert same, f"the second run's artifact differs: {differing_entries(artifact_path, again) or 'in its bytes only'}"


def test_bad_box_exits_2_naming_the_field(tmp_path, capsys):
    cv2.imwrite(str(tmp_path / "photo.png"), np.zeros((20, 30, 3), np.uint8))
    (tmp_path / "scene.yaml").write_text("image: photo.png\nobjects:\n  - box: [0, 0, 40, 10]\n")
    with pytest.raises(SystemExit) as exit_:
        main(["--scene", str(tmp_path / "scene.yaml"), "--out", str(tmp_path / "g.h5"), "--device", "cpu"])
    assert exit_.value.code == 2
    assert "objects[0].box" in capsys.readouterr().err
    assert not (tmp_path / "g.h5").exists()


def test_extra_view_enters_the_hard_depth_loss(tmp_path):
    capsule = Capsule.tilted()
    scene = write_scene(tmp_path, capsule, width=64, height=48, iterations=12)
    # A side view as a multi-view model would give it: the object on a white background, its own framing.
    K = intrinsics_from_fov(30, 80, 80)
    side = photograph(capsule, K, side_view(capsule, 90), 80, 80)
    cv2.imwrite(str(tmp_path / "side.png"), np.where(side.mask[..., None], side.rgb, 255).astype(np.uint8))
    scene.write_text(scene.read_text().replace(
        "iterations: 12}", "iterations: 12, extra_views: [{image: side.png, azimuth_deg: 90}]}"))
    main(["--scene", str(scene), "--out", str(tmp_path / "g.h5"), "--device", "cpu"])
    g = read_artifact(tmp_path / "g.h5", GaussiansArtifact)
    assert np.isfinite(g.loss[:, 3]).sum() == 1 and g.loss[np.isfinite(g.loss[:, 3]), 3][0] > 0


def test_init_ply_is_placed_onto_the_mask(tmp_path, artifact_path):
    """A cloud exported in the OpenGL frame of LGM-like tools (y up, z towards the viewer, centred, its own
    scale) lands on the object in the input camera with the object's size."""
    g = read_artifact(artifact_path, GaussiansArtifact)
    to_opengl = Rotation.from_euler("x", 180, degrees=True)
    means = to_opengl.apply(g.means - g.means.mean(0)) * 7.0
    rotations = (to_opengl * Rotation.from_quat(g.rotations, scalar_first=True)).as_quat(scalar_first=True)
    write_ply(tmp_path / "cloud.ply", GaussianCloud(means, g.scales * 7.0, rotations, g.opacities, g.colors))
    cv2.imwrite(str(tmp_path / "photo.png"), cv2.cvtColor(g.photo, cv2.COLOR_RGB2BGR))
    cv2.imwrite(str(tmp_path / "mask.png"), g.mask * 255)
    (tmp_path / "scene.yaml").write_text(
        "image: photo.png\ncamera: {fov_deg: 40}\nobjects:\n  - mask: mask.png\n    size_m: 0.25\n"
        "reconstruct: {resolution: 64, iterations: 0, init_ply: cloud.ply}\n")
    main(["--scene", str(tmp_path / "scene.yaml"), "--out", str(tmp_path / "placed.h5"), "--device", "cpu"])
    placed = read_artifact(tmp_path / "placed.h5", GaussiansArtifact)
    camera = splat.Camera(placed.K, np.eye(4), 64, 48)

    def silhouette(a):
        t = lambda x: torch.tensor(x, dtype=torch.float32)  # noqa: E731
        return splat.rasterize(t(a.means), t(a.opacities), t(a.colors), camera, scales=t(a.scales),
                               rotations=t(a.rotations)).alpha.numpy() > 0.5

    # The placed cloud covers what the Gaussians it was exported from covered (at 64 px their
    # blurred rims, not the mask, are the reference).
    assert iou(silhouette(placed), silhouette(g)) > 0.85
    assert (placed.means.max(0) - placed.means.min(0)).max() == pytest.approx(0.25, rel=1e-3)


def test_two_objects_get_their_own_gaussians_and_depths(tmp_path):
    K = intrinsics_from_fov(40, 64, 48)
    left, right = (photograph(Capsule(np.array([x, 0.0, 0.6]), np.array([0.0, 0.04, 0.0]), 0.03), K, np.eye(4), 64, 48)
                   for x in (-0.1, 0.1))
    cv2.imwrite(str(tmp_path / "photo.png"), np.where(left.mask[..., None], left.rgb, right.rgb))
    for name, shot in (("left.png", left), ("right.png", right)):
        cv2.imwrite(str(tmp_path / name), shot.mask.astype(np.uint8) * 255)
    (tmp_path / "scene.yaml").write_text(
        "image: photo.png\nobjects:\n  - {mask: left.png, size_m: 0.14}\n  - {mask: right.png, size_m: 0.28}\n"
        "reconstruct: {resolution: 64, iterations: 2}\n")
    main(["--scene", str(tmp_path / "scene.yaml"), "--out", str(tmp_path / "g.h5"), "--device", "cpu"])
    g = read_artifact(tmp_path / "g.h5", GaussiansArtifact)
    assert set(np.unique(g.mask)) == {0, 1, 2} and set(np.unique(g.object_id)) == {0, 1}
    # Same silhouette size, twice the size_m: the second object is placed twice as far away.
    ratio = np.nanmedian(g.depth_prior[g.mask == 2]) / np.nanmedian(g.depth_prior[g.mask == 1])
    assert ratio == pytest.approx(2.0, rel=0.05)
    depth = [np.median(g.means[g.object_id == k, 2]) for k in (0, 1)]
    assert depth[1] / depth[0] == pytest.approx(2.0, rel=0.05)
