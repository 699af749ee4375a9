"""Metric depth prior of each object: a silhouette-inflation prior, or a DPT/MiDaS model.

Both give, per object pixel, the camera-space depth z (metres) of the front
surface and of the back surface. The object is placed so that its largest
extent is size_m (DESIGN.md): every depth scales linearly with the distance,
so the shape is built at unit distance and then scaled.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Sequence

import cv2
import numpy as np
from scipy import ndimage

from .geometry import pixel_rays
from .local_model import load_local_model


EDGE_OFFSET_PX = 0.3
"""Mean distance (pixels) from the silhouette edge to the nearest outside pixel centre."""


def inflation_half_thickness(mask: np.ndarray) -> np.ndarray:
    """Half the object's thickness (H,W) in pixels, 0 off the mask, from round cross-sections.

    Each pixel at distance d from the silhouette, whose nearest medial-axis point
    lies R from the silhouette, gets sqrt(R^2 - (R - d)^2): exact for a sphere
    (R its radius) and for a cylinder seen side-on (R its radius).
    """
    padded = np.pad(mask.astype(bool), 1)  # objects cut by the image border close at the border
    dist, nearest = ndimage.distance_transform_edt(padded, return_indices=True)
    # To the silhouette edge: it lies between the last inside and the first outside pixel centre, on
    # average 0.5 px before the latter on straight axis-aligned edges and 0.2-0.35 px on curved ones
    # (measured on ray-cast discs); 0.3 balances the two.
    dist = np.where(padded, dist - EDGE_OFFSET_PX, 0.0)
    rows, cols = np.indices(padded.shape)
    to_edge = np.stack([nearest[0] - rows, nearest[1] - cols]).astype(np.float64)
    to_edge /= np.maximum(np.linalg.norm(to_edge, axis=0), 1e-9)
    # Medial axis: where neighbours' directions to their nearest silhouette point turn by more than 90 degrees.
    axis = np.zeros_like(padded)
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
        here = (slice(1, -1), slice(1, -1))
        there = (slice(1 + dr, padded.shape[0] - 1 + dr), slice(1 + dc, padded.shape[1] - 1 + dc))
        turned = (to_edge[(slice(None),) + here] * to_edge[(slice(None),) + there]).sum(0) < 0
        turned &= padded[here] & padded[there]
        axis[here] |= turned
        axis[there] |= turned
    if not axis.any():  # a one-pixel-wide mask
        axis = padded.copy()
    _, axis_index = ndimage.distance_transform_edt(~axis, return_indices=True)
    # Flagged pixels come in pairs straddling the true axis, each about half a pixel from it.
    radius = dist[axis_index[0], axis_index[1]] + 0.5
    d = np.minimum(dist, radius)
    half = np.sqrt(np.maximum(radius ** 2 - (radius - d) ** 2, 0.0))
    return np.where(padded, half, 0.0)[1:-1, 1:-1]


@dataclass
class ObjectDepth:
    """Camera-space depths (H,W) in metres of one object's front and back surface; NaN off the object."""

    front: np.ndarray
    back: np.ndarray

    @property
    def pixels(self) -> np.ndarray:
        """Boolean (H,W): the object's pixels."""
        return np.isfinite(self.front)

    def along_ray(self, K: np.ndarray) -> np.ndarray:
        """The front depth as distance along the ray from the camera centre (DESIGN.md's depth_prior)."""
        height, width = self.front.shape
        ray_z = pixel_rays(K, height, width)[..., 2]
        return self.front / ray_z


def unit_distance_shape(mask: np.ndarray, focal: float,
                        front_inverse_depth: Optional[np.ndarray] = None) -> ObjectDepth:
    """Front and back z at unit distance of the silhouette's centre plane.

    Inflation: z = 1 -/+ h / focal. With ``front_inverse_depth`` (a relative
    inverse depth such as MiDaS gives, any scale and shift) the front is that
    map aligned to the inflation front by least squares in inverse depth (as
    MiDaS is evaluated); the back stays the front plus the inflation thickness.
    """
    half = inflation_half_thickness(mask) / focal
    front, back = 1.0 - half, 1.0 + half
    if front_inverse_depth is not None:
        target = 1.0 / front[mask]
        design = np.stack([front_inverse_depth[mask], np.ones(mask.sum())], axis=1)
        (scale, shift), *_ = np.linalg.lstsq(design, target, rcond=None)
        aligned = scale * front_inverse_depth + shift
        floor = 1.0 / (1.0 + 2 * half.max() + 1.0 / focal)  # never behind the inflation's back
        front = np.where(mask, 1.0 / np.maximum(aligned, floor), np.nan)
        back = front + 2 * half
    return ObjectDepth(np.where(mask, front, np.nan), np.where(mask, back, np.nan))


def largest_extent_px(mask: np.ndarray) -> float:
    """Largest extent (pixels) of a silhouette: the longest side of its box aligned with the principal
    axes of its pixels, so that a tilted object measures its own length, not an axis-aligned box's width."""
    points = np.argwhere(mask).astype(np.float64)
    points -= points.mean(0)
    _, axes = np.linalg.eigh(points.T @ points)
    along = points @ axes
    return float((along.max(0) - along.min(0)).max()) + 1.0  # pixel centres to pixel edges


def object_depths(labels: np.ndarray, K: np.ndarray, sizes_m: Sequence[float],
                  inverse_depth: Optional[np.ndarray] = None) -> list[ObjectDepth]:
    """Metric front/back depths of each object (labels k+1).

    Its largest extent is sizes_m[k]: the larger of the silhouette's extent and
    the inflation's thickness, both in pixels, equals size_m at the distance
    Z = size_m * focal / extent_px of the silhouette's centre plane. (Measuring
    the lifted 3D points instead over-sizes by a few percent: the back of the
    rim spreads along the diverging rays.)
    """
    out = []
    for k, size in enumerate(sizes_m):
        mask = labels == k + 1
        focal = K[1, 1]
        shape = unit_distance_shape(mask, focal, inverse_depth)
        extent_px = max(largest_extent_px(mask), 2 * inflation_half_thickness(mask).max())
        distance = size * focal / extent_px
        out.append(ObjectDepth(shape.front * distance, shape.back * distance))
    return out


def depth_prior_image(depths: Sequence[ObjectDepth], K: np.ndarray) -> np.ndarray:
    """f32 (H,W): metres along the ray to the nearest object's front surface, NaN off the objects."""
    along = np.stack([d.along_ray(K) for d in depths])
    with np.errstate(all="ignore"):
        prior = np.nanmin(np.where(np.isfinite(along), along, np.inf), axis=0)
    return np.where(np.isfinite(prior), prior, np.nan).astype(np.float32)


class DptDepth:
    """Relative inverse depth from a DPT/MiDaS (or other transformers depth-estimation) model in a local folder.

    The folder is what ``save_pretrained`` of the model and its image processor
    write (e.g. a download of Intel/dpt-hybrid-midas): config.json, the weights,
    preprocessor_config.json. Nothing is fetched from the network.
    """

    def __init__(self, model_dir: Path | str, device: str = "cpu"):
        import torch
        from transformers import AutoImageProcessor, AutoModelForDepthEstimation

        self.torch, self.device = torch, device
        self.processor, self.model = load_local_model(
            AutoImageProcessor, AutoModelForDepthEstimation, Path(model_dir), device,
            "depth-estimation", "Intel/dpt-hybrid-midas", "use the default inflation prior")

    def inverse_depth(self, photo: np.ndarray) -> np.ndarray:
        """(H,W) float64 relative inverse depth of the RGB u8 photo (larger = nearer), resized to the photo."""
        inputs = self.processor(images=photo, return_tensors="pt")
        with self.torch.no_grad():
            predicted = self.model(pixel_values=inputs["pixel_values"].to(self.device)).predicted_depth
        height, width = photo.shape[:2]
        return cv2.resize(predicted[0].cpu().numpy().astype(np.float64), (width, height),
                          interpolation=cv2.INTER_LINEAR)
