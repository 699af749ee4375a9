"""LGM's splatter images: 14 raw channels per output pixel -> one Gaussian per pixel, in LGM's object frame.

Channels and activations (LGM's): position 0-2 clamped to [-1, 1] (the object
lives in that cube, ``rays.py``); opacity 3 through a sigmoid; scale 4-6 as
0.1 softplus (standard deviations in the cube's units); rotation 7-10 a
quaternion (w, x, y, z) normalised; colour 11-13 as 0.5 tanh + 0.5 (sRGB in [0, 1]).
Gaussian n of an object is pixel (row, col) of view v with
n = (v * s + row) * s + col, s the splatter image's side.
"""
from __future__ import annotations

import torch
import torch.nn.functional as F

from schemas.ply import GaussianCloud

OPACITY_FLOOR = 0.005
"""Gaussians below this opacity are dropped (LGM's own export does the same)."""


def activate(raw: torch.Tensor) -> torch.Tensor:
    """(..., 14) raw channels -> (..., 14) position, opacity, scale, rotation, colour after LGM's activations."""
    return torch.cat([raw[..., 0:3].clamp(-1, 1), torch.sigmoid(raw[..., 3:4]), 0.1 * F.softplus(raw[..., 4:7]),
                      F.normalize(raw[..., 7:11], dim=-1), 0.5 * torch.tanh(raw[..., 11:14]) + 0.5], dim=-1)


def decode(splatter: torch.Tensor) -> GaussianCloud:
    """One object's raw splatter images (V, 14, s, s) -> its V s^2 Gaussians (float64, LGM's object frame, the
    cube's units), pixel order as in the module doc."""
    views, channels, height, width = splatter.shape
    values = activate(splatter.detach().float().permute(0, 2, 3, 1).reshape(views * height * width, channels))
    values = values.cpu().double().numpy()
    return GaussianCloud(values[:, 0:3], values[:, 4:7], values[:, 7:11], values[:, 3], values[:, 11:14])


def prune(gaussians: GaussianCloud, floor: float = OPACITY_FLOOR) -> GaussianCloud:
    """Only the Gaussians at least ``floor`` opaque."""
    return gaussians.select(gaussians.opacities >= floor)
