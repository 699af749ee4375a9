"""reconstruct.prior lgm: LGM and ImageDream at their published architectures, tiny random ones through the real
loading code, Pluecker rays against float64, splatter pixels on their rays, placement against a ray-cast sphere."""
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml
from scipy import ndimage
from safetensors.torch import load_file, save_file

import splat
from schemas import InputError, load_scene
from schemas.artifacts import GaussiansArtifact, read_artifact
from schemas.camera import pixel_rays
from stages.reconstruct.cli import main
from stages.reconstruct.geometry import intrinsics_from_fov
from stages.reconstruct.lgm import prior as prior_module
from stages.reconstruct.lgm.loading import find_lgm, find_multiview, load_lgm, load_multiview, meta_shapes
from stages.reconstruct.lgm.multiview import MultiViewUNetModel, frame_cameras, sample_views
from stages.reconstruct.lgm.placement import nearest_depth, place, seen_from_camera
from stages.reconstruct.lgm.rays import AZIMUTHS_DEG, CAMERA_RADIUS, FOVY_DEG, plucker_embedding, view_poses
from stages.reconstruct.lgm.splatter import decode, prune
from stages.reconstruct.lgm.unet import LGM, LGMConfig, MultiViewAttention
from testing.photographs import Capsule, write_scene
from testing.tiny_lgm import TINY_LGM, TINY_MULTIVIEW_UNET, save_tiny_lgm, save_tiny_multiview

PUBLISHED = Path(__file__).parent / "lgm_published"


def published_shapes(name: str) -> dict:
    lines = [line.split() for line in (PUBLISHED / name).read_text().splitlines() if not line.startswith("#")]
    return {key: tuple(int(n) for n in shape.split("x")) for key, shape in lines}


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    folder = tmp_path_factory.mktemp("lgm_models")
    return save_tiny_lgm(folder / "lgm"), save_tiny_multiview(folder / "imagedream")


@pytest.fixture(autouse=True)
def empty_hub_cache(tmp_path, monkeypatch):
    """No model from this machine's Hugging Face cache or environment leaks into a test."""
    monkeypatch.setenv("HF_HUB_CACHE", str(tmp_path / "hub"))
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    monkeypatch.delenv("PHYSMOTION_LGM_MODEL", raising=False)
    monkeypatch.delenv("PHYSMOTION_MULTIVIEW_MODEL", raising=False)


def test_published_architectures_have_the_checkpoints_names_and_shapes():
    lgm = meta_shapes(LGM)
    assert lgm == published_shapes("lgm_big_keys.txt")
    assert 414e6 < sum(math.prod(s) for s in lgm.values()) < 416e6  # LGM's 415 M parameters
    assert LGMConfig().splat_size == 128
    unet = meta_shapes(MultiViewUNetModel)
    assert unet == published_shapes("imagedream_unet_keys.txt")


def test_tiny_models_round_trip_through_the_loaders(tiny, tmp_path):
    lgm_folder, multiview_folder = tiny
    weights = find_lgm(lgm_folder, tmp_path / "scene.yaml")
    model = load_lgm(weights, "cpu")
    saved = load_file(str(weights))
    assert model.state_dict().keys() == saved.keys()
    assert all(torch.equal(value, saved[key].float()) for key, value in model.state_dict().items())
    inputs = torch.randn(1, 4, 9, TINY_LGM.input_size, TINY_LGM.input_size)
    with torch.no_grad():
        raw = model(inputs)
    assert raw.shape == (1, 4, 14, TINY_LGM.splat_size, TINY_LGM.splat_size) == (1, 4, 14, 16, 16)
    cloud = decode(raw[0])
    assert len(cloud) == 4 * 16 * 16
    assert np.all(np.abs(cloud.means) <= 1) and np.all((cloud.opacities > 0) & (cloud.opacities < 1))
    assert np.allclose(np.linalg.norm(cloud.rotations, axis=1), 1) and np.all(cloud.scales > 0)

    models = load_multiview(find_multiview(multiview_folder, tmp_path / "scene.yaml"), "cpu")
    saved = load_file(str(multiview_folder / "unet" / "diffusion_pytorch_model.safetensors"))
    assert all(torch.equal(value, saved[key]) for key, value in models.unet.state_dict().items())
    image = np.ones((32, 32, 3), np.float32)
    image[8:24, 10:22] = (0.8, 0.2, 0.1)
    views = sample_views(models, image, steps=2, size=32)
    assert views.shape == (4, 32, 32, 3) and views.min() >= 0 and views.max() <= 1


def test_views_see_each_other_through_attention_only():
    """Changing one view changes the others' output through the cross-view attention, and not without it."""
    torch.manual_seed(0)
    lgm = LGM(TINY_LGM).eval()
    inputs = torch.randn(1, 4, 9, 32, 32)
    changed = inputs.clone()
    changed[0, 3] += 1
    with torch.no_grad():
        assert (lgm(changed)[0, 0] - lgm(inputs)[0, 0]).abs().max() > 1e-3
        for block in lgm.modules():
            if isinstance(block, MultiViewAttention):
                block.views = 1  # each view attends to itself only
        assert torch.equal(lgm(changed)[0, 0], lgm(inputs)[0, 0])
    unet = MultiViewUNetModel(**TINY_MULTIVIEW_UNET).eval()
    latents, context = torch.randn(5, 4, 16, 16), torch.randn(5, 3, 32)
    tokens, cameras = torch.randn(5, 6, 32), frame_cameras()
    with torch.no_grad():
        run = lambda x, frames, cams=cameras: unet(x, torch.full((5,), 500), context, cams, frames,  # noqa: E731
                                                   tokens, x[frames - 1::frames])
        moved = latents.clone()
        moved[2] += 1
        assert (run(moved, 5)[0] - run(latents, 5)[0]).abs().max() > 1e-4
        assert torch.equal(run(moved, 1)[0], run(latents, 1)[0])  # one frame per object: nothing crosses
        assert (run(latents, 5, cameras.roll(1, 0))[0] - run(latents, 5)[0]).abs().max() > 1e-4


def test_a_missing_or_partial_model_folder_says_where_and_how(tiny, tmp_path):
    lgm_folder, multiview_folder = tiny
    with pytest.raises(InputError) as missing:
        find_lgm(None, tmp_path / "scene.yaml")
    assert "reconstruct.prior" in str(missing.value) and "huggingface-cli download ashawkey/LGM" in str(missing.value)
    broken = tmp_path / "lgm"
    broken.mkdir()
    shutil.copy(lgm_folder / "config.json", broken)
    weights = load_file(str(lgm_folder / "model_fp16_fixrot.safetensors"))
    weights["conv.weight"] = weights["conv.weight"][:7]
    save_file(weights, str(broken / "model_fp16.safetensors"))
    with pytest.raises(InputError, match=r"conv.weight \(7, 14, 1, 1\) instead of \(14, 14, 1, 1\)"):
        find_lgm(broken, tmp_path / "scene.yaml")
    partial = tmp_path / "imagedream"
    shutil.copytree(multiview_folder, partial)
    (partial / "image_encoder" / "model.safetensors").unlink()
    with pytest.raises(InputError, match=rf"{partial} from the command line: image_encoder/ has no \*.safetensors"):
        find_multiview(partial, tmp_path / "scene.yaml")


def float64_rays(azimuth_deg: float, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Camera centre (3,) and unit directions (size,size,3) of LGM's view at ``azimuth_deg``: the camera of
    azimuth 0 (at +z, looking at the origin, y up) turned about y by the azimuth, pixel by pixel."""
    a = math.radians(azimuth_deg)
    turn = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
    centre = turn @ np.array([0.0, 0.0, CAMERA_RADIUS])
    focal = size / 2 / math.tan(math.radians(FOVY_DEG) / 2)
    directions = np.empty((size, size, 3))
    for i in range(size):
        for j in range(size):
            camera = np.array([(j + 0.5 - size / 2) / focal, -(i + 0.5 - size / 2) / focal, -1.0])
            directions[i, j] = turn @ camera / np.linalg.norm(camera)
    return centre, directions


def test_plucker_embedding_matches_float64():
    size = 12
    embedding = plucker_embedding(view_poses(), size).numpy()
    assert embedding.shape == (4, 6, size, size)
    for v, azimuth in enumerate(AZIMUTHS_DEG):
        centre, directions = float64_rays(azimuth, size)
        np.testing.assert_allclose(embedding[v, 3:].transpose(1, 2, 0), directions, atol=1e-6)
        np.testing.assert_allclose(embedding[v, :3].transpose(1, 2, 0), np.cross(centre, directions), atol=1e-6)


SPHERE_RADIUS = 0.5  # in LGM's cube


def first_hits(origin: np.ndarray, directions: np.ndarray, spheres: list) -> tuple[np.ndarray, np.ndarray]:
    """Where rays from ``origin`` (3,) along ``directions`` (...,3) first meet the spheres [(centre, radius)]:
    distance along the ray (..., inf on a miss) and the point (...,3)."""
    nearest = np.full(directions.shape[:-1], np.inf)
    for centre, radius in spheres:
        rel = origin - np.asarray(centre)
        along = -(directions @ rel)
        closest = rel @ rel - along ** 2
        t = along - np.sqrt(np.maximum(radius ** 2 - closest, 0))
        nearest = np.where((closest < radius ** 2) & (t > 0) & (t < nearest), t, nearest)
    return nearest, origin + np.where(np.isfinite(nearest), nearest, 0)[..., None] * directions


def sphere_splatter(size: int, spheres: list = (((0.0, 0.0, 0.0), SPHERE_RADIUS),)) -> torch.Tensor:
    """Raw splatter images (4,14,size,size) of spheres in LGM's cube: each pixel's Gaussian where its ray first
    meets them (opaque), transparent where the ray misses; standard deviation 0.01, grey."""
    raw = torch.zeros(4, 14, size, size, dtype=torch.float64)
    for v, azimuth in enumerate(AZIMUTHS_DEG):
        centre, directions = float64_rays(azimuth, size)
        distance, points = first_hits(centre, directions, list(spheres))
        raw[v, 0:3] = torch.from_numpy(points.transpose(2, 0, 1))
        raw[v, 3] = torch.from_numpy(np.where(np.isfinite(distance), 8.0, -20.0))
        raw[v, 4:7] = math.log(math.expm1(0.1))  # 0.1 softplus(x) = 0.01
        raw[v, 7] = 1.0
    return raw


def test_splatter_pixels_land_on_their_rays():
    size = 16
    cloud = decode(sphere_splatter(size))
    embedding = plucker_embedding(view_poses(), size).double().numpy()
    moment = embedding[:, :3].transpose(0, 2, 3, 1).reshape(-1, 3)  # Gaussian n = (v s + row) s + col
    direction = embedding[:, 3:].transpose(0, 2, 3, 1).reshape(-1, 3)
    opaque = cloud.opacities > 0.5
    assert 0.2 < opaque.mean() < 0.8
    # on the line of its own pixel's ray: p x d = o x d (float32 embedding)
    np.testing.assert_allclose(np.cross(cloud.means[opaque], direction[opaque]), moment[opaque], atol=2e-6)
    # and not on a neighbour's: the pixel order is the documented one
    shifted = np.roll(direction, 1, axis=0)
    assert np.abs(np.cross(cloud.means[opaque], shifted[opaque]) - moment[opaque]).max() > 1e-2
    assert len(prune(cloud)) == opaque.sum()


def sphere_photograph(spheres: list, size: int, fov_deg: float = 40.0):
    """K, mask and camera-space front depth (NaN off it) of spheres [(centre, radius)] in the camera frame."""
    K = intrinsics_from_fov(fov_deg, size, size)
    rays = pixel_rays(K, size, size)
    distance, _ = first_hits(np.zeros(3), rays, spheres)
    mask = np.isfinite(distance)
    return K, mask, np.where(mask, distance * rays[..., 2], np.nan)


def render_alpha(placed, K: np.ndarray, size: int) -> np.ndarray:
    as_tensor = lambda a: torch.tensor(a, dtype=torch.float32)  # noqa: E731
    return splat.rasterize(as_tensor(placed.means), as_tensor(placed.opacities), as_tensor(placed.colors),
                           splat.Camera(K, np.eye(4), size, size), scales=as_tensor(placed.scales),
                           rotations=as_tensor(placed.rotations)).alpha.numpy()


def test_placed_sphere_renders_on_its_mask_at_the_prior_depth():
    radius, distance, size = 0.1, 0.6, 128
    K, mask, front = sphere_photograph([((0, 0, distance), radius)], size)
    placed = place(prune(decode(sphere_splatter(32))), mask, K, 2 * radius, front)
    covered = render_alpha(placed, K, size) > 0.5
    # the silhouette: all but a rim of Gaussian footprint and the poles, which views at elevation 0 graze
    assert (covered & mask).sum() / (covered | mask).sum() > 0.85
    np.testing.assert_allclose(np.argwhere(covered).mean(0), np.argwhere(mask).mean(0), atol=0.5)
    # the nearest Gaussian in each pixel lies on the prior's front
    coarse = np.diag([0.5, 0.5, 1.0]) @ K  # pixels of 2 x 2, so that most hold a front Gaussian
    zbuffer, _ = nearest_depth(placed.means, coarse, (size // 2, size // 2))
    inside, truth = mask[1::2, 1::2], front[1::2, 1::2]
    both = inside & np.isfinite(zbuffer)
    assert both.sum() > 0.8 * inside.sum()
    assert np.median(np.abs(zbuffer[both] - truth[both])) < 0.03 * radius
    np.testing.assert_allclose(placed.means.mean(0), [0, 0, distance], atol=0.05 * radius)
    # the photograph sees the near cap: within 3 % of size_m behind the nearest Gaussian of its pixel
    seen = seen_from_camera(placed, K, mask, 2 * radius)
    assert 0.2 < seen.mean() < 0.6
    assert placed.means[seen, 2].max() < distance and placed.means[~seen, 2].min() > distance - radius


def test_placement_keeps_left_right_and_up_down():
    """A big ball at the photograph's right and a small one up left: LGM's frame (y up, z towards view 0) turned
    into the camera's (y down, z away) puts each where the photograph has it, not mirrored."""
    big, small = ((0.05, 0.01, 0.6), 0.05), ((-0.06, -0.04, 0.62), 0.025)
    K, mask, front = sphere_photograph([big, small], 96)
    to_cube = lambda centre: (5 * centre[0], -5 * centre[1], -5 * (centre[2] - 0.6))  # noqa: E731
    cloud = prune(decode(sphere_splatter(32, [(to_cube(c), 5 * r) for c, r in (big, small)])))
    placed = place(cloud, mask, K, 0.185, front)  # the pair's largest extent, along x: 0.05 + 0.05 + 0.06 + 0.025
    covered = render_alpha(placed, K, 96) > 0.5
    assert (covered & mask).sum() / (covered | mask).sum() > 0.8
    mirrored = covered[:, ::-1], covered[::-1, :]
    assert all((m & mask).sum() / (m | mask).sum() < 0.5 for m in mirrored)


def scene_with_prior(tmp_path, prior: str, shape=None, iterations: int = 1, enhance=None):
    """A 64x48 scene.yaml under tmp_path of ``shape`` (a tilted capsule by default) with reconstruct.prior
    ``prior`` and, where given, the ``enhance`` section."""
    scene = write_scene(tmp_path / "scene", shape or Capsule.tilted(), width=64, height=48, iterations=iterations)
    config = yaml.safe_load(scene.read_text())
    config["reconstruct"]["prior"] = prior
    if enhance is not None:
        config["enhance"] = enhance
    scene.write_text(yaml.safe_dump(config))
    return scene


def test_prior_lgm_runs_in_pm_reconstruct(tiny, tmp_path, monkeypatch):
    lgm_folder, multiview_folder = tiny
    monkeypatch.setattr(prior_module, "DIFFUSION_STEPS", 2)
    scene = scene_with_prior(tmp_path, "lgm", Capsule.tilted(distance=0.6), iterations=4)
    out = tmp_path / "gaussians.h5"
    main(["--scene", str(scene), "--out", str(out), "--device", "cpu", "--lgm-model", str(lgm_folder),
          "--multiview-model", str(multiview_folder)])
    artifact = read_artifact(out, GaussiansArtifact)
    assert len(artifact.means) > 50
    assert np.isnan(artifact.solid_spacing).all()  # a learned body is its Gaussians', which simulate fills
    # every Gaussian's centre projects onto the object's mask, grown by the carving margin
    uv = artifact.means @ artifact.K.T
    cols, rows = (uv[:, :2] / uv[:, 2:]).T.astype(int)
    assert ((rows >= 0) & (rows < 48) & (cols >= 0) & (cols < 64)).all()
    grown = np.pad(artifact.mask == 1, 2, mode="edge")
    near = np.zeros_like(artifact.mask, bool)
    for dy in range(5):
        for dx in range(5):
            near |= grown[dy:dy + 48, dx:dx + 64]
    assert near[rows, cols].mean() > 0.95
    # and they render there (splat at the artifact's camera): the mask covered, nothing beyond the reach of the
    # Gaussians' footprints (three standard deviations of the median one; random weights make them wide)
    as_tensor = lambda a: torch.tensor(np.asarray(a), dtype=torch.float32)  # noqa: E731
    alpha = splat.rasterize(as_tensor(artifact.means), as_tensor(artifact.opacities), as_tensor(artifact.colors),
                            splat.Camera(artifact.K, np.eye(4), 64, 48), scales=as_tensor(artifact.scales),
                            rotations=as_tensor(artifact.rotations)).alpha.numpy()
    mask = artifact.mask == 1
    assert (alpha[mask] > 0.5).mean() > 0.9
    reach = 3 * np.median(artifact.scales) * artifact.K[0, 0] / np.median(artifact.means[:, 2])
    outside = ndimage.distance_transform_edt(~mask) > reach
    assert alpha[outside].sum() < 0.05 * alpha.sum()


def test_prior_lgm_without_weights_exits_2_saying_what_it_needs(tmp_path, capsys):
    scene = scene_with_prior(tmp_path, "lgm")
    with pytest.raises(SystemExit) as stopped:
        main(["--scene", str(scene), "--out", str(tmp_path / "g.h5"), "--device", "cpu"])
    assert stopped.value.code == 2
    err = capsys.readouterr().err
    assert "reconstruct.prior" in err and "LGM checkpoint" in err and "--lgm-model" in err
    assert not (tmp_path / "g.h5").exists()


@pytest.mark.parametrize("given, prior, shown", [({}, "lgm", "render"), ({}, "symmetric", "photo"),
                                                 ({"hidden_surfaces": "photo"}, "lgm", "photo")])
def test_the_learned_colours_show_on_unseen_surfaces_unless_the_scene_says(tmp_path, given, prior, shown):
    from stages.enhance.cli import hidden_surfaces

    scene = scene_with_prior(tmp_path, prior, enhance=given)
    assert hidden_surfaces(load_scene(scene)) == shown


def test_the_default_prior_leaves_the_reconstruct_hash_as_before(tmp_path):
    from schemas import config_hash, stage_keys

    scene = write_scene(tmp_path / "scene", Capsule.tilted(), width=64, height=48, iterations=1)
    before = config_hash(stage_keys(load_scene(scene), "reconstruct"))
    config = yaml.safe_load(scene.read_text())
    for prior, same in (("symmetric", True), ("lgm", False)):
        config["reconstruct"]["prior"] = prior
        scene.write_text(yaml.safe_dump(config))
        assert (config_hash(stage_keys(load_scene(scene), "reconstruct")) == before) == same
