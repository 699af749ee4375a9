"""LGM's splatter images: 14 raw channels per output pixel -> one Gaussian per pixel, in LGM's object frame.

Channels and activations (LGM's): position 0-2 clamped to [-1, 1] (the object
lives in that cube, ``rays.py``); opacity 3 through a sigmoid; scale 4-6 as
0.1 softplus (standard deviations in the cube's units); rotation 7-10 a
quaternion (w, x, y, z) normalised; colour 11-13 as 0.5 tanh + 0.5 (sRGB in [0, 1]).
Gaussian n of an object is pixel (row, col) of view v with
n = (v * s + row) * s + col, s the splatter image's side.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

OPACITY_FLOOR = 0.005
"""Gaussians below this opacity are dropped (LGM's own export does the same)."""


@dataclass
class SplatterGaussians:
    """N Gaussians in LGM's object frame (OpenGL, ``rays.py``): means (N,3), scales (N,3) standard deviations,
    rotations (N,4) wxyz, opacities (N,), colors (N,3) sRGB in [0,1], all float64 numpy."""

    means: np.ndarray
    scales: np.ndarray
    rotations: np.ndarray
    opacities: np.ndarray
    colors: np.ndarray

    def __len__(self) -> int:
        return len(self.means)

    def select(self, keep: np.ndarray) -> "SplatterGaussians":
        return SplatterGaussians(self.means[keep], self.scales[keep], self.rotations[keep], self.opacities[keep],
                                 self.colors[keep])


def activate(raw: torch.Tensor) -> torch.Tensor:
    """(..., 14) raw channels -> (..., 14) position, opacity, scale, rotation, colour after LGM's activations."""
    return torch.cat([raw[..., 0:3].clamp(-1, 1), torch.sigmoid(raw[..., 3:4]), 0.1 * F.softplus(raw[..., 4:7]),
                      F.normalize(raw[..., 7:11], dim=-1), 0.5 * torch.tanh(raw[..., 11:14]) + 0.5], dim=-1)


def decode(splatter: torch.Tensor) -> SplatterGaussians:
    """One object's raw splatter images (V, 14, s, s) -> its V s^2 Gaussians, pixel order as in the module doc."""
    views, channels, height, width = splatter.shape
    values = activate(splatter.detach().float().permute(0, 2, 3, 1).reshape(views * height * width, channels))
    values = values.cpu().double().numpy()
    return SplatterGaussians(values[:, 0:3], values[:, 4:7], values[:, 7:11], values[:, 3], values[:, 11:14])


def prune(gaussians: SplatterGaussians, floor: float = OPACITY_FLOOR) -> SplatterGaussians:
    """Only the Gaussians at least ``floor`` opaque."""
    return gaussians.select(gaussians.opacities >= floor)
