"""The artifacts' pinhole camera: how a camera-frame point lands on the photograph.

The camera frame has x right, y down and z forward (away from the camera), in metres; K (3, 3) are
the intrinsics of gaussians.h5's /camera/K (and coarse.h5's), in pixels, with the centre of pixel
(i, j) at image point (j + 0.5, i + 0.5).
"""
from __future__ import annotations

import numpy as np

# Depth (m) below which a point counts as on the camera plane: points there or behind it project
# to far outside the picture instead of dividing by zero.
MIN_DEPTH = 1e-9


def project_points(points, K):
    """(..., 2) image points u = fx x / z + cx, v = fy y / z + cy, pixels, of (..., 3) camera-frame
    points (m) under intrinsics K (3, 3); numpy arrays or torch tensors (this module imports neither
    torch nor splat, so the stages that only need numpy start without them)."""
    z = points[..., 2:3]
    z = z.clamp_min(MIN_DEPTH) if hasattr(z, "clamp_min") else z.clip(min=MIN_DEPTH)
    return points[..., :2] / z * K[[0, 1], [0, 1]] + K[:2, 2]


def pixel_rays(K: np.ndarray, height: int, width: int) -> np.ndarray:
    """Unit ray directions (H,W,3) float64, camera frame, through every pixel centre under intrinsics K (3,3)."""
    j, i = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    uv1 = np.stack([j, i, np.ones_like(j)], axis=-1)
    rays = uv1 @ np.linalg.inv(K).T
    return rays / np.linalg.norm(rays, axis=-1, keepdims=True)
