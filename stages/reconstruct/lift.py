"""Initial Gaussians: the front surface lifted from the depth prior, the back closed, the rim walled.

The simulator fills each object's interior by ray parity on an occupancy grid,
so the Gaussians of one object must enclose a volume: front sheet + back sheet
+ a wall along the silhouette between them. Each surface Gaussian is a flat
disc (surfel) tangent to its sheet, sized to cover its pixel's footprint.
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
from scipy import ndimage
from scipy.spatial.transform import Rotation

from schemas.camera import pixel_rays

from .depth import ObjectDepth

SIGMA_PER_SPACING = 0.6
"""Surfel standard deviation per sample spacing: neighbours overlap, so the sheet has no gaps."""
MAX_STRETCH = 4.0
"""A steep surfel stretches along the slope at most this many spacings (the rim wall closes the rest)."""
THICKNESS_PER_SPACING = 0.15
"""Surfel thickness (along its normal) per sample spacing."""
INITIAL_OPACITY = 0.9


@dataclass
class Gaussians:
    """G Gaussians (DESIGN.md conventions): means (G,3) m, scales (G,3) m, rotations (G,4) wxyz,
    opacities (G,) in [0,1], colors (G,3) sRGB in [0,1], object_id (G,) int."""

    means: np.ndarray
    scales: np.ndarray
    rotations: np.ndarray
    opacities: np.ndarray
    colors: np.ndarray
    object_id: np.ndarray

    def __len__(self) -> int:
        return len(self.means)

    @staticmethod
    def concatenate(parts: list["Gaussians"]) -> "Gaussians":
        return Gaussians(**{f.name: np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(Gaussians)})

    def select(self, keep: np.ndarray) -> "Gaussians":
        return Gaussians(**{f.name: getattr(self, f.name)[keep] for f in fields(Gaussians)})


def _filled(depth: np.ndarray) -> np.ndarray:
    """``depth`` with NaNs replaced by the nearest valid value, so finite differences work at the rim."""
    invalid = ~np.isfinite(depth)
    _, (rows, cols) = ndimage.distance_transform_edt(invalid, return_indices=True)
    return depth[rows, cols]


def _surfels(points: np.ndarray, pixels: np.ndarray, stride: int, colors: np.ndarray, object_id: int) -> Gaussians:
    """Surfels at ``points`` (H,W,3) on the pixels (H,W bool) of a stride-``stride`` grid."""
    d_col = np.gradient(points, axis=1) * stride  # metres between neighbouring samples
    d_row = np.gradient(points, axis=0) * stride
    d_col, d_row, centres = d_col[pixels], d_row[pixels], points[pixels]
    normal = np.cross(d_col, d_row)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True) + 1e-12
    axis1 = d_col - (d_col * normal).sum(1, keepdims=True) * normal
    axis1 /= np.linalg.norm(axis1, axis=1, keepdims=True) + 1e-12
    axis2 = np.cross(normal, axis1)
    # The un-stretched spacing: one sample's footprint, the smaller of the two tangent lengths' in-plane parts.
    len1 = np.abs((d_col * axis1).sum(1))
    len2 = np.abs((d_row * axis2).sum(1))
    spacing = np.minimum(len1, len2)
    scales = SIGMA_PER_SPACING * np.stack([np.minimum(len1, MAX_STRETCH * spacing),
                                           np.minimum(len2, MAX_STRETCH * spacing),
                                           THICKNESS_PER_SPACING / SIGMA_PER_SPACING * spacing], axis=1)
    rotations = Rotation.from_matrix(np.stack([axis1, axis2, normal], axis=2)).as_quat(scalar_first=True)
    count = len(centres)
    return Gaussians(centres, scales, rotations, np.full(count, INITIAL_OPACITY), colors[pixels],
                     np.full(count, object_id))


def _rim_wall(front: np.ndarray, back: np.ndarray, pixels: np.ndarray, spacing: np.ndarray, colors: np.ndarray,
              object_id: int) -> Gaussians:
    """Isotropic Gaussians from the front surface (H,W,3) to the back (H,W,3) along the rays of the
    silhouette's edge pixels, one spacing (H,W) apart."""
    edge = pixels & ~ndimage.binary_erosion(pixels, border_value=0)
    rows, cols = np.nonzero(edge)
    counts = np.maximum(1, np.ceil(np.linalg.norm(back - front, axis=-1)[edge] / spacing[edge]).astype(int) - 1)
    steps = np.concatenate([(np.arange(1, c + 1) / (c + 1)) for c in counts])
    idx = np.repeat(np.arange(len(rows)), counts)
    start, end = front[rows[idx], cols[idx]], back[rows[idx], cols[idx]]
    means = start + steps[:, None] * (end - start)
    sigma = SIGMA_PER_SPACING * spacing[rows[idx], cols[idx]]
    count = len(means)
    return Gaussians(means, np.repeat(sigma[:, None], 3, axis=1), np.tile([1.0, 0, 0, 0], (count, 1)),
                     np.full(count, INITIAL_OPACITY), colors[rows[idx], cols[idx]], np.full(count, object_id))


def lift_object(depth: ObjectDepth, K: np.ndarray, photo: np.ndarray, object_id: int,
                front_stride: int = 1, back_stride: int = 2) -> tuple[Gaussians, np.ndarray]:
    """Closed surface of Gaussians of one object: its front and back where each pixel's ray enters and
    leaves the body the prior describes (closure.py), walled along the silhouette's edge.

    Args:
        depth: camera-space front/back z (H,W) of the object at the lifting resolution, NaN off it.
        K: (3,3) intrinsics at that resolution.
        photo: RGB u8 (H,W,3) at that resolution; front and back take the pixel's colour.
        front_stride, back_stride: sample every n-th pixel (the back is never seen, so it can be coarser).

    Returns:
        The Gaussians, and which of them lie on the front, the surface the photograph sees, (G,) bool.
    """
    height, width = depth.front.shape
    rays = pixel_rays(K, height, width)
    rays = rays / rays[..., 2:3]  # point = ray * z
    colors = photo.astype(np.float64) / 255.0
    pixels = depth.pixels
    front = rays * _filled(depth.front)[..., None]
    back = rays * _filled(depth.back)[..., None]
    parts = []
    for points, stride in ((front, front_stride), (back, back_stride)):
        grid = np.zeros_like(pixels)
        grid[stride // 2::stride, stride // 2::stride] = True
        parts.append(_surfels(points, pixels & grid, stride, colors, object_id))
    wall_spacing = back_stride * depth.front / K[0, 0]  # metres per pixel at the front surface, times the stride
    parts.append(_rim_wall(front, back, pixels, wall_spacing, colors, object_id))
    # The photograph sees the front, but not where it was cut onto the base the body stands on.
    front_grid = np.zeros_like(pixels)
    front_grid[front_stride // 2::front_stride, front_stride // 2::front_stride] = True
    on_base = depth.base if depth.base is not None else np.zeros_like(pixels)
    seen = np.zeros(sum(map(len, parts)), bool)
    seen[:len(parts[0])] = ~on_base[pixels & front_grid]
    return Gaussians.concatenate(parts), seen
