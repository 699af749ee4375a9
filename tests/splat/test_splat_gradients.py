"""Gradients of the Warp path against the float64 oracle's autograd and against central differences."""
import pytest
import torch
from splat_reference import reference_covariances, render_reference
from splat_scenes import DEVICES, look_at, random_scene, render_oracle

import splat

INPUTS = ["means", "opacities", "features", "scales", "rotations", "background"]


def _scenes():
    return {
        # A quarter fully opaque, so the 0.99 alpha clamp is hit.
        "plain": random_scene(20, 40, 32, 24, background=True).with_(
            opacities=torch.rand(40, generator=torch.Generator().manual_seed(0)).clamp(max=0.75) / 0.75),
        "rotated camera, off-screen and large": random_scene(
            21, 30, 27, 22, spread=1.8, scale=(0.05, 0.6), depth=(0.8, 3.0), background=True,
            world_to_camera=look_at([0.4, -0.3, -1.0], [0.0, 0.1, 1.5])),
        "dense, transmittance floor": random_scene(22, 60, 20, 18, spread=0.4, scale=(0.05, 0.3),
                                                   background=True).with_(opacities=torch.full((60,), 0.9)),
    }


def _loss_weights(scene, seed=0):
    """Random loss weights on each output, zero where float32 rounding could flip a threshold."""
    reliable = render_oracle(scene).reliable.double()
    g = torch.Generator().manual_seed(seed)
    H, W, C = scene.height, scene.width, scene.features.shape[1]
    return (torch.randn(H, W, C, generator=g, dtype=torch.float64) * reliable[..., None],
            torch.randn(H, W, generator=g, dtype=torch.float64) * reliable,
            torch.randn(H, W, generator=g, dtype=torch.float64) * reliable)


def _weighted(render, weights):
    return sum((out * w.to(out)).sum() for out, w in zip(render[:3], weights))


def _warp_gradients(scene, weights, device="cpu", covariance_input=False, **kwargs):
    leaves = {name: getattr(scene, name).to(device).clone().requires_grad_() for name in INPUTS}
    if covariance_input:
        leaves["covariances"] = splat.covariances_from_scales_rotations(scene.scales, scene.rotations).to(
            device).requires_grad_()
        shape = {"covariances": leaves["covariances"]}
    else:
        shape = {"scales": leaves["scales"], "rotations": leaves["rotations"]}
    out = splat.rasterize(leaves["means"], leaves["opacities"], leaves["features"], scene.camera,
                          background=leaves["background"], **shape, **kwargs)
    _weighted(out, weights).backward()
    return {name: (None if leaf.grad is None else leaf.grad.cpu().double()) for name, leaf in leaves.items()}


def _oracle_loss(scene, weights, params, **kwargs):
    covariances = params.get("covariances")
    if covariances is None:
        covariances = reference_covariances(params["scales"], params["rotations"])
    out = render_reference(params["means"], params["opacities"], params["features"], scene.K, scene.world_to_camera,
                           scene.width, scene.height, covariances=covariances, background=params["background"],
                           **kwargs)
    return _weighted(out, weights)


def _oracle_gradients(scene, weights, covariance_input=False, **kwargs):
    params = {name: getattr(scene, name).double().clone().requires_grad_() for name in INPUTS}
    if covariance_input:
        params["covariances"] = reference_covariances(scene.scales.double(), scene.rotations.double()).detach()
        params["covariances"].requires_grad_()
    _oracle_loss(scene, weights, params, **kwargs).backward()
    return {name: p.grad for name, p in params.items()}


def _assert_close(got, want, name, rtol=1e-3):
    scale = float(want.abs().max())
    error = float((got - want).abs().max())
    assert error <= rtol * max(scale, 1e-6), f"{name}: gradient error {error:.3g} vs magnitude {scale:.3g}"


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("scene_name", list(_scenes()))
def test_gradients_match_oracle_autograd(scene_name, device):
    scene = _scenes()[scene_name]
    weights = _loss_weights(scene)
    got = _warp_gradients(scene, weights, device)
    want = _oracle_gradients(scene, weights)
    for name in INPUTS:
        assert float(want[name].abs().max()) > 0, f"{name}: the oracle gradient is zero, the test proves nothing"
        _assert_close(got[name], want[name], name)


def test_covariance_gradients_match_oracle_autograd():
    scene = _scenes()["rotated camera, off-screen and large"]
    weights = _loss_weights(scene, seed=1)
    got = _warp_gradients(scene, weights, covariance_input=True)
    want = _oracle_gradients(scene, weights, covariance_input=True)
    for name in ["means", "opacities", "features", "background", "covariances"]:
        _assert_close(got[name], want[name], name)


def test_hard_depth_gradients_reach_means_only():
    scene = _scenes()["plain"]
    weights = _loss_weights(scene, seed=2)
    got = _warp_gradients(scene, weights, hard_depth=True, delta=0.95)
    want = _oracle_gradients(scene, weights, hard_depth=True, delta=0.95)
    _assert_close(got["means"], want["means"], "means")
    for name in ["opacities", "features", "scales", "rotations", "background"]:
        assert got[name] is None, f"hard depth must not send gradients to {name}"


@pytest.mark.parametrize("name", INPUTS + ["covariances"])
def test_gradients_match_central_differences(name):
    # Directional derivative along a random direction: the Warp gradient against
    # (L(x + eps v) - L(x - eps v)) / 2 eps of the float64 oracle's forward pass.
    scene = _scenes()["rotated camera, off-screen and large"]
    weights = _loss_weights(scene, seed=3)
    covariance_input = name == "covariances"
    got = _warp_gradients(scene, weights, covariance_input=covariance_input)[name]
    params = {n: getattr(scene, n).double() for n in INPUTS}
    if covariance_input:
        params["covariances"] = reference_covariances(params["scales"], params["rotations"])
    direction = torch.randn(params[name].shape, generator=torch.Generator().manual_seed(4), dtype=torch.float64)
    if covariance_input:
        direction = direction + direction.transpose(1, 2)  # stay symmetric
    eps = 1e-6
    with torch.no_grad():
        plus = _oracle_loss(scene, weights, {**params, name: params[name] + eps * direction})
        minus = _oracle_loss(scene, weights, {**params, name: params[name] - eps * direction})
    numeric = float(plus - minus) / (2 * eps)
    analytic = float((got * direction).sum())
    assert abs(numeric) > 1e-3, "the loss does not depend on this input: the test proves nothing"
    assert abs(analytic - numeric) <= 2e-3 * abs(numeric) + 1e-4, f"{name}: {analytic} vs {numeric}"
