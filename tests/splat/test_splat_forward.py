"""The Warp render equals the float64 brute-force oracle, pixel by pixel, on hard scenes."""
import numpy as np
import pytest
import torch
from splat_scenes import (
    DEVICES,
    assert_matches_oracle,
    look_at,
    random_scene,
    render_oracle,
    render_warp,
)

import splat
from splat import composite


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("num_gaussians, width, height, seed", [
    (1, 17, 23, 0), (40, 45, 33, 1), (600, 64, 48, 2), (5000, 50, 37, 3)])
def test_random_scenes_match_oracle(device, num_gaussians, width, height, seed):
    # Image sizes are not multiples of the 8 px tile; some means lie outside the view.
    scene = random_scene(seed, num_gaussians, width, height, spread=1.2, background=True)
    assert_matches_oracle(scene, device)


def test_rotated_translated_camera_matches_oracle():
    camera = look_at(eye=[0.8, -0.5, -2.0], target=[0.1, 0.2, 0.6])
    assert_matches_oracle(random_scene(4, 300, 41, 52, world_to_camera=camera), min_reliable=0.9)


def test_gaussians_behind_and_straddling_near_plane():
    # Means from 1 m behind the camera to just in front of it, scales up to 0.5 m:
    # many are culled, the rest straddle the near plane and fill the view.
    scene = random_scene(5, 300, 40, 30, depth=(-1.0, 0.6), scale=(0.01, 0.5))
    assert_matches_oracle(scene, min_reliable=0.9)


def test_gaussians_larger_than_image_and_beside_it():
    # Huge Gaussians centred outside the view: the 1.3x FOV clamp of J matters here.
    scene = random_scene(6, 30, 37, 29, spread=3.0, depth=(0.5, 2.0), scale=(0.5, 2.0))
    assert_matches_oracle(scene)


def test_needle_gaussians_crossing_many_tiles():
    # Long thin tilted Gaussians: their bounding boxes hold many tiles the ellipse misses,
    # which binning drops; every pixel they do reach must still be composited.
    scene = random_scene(18, 60, 70, 52, scale=(0.002, 0.004))
    scales = scene.scales.clone()
    scales[:, 0] = 0.6
    assert_matches_oracle(scene.with_(scales=scales))


def test_sub_pixel_gaussians():
    # Scales far below a pixel: the 0.3 px^2 dilation alone shapes them.
    assert_matches_oracle(random_scene(7, 400, 33, 31, scale=(1e-5, 1e-3)))


def test_opaque_stack_stops_at_transmittance_floor():
    scene = random_scene(8, 200, 20, 20, spread=0.3, scale=(0.1, 0.3))
    scene = scene.with_(opacities=torch.full((200,), 0.98))
    out = render_warp(scene)
    assert float(out.alpha.max()) > 1 - 1e-3  # the floor is reached somewhere
    assert_matches_oracle(scene)


def test_equal_depth_ties_break_by_index():
    # Two identical, opaque Gaussians at the same depth with different colours:
    # the one with the lower index is in front.
    means = torch.tensor([[0.0, 0.0, 2.0], [0.0, 0.0, 2.0], [0.05, 0.02, 2.0]])
    scene = random_scene(9, 3, 24, 20).with_(
        means=means, scales=torch.full((3, 3), 0.1), rotations=torch.tensor([[1.0, 0, 0, 0]] * 3),
        opacities=torch.tensor([0.99, 0.99, 0.99]), features=torch.eye(3))
    centre = render_warp(scene).features[7, 13]  # the pixel under both means
    assert centre[0] > 0.9 and centre[1] < 0.05
    swapped = render_warp(scene.with_(features=torch.eye(3)[[1, 0, 2]])).features[7, 13]
    assert swapped[1] > 0.9 and swapped[0] < 0.05
    assert_matches_oracle(scene)
    # Many Gaussians sharing one depth plane, overlapping everywhere.
    many = random_scene(10, 300, 40, 30, depth=(2.0, 2.0))
    assert_matches_oracle(many)


def test_gaussians_on_tile_borders():
    # 2D means exactly on tile edges and corners (multiples of the 8 px tile) and half a pixel beside them.
    scene = random_scene(11, 24, 50, 35, scale=(0.005, 0.05), focal=40.0)
    uv = torch.tensor([(u, v) for u in (0.0, 15.5, 16.0, 16.5, 32.0, 48.0) for v in (0.0, 16.0, 31.5, 32.0)],
                      dtype=torch.float64)
    z = 1.0 + 0.01 * torch.arange(24, dtype=torch.float64)
    (fx, fy), (cx, cy) = scene.camera.focal, scene.camera.principal_point
    means = torch.stack([(uv[:, 0] - cx) / fx * z, (uv[:, 1] - cy) / fy * z, z], dim=1)
    assert_matches_oracle(scene.with_(means=means.float()))


@pytest.mark.parametrize("channels", [1, 5])
def test_any_number_of_channels(channels):
    assert_matches_oracle(random_scene(12, 200, 30, 26, channels=channels, background=True))


def test_hard_depth_matches_oracle():
    scene = random_scene(13, 300, 40, 30)
    assert_matches_oracle(scene, hard_depth=True, delta=0.95)


def test_covariance_input_equals_scale_rotation_input():
    scene = random_scene(14, 200, 30, 30)
    by_parts = render_warp(scene)
    covariances = splat.covariances_from_scales_rotations(scene.scales, scene.rotations)
    by_matrix = splat.rasterize(scene.means, scene.opacities, scene.features, scene.camera, covariances=covariances)
    # Built in the kernel vs by splat.covariances_from_scales_rotations in torch: equal up to float32 rounding.
    for a, b in zip(by_parts, by_matrix):
        torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-5)


def test_no_gaussians_gives_background():
    scene = random_scene(15, 0, 20, 10, background=True)
    out = render_warp(scene)
    assert torch.equal(out.features, scene.background.expand(10, 20, 3))
    assert not out.alpha.any() and not out.depth.any()


def test_cpu_threads_do_not_change_the_result(monkeypatch):
    scene = random_scene(16, 2000, 70, 50)
    threaded = render_warp(scene)
    monkeypatch.setattr(composite, "CPU_THREADS", 1)
    single = render_warp(scene)
    for a, b in zip(threaded, single):
        assert torch.equal(a, b)


def test_oracle_reliability_mask_is_not_vacuous():
    # The mask must exclude pixels, but only near thresholds: a scene of many faint
    # Gaussians has pixels close to 1/255 and most pixels still decidable.
    scene = random_scene(17, 2000, 40, 30, scale=(0.005, 0.05))
    scene = scene.with_(opacities=torch.full((2000,), 0.02))
    reliable = render_oracle(scene).reliable
    assert 0.5 < float(reliable.float().mean()) < 1.0


def test_camera_scaled_to_width_keeps_the_view():
    camera = splat.Camera(np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]]), np.eye(4), 640, 480)
    half = camera.scaled_to_width(321)
    assert (half.width, half.height) == (321, 241)
    point = np.array([0.3, -0.2, 2.0])
    pixel = (camera.K @ point / point[2])[:2]
    assert np.allclose((half.K @ point / point[2])[:2], pixel * 321 / 640)  # the whole pixel frame scales


def test_bad_arguments_are_refused():
    scene = random_scene(19, 5, 10, 10)
    with pytest.raises(ValueError, match="either scales and rotations, or covariances"):
        splat.rasterize(scene.means, scene.opacities, scene.features, scene.camera, scales=scene.scales)
    with pytest.raises(ValueError, match="features must have shape"):
        splat.rasterize(scene.means, scene.opacities, scene.features[:4], scene.camera, scales=scene.scales,
                        rotations=scene.rotations)
    with pytest.raises(ValueError, match="Camera.K"):
        splat.Camera(np.eye(4), np.eye(4), 10, 10)


def test_torch_thread_setting_is_restored():
    # splat runs torch single-threaded inside (see splat.launch); the caller's setting must survive.
    scene = random_scene(20, 50, 20, 20)
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        means = scene.means.clone().requires_grad_()
        out = splat.rasterize(means, scene.opacities, scene.features, scene.camera, scales=scene.scales,
                              rotations=scene.rotations)
        assert torch.get_num_threads() == 2
        out.features.sum().backward()
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(before)


def test_non_finite_gaussians_are_culled_not_smeared():
    scene = random_scene(21, 100, 30, 20)
    clean = render_warp(scene)
    broken = scene.with_(means=torch.cat([scene.means, torch.tensor([[float("nan"), 0.0, 2.0], [0.0, 0.0, 2.0]])]),
                         scales=torch.cat([scene.scales, torch.tensor([[0.1, 0.1, 0.1], [float("inf"), 0.1, 0.1]])]),
                         rotations=torch.cat([scene.rotations, torch.tensor([[1.0, 0, 0, 0]] * 2)]),
                         opacities=torch.cat([scene.opacities, torch.tensor([0.9, 0.9])]),
                         features=torch.cat([scene.features, torch.ones(2, 3)]))
    dirty = render_warp(broken)
    for a, b in zip(clean, dirty):
        assert torch.equal(a, b)
    nan_opacity = scene.with_(opacities=torch.cat([scene.opacities[:-1], torch.tensor([float("nan")])]))
    assert torch.isfinite(render_warp(nan_opacity).features).all()
