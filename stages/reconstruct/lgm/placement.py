"""LGM's Gaussians placed into the input camera, and which of them the photograph sees.

Placement (the paper's Sec. 3.3 start): the object frame is OpenGL's with view 0
facing the photograph, so the cloud turns 180 degrees about x into the camera's
axes (``ply.opengl_to_camera``); it is scaled so that its largest extent (of the
1st-99th percentile box of its means, robust to LGM's floaters) is size_m, and
centred on the ray through the mask's bounding-box centre at the distance
where it projects as large as the mask (``ply.distance_for_extent``). The depth
prior then sets the distance: the cloud moves along that ray by the median gap
between the prior's front and the nearest Gaussian in each mask pixel. Last,
the mask carves: Gaussians whose centres project outside the (slightly grown)
mask contradict the photograph and are dropped.
"""
from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

from schemas.camera import project_points
from schemas.ply import GaussianCloud

from ..lift import Gaussians
from ..ply import distance_for_extent, mask_box, opengl_to_camera

ROBUST_PERCENTILES = (1.0, 99.0)
CARVE_MARGIN = 0.02
"""The mask grows by this share of its larger bounding-box side (at least one pixel) before carving."""
FRONT_LAYER = 0.03
"""A Gaussian within this share of size_m behind the nearest one in its pixel counts as seen."""
GAUSSIANS_PER_PIXEL = 8
"""Gaussians per object pixel when telling the seen ones: about half of them on the near side."""


def pixels_of(means: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixel columns and rows (N,) int of camera-space points (N,3) m, by the pixel they fall in."""
    uv = np.floor(project_points(means, K)).astype(int)
    return uv[:, 0], uv[:, 1]


def nearest_depth(means: np.ndarray, K: np.ndarray, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """The z-buffer (H,W) of the points (inf where none falls) and each point's pixel index (N,), -1 off the image."""
    height, width = shape
    cols, rows = pixels_of(means, K)
    inside = (cols >= 0) & (cols < width) & (rows >= 0) & (rows < height) & (means[:, 2] > 0)
    index = np.where(inside, rows * width + cols, -1)
    zbuffer = np.full(height * width, np.inf)
    np.minimum.at(zbuffer, index[inside], means[inside, 2])
    return zbuffer.reshape(shape), index


def place(cloud: GaussianCloud, mask: np.ndarray, K: np.ndarray, size_m: float, front: np.ndarray,
          object_id: int = 0) -> Gaussians:
    """LGM's ``cloud`` in the camera ``K`` (3,3) on the object ``mask`` (H,W bool), size_m metres across, its
    front at the prior's camera-space depths ``front`` (H,W, NaN off the object)."""
    means, rotations = opengl_to_camera(cloud.means, cloud.rotations)
    low, high = np.percentile(means, ROBUST_PERCENTILES, axis=0)
    scale = size_m / float((high - low).max())
    means = (means - (low + high) / 2) * scale
    core = np.all((means >= (low - (low + high) / 2) * scale) & (means <= (high - (low + high) / 2) * scale), axis=1)
    extent_px, centre_px = mask_box(mask)
    distance = distance_for_extent(means[core], K[1, 1], extent_px)
    ray = np.linalg.inv(K) @ centre_px
    means = means + ray * distance  # ray has z = 1: the centre at camera-space depth `distance`
    zbuffer, _ = nearest_depth(means, K, mask.shape)
    gap = (front - zbuffer)[mask & np.isfinite(front) & np.isfinite(zbuffer)]
    if gap.size:
        means = means + ray * float(np.median(gap))
    margin = max(1, round(CARVE_MARGIN * extent_px))
    grown = ndimage.binary_dilation(mask, iterations=margin)
    _, index = nearest_depth(means, K, mask.shape)
    keep = (index >= 0) & grown.reshape(-1)[np.maximum(index, 0)]
    return Gaussians(means[keep], cloud.scales[keep] * scale, rotations[keep], cloud.opacities[keep],
                     cloud.colors[keep], np.full(int(keep.sum()), object_id))


def seen_from_camera(gaussians: Gaussians, K: np.ndarray, mask: np.ndarray, size_m: float) -> np.ndarray:
    """(G,) bool: the Gaussians within FRONT_LAYER size_m of the nearest one in their pixel of the camera ``K``,
    on pixels coarsened until the object's ``mask`` (H,W bool) holds GAUSSIANS_PER_PIXEL of them a pixel (a pixel
    with one Gaussian would call it seen wherever it lies)."""
    coarsen = max(1.0, math.sqrt(GAUSSIANS_PER_PIXEL * float(mask.sum()) / max(1, len(gaussians))))
    coarse = np.diag([1 / coarsen, 1 / coarsen, 1.0]) @ K
    shape = (math.ceil(mask.shape[0] / coarsen), math.ceil(mask.shape[1] / coarsen))
    zbuffer, index = nearest_depth(gaussians.means, coarse, shape)
    nearest = np.where(index >= 0, zbuffer.reshape(-1)[np.maximum(index, 0)], np.inf)
    return gaussians.means[:, 2] <= nearest + FRONT_LAYER * size_m
