"""Pinhole camera shared by the rasterizer and its callers.

Conventions (DESIGN.md): x right, y down, z forward; the centre of pixel
(row i, col j) is the image point (j + 0.5, i + 0.5).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch


def _as_float64(value, name: str, shape: tuple[int, ...]) -> np.ndarray:
    array = value.detach().cpu().numpy() if isinstance(value, torch.Tensor) else np.asarray(value)
    array = array.astype(np.float64)
    if array.shape != shape:
        raise ValueError(f"Camera.{name} must have shape {shape}, got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"Camera.{name} has non-finite entries")
    return array


@dataclass(frozen=True)
class Camera:
    """A pinhole camera.

    Args:
        K: (3, 3) intrinsics in pixels, torch or numpy; no skew.
        world_to_camera: (4, 4) rigid transform from world to camera frame, torch or numpy.
        width, height: image size in pixels.

    Both matrices are kept as float64 numpy arrays: the camera is a constant
    of the render, never optimised through.
    """

    K: np.ndarray
    world_to_camera: np.ndarray
    width: int
    height: int

    def __init__(self, K, world_to_camera, width: int, height: int):
        object.__setattr__(self, "K", _as_float64(K, "K", (3, 3)))
        object.__setattr__(self, "world_to_camera", _as_float64(world_to_camera, "world_to_camera", (4, 4)))
        if int(width) < 1 or int(height) < 1:
            raise ValueError(f"Camera size must be positive, got {width}x{height}")
        object.__setattr__(self, "width", int(width))
        object.__setattr__(self, "height", int(height))

    @property
    def focal(self) -> tuple[float, float]:
        """(fx, fy) in pixels."""
        return float(self.K[0, 0]), float(self.K[1, 1])

    @property
    def principal_point(self) -> tuple[float, float]:
        """(cx, cy) in pixels."""
        return float(self.K[0, 2]), float(self.K[1, 2])

    def scaled_to_width(self, width: int) -> Camera:
        """The same camera rendering ``width`` pixels wide.

        Artifacts store K at the photograph's full size; rendering at width w
        scales the whole pixel frame by w / W and rounds the height.
        """
        scale = width / self.width
        K = self.K.copy()
        K[:2] *= scale
        return Camera(K, self.world_to_camera, width, max(1, round(self.height * scale)))
