"""Synthetic inputs for tests and benchmarks: Gaussians on the surface of boxes and spheres."""
from __future__ import annotations

import numpy as np

from schemas.solid import SolidGrid, gravity_axes


def box_surface(lo, hi, spacing: float) -> np.ndarray:
    """Points (N,3) on the six faces of the axis-aligned box [lo, hi] (m), about `spacing` apart."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    # round() before ceil: 0.28 - 0.2 is 0.08000000000000002, which must not buy a box an extra row
    steps = [int(np.ceil(round((hi[a] - lo[a]) / spacing, 9))) for a in range(3)]
    axes = [np.linspace(lo[a], hi[a], max(2, steps[a] + 1)) for a in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1)
    on_face = np.zeros(grid.shape[:3], bool)
    for a in range(3):
        on_face |= np.isclose(grid[..., a], lo[a]) | np.isclose(grid[..., a], hi[a])
    return grid[on_face]


def boxes(*extents, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Means (G,3) and object ids (G,) of one box per (lo, hi) pair, object k = k-th box."""
    means = [box_surface(lo, hi, spacing) for lo, hi in extents]
    return np.concatenate(means), np.concatenate([np.full(len(m), k) for k, m in enumerate(means)])


def fibonacci_sphere(n: int, radius: float) -> np.ndarray:
    """(n, 3) points spread evenly over a sphere about the origin (m)."""
    i = np.arange(n) + 0.5
    polar, azimuth = np.arccos(1 - 2 * i / n), np.pi * (1 + 5 ** 0.5) * i
    return radius * np.stack([np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar), np.cos(polar)], 1)


def sphere_surfels(n: int, radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """n flat Gaussians tangent to a sphere of ``radius`` m about the origin, spread evenly over it: unit
    normals (n,3), scales (n,3) m (thin along the normal) and rotations (n,4) wxyz taking z onto the normal."""
    normals = fibonacci_sphere(n, 1.0)
    spacing = np.sqrt(4 * np.pi / n) * radius
    rotations = np.stack([1 + normals[:, 2], -normals[:, 1], normals[:, 0], np.zeros(n)], 1)
    rotations /= np.linalg.norm(rotations, axis=1, keepdims=True)
    return normals, np.tile([0.6 * spacing, 0.6 * spacing, 0.05 * spacing], (n, 1)), rotations


def sphere_solid(centre: np.ndarray, radius: float, nodes: int = 48) -> SolidGrid:
    """The signed distance of a ball (centre (3,) m, radius m) on a grid aligned with default gravity, as
    pm-reconstruct passes a solid on."""
    spacing = 2.4 * radius / (nodes - 1)
    axes = gravity_axes(np.array([0.0, 1.0, 0.0]))
    ijk = np.stack(np.meshgrid(*[np.arange(nodes)] * 3, indexing="ij"), axis=-1) - 0.5 * (nodes - 1)
    return SolidGrid(np.linalg.norm(ijk * spacing, axis=-1) - radius, np.asarray(centre, float), axes, spacing)
