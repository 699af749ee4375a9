"""The public entry point: project, bin, composite."""
from __future__ import annotations

from typing import NamedTuple

import torch

from .binning import bin_gaussians
from .camera import Camera
from .composite import composite
from .launch import torch_single_threaded
from .project import project_gaussians


class Render(NamedTuple):
    """features (H, W, C) over the background; alpha (H, W); depth (H, W) in metres, Eq. 2 (not divided by alpha)."""

    features: torch.Tensor
    alpha: torch.Tensor
    depth: torch.Tensor


def _check(name: str, tensor: torch.Tensor, shape: tuple, device: torch.device) -> torch.Tensor:
    """``tensor`` as float32 after checking its shape (None in ``shape``: any size) and device."""
    if tensor.dim() != len(shape) or any(want not in (None, got) for want, got in zip(shape, tensor.shape)):
        raise ValueError(f"rasterize: {name} must have shape {shape}, got {tuple(tensor.shape)}")
    if tensor.device != device:
        raise ValueError(f"rasterize: {name} is on {tensor.device}, means on {device}")
    return tensor.float()


@torch_single_threaded()
def rasterize(means: torch.Tensor, opacities: torch.Tensor, features: torch.Tensor, camera: Camera, *,
              scales: torch.Tensor | None = None, rotations: torch.Tensor | None = None,
              covariances: torch.Tensor | None = None, background: torch.Tensor | None = None,
              hard_depth: bool = False, delta: float = 0.95) -> Render:
    """Render 3D Gaussians with standard 3DGS semantics, differentiably.

    Args:
        means: (G, 3) world positions, metres.
        opacities: (G,) in [0, 1].
        features: (G, C) any number of channels (colour, source-pixel coordinates, ...).
        camera: the view; its size is the output size.
        scales, rotations: (G, 3) linear standard deviations in metres and (G, 4) quaternions
            (w, x, y, z); or instead
        covariances: (G, 3, 3) world covariances, metres^2.
        background: (C,) composited behind the Gaussians; zeros by default.
        hard_depth: paper Eq. 8: every opacity becomes ``delta`` so only the nearest Gaussians
            are seen, and gradients reach the means only.
        delta: the hard-depth opacity.
    Returns:
        Render on the device of ``means`` (Warp runs on the matching device). Computation is
        float32; gradients flow to every tensor argument (to ``means`` only with hard_depth).
    """
    if (covariances is None) == (scales is None or rotations is None):
        raise ValueError("rasterize: pass either scales and rotations, or covariances")
    if not 0.0 < delta <= 1.0:
        raise ValueError(f"rasterize: delta must be in (0, 1], got {delta}")
    device, G = means.device, means.shape[0]
    means = _check("means", means, (G, 3), device)
    opacities = _check("opacities", opacities, (G,), device)
    features = _check("features", features, (G, None), device)
    if covariances is None:
        shape = {"scales": _check("scales", scales, (G, 3), device),
                 "rotations": _check("rotations", rotations, (G, 4), device)}
    else:
        shape = {"covariances": _check("covariances", covariances, (G, 3, 3), device)}
    C = features.shape[1]
    background = torch.zeros(C, device=device) if background is None else _check("background", background, (C,),
                                                                                   device)
    if hard_depth:
        opacities = torch.full_like(opacities, delta)
        shape = {name: tensor.detach() for name, tensor in shape.items()}
        features, background = features.detach(), background.detach()

    projection = project_gaussians(means, camera, **shape)
    bins = bin_gaussians(projection.means2d, projection.conics, opacities, projection.depths,
                         camera.width, camera.height)
    return Render(*composite(projection.means2d, projection.conics, opacities, projection.distances,
                             features, background, bins, camera.width, camera.height))
