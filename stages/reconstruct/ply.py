"""Initial Gaussians from a 3DGS PLY made by another tool (LGM and the like), placed into the input camera.

Coordinate conversion: such tools build the object centred near the origin in
an OpenGL-style frame, x right, y up, z towards the camera of the input view.
physmotion's world is the input camera (x right, y down, z forward), so the
cloud is turned 180 degrees about x (x, y, z) -> (x, -y, -z), its rotations
likewise (q -> q_x(180) q); then scaled uniformly so that the largest extent of
its means is size_m; then moved along the ray through the centre of the
object's mask bounding box to the distance where the projection of its means
is as wide or high (the larger) as the mask. Its near side projects larger
than its far side, so that distance is solved for (the extent falls
monotonically with distance) rather than taken as focal * extent_m / extent_px.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.optimize import brentq
from scipy.spatial.transform import Rotation

from schemas.ply import read_ply

from .lift import Gaussians

OPENGL_TO_CAMERA = Rotation.from_euler("x", 180, degrees=True)


def opengl_to_camera(means: np.ndarray, rotations: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Means (N,3) and rotations (N,4) wxyz of an OpenGL-framed cloud turned into the camera's axes."""
    turned = OPENGL_TO_CAMERA * Rotation.from_quat(rotations, scalar_first=True)
    return OPENGL_TO_CAMERA.apply(means), turned.as_quat(scalar_first=True)


def mask_box(mask: np.ndarray) -> tuple[int, np.ndarray]:
    """The larger side (px) of the bounding box of ``mask`` (H,W bool) and its centre (u, v, 1) (3,), px."""
    rows, cols = np.nonzero(mask)
    extent_px = max(cols.max() + 1 - cols.min(), rows.max() + 1 - rows.min())
    return extent_px, np.array([(cols.min() + cols.max() + 1) / 2, (rows.min() + rows.max() + 1) / 2, 1.0])


def distance_for_extent(means: np.ndarray, focal: float, extent_px: float) -> float:
    """Camera-space depth (m) of the centre of ``means`` (N,3, centred) on the optical axis at which
    their projection is ``extent_px`` wide or high (the larger), ``focal`` in px."""
    def excess(distance: float) -> float:
        image = focal * means[:, :2] / (means[:, 2:3] + distance)
        return float((image.max(0) - image.min(0)).max()) - extent_px

    # Just in front of the nearest point the projection is unbounded; four times the pinhole
    # distance of the largest extent beyond it, it is at most a quarter of extent_px.
    nearest = 1.001 * float(-means[:, 2].min()) + 1e-6
    farthest = nearest + 4 * focal * float((means.max(0) - means.min(0)).max()) / extent_px
    return brentq(excess, nearest, farthest)


def place_ply(path: Path, mask: np.ndarray, K: np.ndarray, size_m: float, object_id: int = 0) -> Gaussians:
    """Gaussians of the PLY at ``path`` placed onto the object ``mask`` (H,W bool) of the camera ``K`` (3,3)."""
    cloud = read_ply(path)
    means, rotations = opengl_to_camera(cloud.means.astype(np.float64), cloud.rotations)
    low, high = means.min(0), means.max(0)
    scale = size_m / float((high - low).max())
    means = (means - (low + high) / 2) * scale
    extent_px, centre_px = mask_box(mask)
    distance = distance_for_extent(means, K[1, 1], extent_px)
    centre = np.linalg.inv(K) @ centre_px * distance  # on that ray, at camera-space depth `distance`
    count = len(means)
    return Gaussians(means + centre, cloud.scales.astype(np.float64) * scale, rotations,
                     cloud.opacities.astype(np.float64), cloud.colors.astype(np.float64),
                     np.full(count, object_id))
