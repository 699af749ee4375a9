"""Camera helpers for the input view and the extra views.

Conventions (DESIGN.md): pinhole, x right, y down, z forward; the input camera
is the world frame; pixel (row i, col j) has its centre at image point
(j + 0.5, i + 0.5).
"""
from __future__ import annotations

import math

import numpy as np


def intrinsics_from_fov(fov_deg: float, width: int, height: int) -> np.ndarray:
    """K (3,3) float64 in pixels from the VERTICAL field of view; principal point (W/2, H/2)."""
    focal = 0.5 * height / math.tan(math.radians(fov_deg) / 2)
    return np.array([[focal, 0, width / 2], [0, focal, height / 2], [0, 0, 1]], dtype=np.float64)


def working_size(width: int, height: int, resolution: int) -> tuple[int, int]:
    """(w, h) whose longest side is ``resolution`` (never upsampled), scaled as splat.Camera.scaled_to_width does."""
    scale = min(1.0, resolution / max(width, height))
    w = max(1, round(width * scale))
    return w, max(1, round(height * w / width))


def orbit_world_to_camera(center: np.ndarray, azimuth_deg: float) -> np.ndarray:
    """world_to_camera (4,4) of the input camera turned by ``azimuth_deg`` about the vertical
    axis (y) through ``center`` (3,), metres.

    Positive azimuth moves the camera towards +x (the photograph's right), so at
    90 degrees it looks at the side of the object that was at the photograph's
    right edge; the distance to ``center`` and the up direction are kept.
    """
    a = math.radians(azimuth_deg)
    # Camera-to-world rotation: the camera's axes turned about y. Its position
    # c + R (0 - c); with R = rot_y(-a) the camera swings towards +x.
    rot = np.array([[math.cos(a), 0, -math.sin(a)], [0, 1, 0], [math.sin(a), 0, math.cos(a)]])
    position = center - rot @ center
    world_to_camera = np.eye(4)
    world_to_camera[:3, :3] = rot.T
    world_to_camera[:3, 3] = -rot.T @ position
    return world_to_camera
