"""Random test scenes for the splat tests, and the comparison against the float64 oracle."""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import torch
from splat_reference import ReferenceRender, reference_covariances, render_reference

import splat

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


@dataclass
class Scene:
    means: torch.Tensor  # (G, 3) float32
    scales: torch.Tensor  # (G, 3)
    rotations: torch.Tensor  # (G, 4)
    opacities: torch.Tensor  # (G,)
    features: torch.Tensor  # (G, C)
    K: np.ndarray  # (3, 3)
    world_to_camera: np.ndarray  # (4, 4)
    width: int
    height: int
    background: torch.Tensor | None = None

    @property
    def camera(self) -> splat.Camera:
        return splat.Camera(self.K, self.world_to_camera, self.width, self.height)

    def with_(self, **changes) -> Scene:
        return replace(self, **changes)


def look_at(eye, target) -> np.ndarray:
    """world_to_camera for a camera at ``eye`` looking at ``target`` (y down)."""
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, [0.0, -1.0, 0.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    R = np.stack([right, down, forward])
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, -R @ eye
    return T


def random_scene(seed: int, num_gaussians: int, width: int, height: int, *, channels: int = 3,
                 depth=(1.5, 4.0), spread: float = 0.9, scale=(0.01, 0.2), focal: float | None = None,
                 world_to_camera: np.ndarray | None = None, background: bool = False) -> Scene:
    """G random Gaussians: camera depths uniform in ``depth`` (metres), means filling ``spread`` times
    the field of view (over 1: some off screen), log-uniform scales in ``scale`` (metres), random
    rotations, opacities and features; an off-centre principal point and unequal focal lengths."""
    g = torch.Generator().manual_seed(seed)
    focal = focal or 0.9 * max(width, height)
    z = torch.empty(num_gaussians).uniform_(*depth, generator=g)
    half_view = torch.tensor([width / (2 * focal), height / (2 * focal)])  # tan of the half field of view
    xy = (torch.rand(num_gaussians, 2, generator=g) * 2 - 1) * spread * z[:, None] * half_view
    camera_points = torch.cat([xy, z[:, None]], dim=1)
    T = np.eye(4) if world_to_camera is None else world_to_camera
    R, t = torch.tensor(T[:3, :3], dtype=torch.float32), torch.tensor(T[:3, 3], dtype=torch.float32)
    means = (camera_points - t) @ R  # world = R^T (camera - t)
    log_lo, log_hi = np.log(scale[0]), np.log(scale[1])
    scales = torch.exp(torch.empty(num_gaussians, 3).uniform_(log_lo, log_hi, generator=g))
    K = np.array([[focal, 0.0, width / 2 + 1.7], [0.0, focal * 1.1, height / 2 - 2.3], [0.0, 0.0, 1.0]])
    return Scene(
        means=means, scales=scales, rotations=torch.randn(num_gaussians, 4, generator=g),
        opacities=torch.rand(num_gaussians, generator=g), features=torch.rand(num_gaussians, channels, generator=g),
        K=K, world_to_camera=T, width=width, height=height,
        background=torch.rand(channels, generator=g) if background else None)


def render_warp(scene: Scene, device: str = "cpu", **kwargs) -> splat.Render:
    def to(x):
        return None if x is None else x.to(device)

    return splat.rasterize(to(scene.means), to(scene.opacities), to(scene.features), scene.camera,
                           scales=to(scene.scales), rotations=to(scene.rotations),
                           background=to(scene.background), **kwargs)


def render_oracle(scene: Scene, **kwargs) -> ReferenceRender:
    return render_reference(scene.means.double(), scene.opacities.double(), scene.features.double(), scene.K,
                            scene.world_to_camera, scene.width, scene.height,
                            covariances=reference_covariances(scene.scales.double(), scene.rotations.double()),
                            background=None if scene.background is None else scene.background.double(), **kwargs)


def assert_matches_oracle(scene: Scene, device: str = "cpu", min_reliable: float = 0.95, **kwargs) -> None:
    """Warp render equals the oracle to 1e-4 at every reliable pixel (depth: 1e-4 relative to the farthest)."""
    out = render_warp(scene, device, **kwargs)
    ref = render_oracle(scene, **kwargs)
    reliable = ref.reliable
    assert reliable.float().mean() >= min_reliable, "too few pixels are decidable in float32: rethink the scene"
    depth_scale = max(1.0, float(scene.means.norm(dim=1).max()) + float(np.abs(scene.world_to_camera[:3, 3]).sum()))
    checks = {"features": (out.features, ref.features, 1e-4), "alpha": (out.alpha, ref.alpha, 1e-4),
              "depth": (out.depth, ref.depth, 1e-4 * depth_scale)}
    for name, (got, want, tol) in checks.items():
        error = (got.detach().cpu().double() - want.detach()).abs()
        if error.dim() == 3:
            error = error.amax(-1)
        worst = float(error[reliable].max()) if reliable.any() else 0.0
        assert worst <= tol, f"{name}: max error {worst:.3g} > {tol:.3g} at a reliable pixel"
