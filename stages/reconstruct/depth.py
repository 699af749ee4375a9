"""Metric depth prior of each object: a silhouette-inflation prior, or a DPT/MiDaS model.

Both give, per object pixel, the camera-space depth z (metres) of the front
surface and of the back surface. The object is placed so that its largest
extent is size_m (DESIGN.md): every depth scales linearly with the distance,
so the shape is built at unit distance and then scaled.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional, Sequence

import cv2
import numpy as np
from scipy import ndimage

from schemas.camera import pixel_rays

from .local_model import load_local_model


EDGE_OFFSET_PX = 0.3
"""Mean distance (pixels) from the silhouette edge to the nearest outside pixel centre."""
TIP_WINDOW_PX = 3.0
"""An end of a silhouette is located from its edge this far back from its farthest point: rows enough
for a round end of 10 px radius (about 30 edge points), little of a flat end's sides."""


def medial_balls(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The round cross-sections a silhouette is inflated from: for each pixel (H,W), the radius R (px) of the
    ball it lies on, the distance d (px) from the silhouette's edge, and the (row, col) (2,H,W) of the ball's
    centre, the pixel's nearest point of the medial axis; R and d are 0 off the mask.

    A pixel d from the edge whose nearest medial-axis point lies R from the edge lies on a ball of radius
    R about that point, at half thickness sqrt(R^2 - (R - d)^2): exact for a sphere (R its radius) and for
    a cylinder seen side-on (R its radius).
    """
    padded = np.pad(mask.astype(bool), 2)  # objects cut by the image border close at the border
    # To the silhouette edge: it lies between the last inside and the first outside pixel centre, on
    # average 0.5 px before the latter on straight axis-aligned edges and 0.2-0.35 px on curved ones
    # (measured on ray-cast discs); 0.3 balances the two.
    dist = np.where(padded, ndimage.distance_transform_edt(padded) - EDGE_OFFSET_PX, 0.0)
    # Away from the edge: up the signed distance's gradient. The direction from the nearest outside pixel
    # breaks its ties on a pixelated rim so that neighbours at a one-pixel nub face opposite ways, and
    # spurs of the axis there give the pixels near them a radius of about one pixel.
    gradient = np.stack(np.gradient(dist - ndimage.distance_transform_edt(~padded)))
    slope = np.linalg.norm(gradient, axis=0)
    inward = gradient / np.maximum(slope, 1e-9)

    def at(array: np.ndarray, dr: int, dc: int) -> np.ndarray:
        """``array`` at each mask pixel's neighbour (dr, dc), |dr|, |dc| <= 1."""
        rows, cols = array.shape[-2:]
        return array[..., 2 + dr:rows - 2 + dr, 2 + dc:cols - 2 + dc]

    def turned(a: tuple[int, int], b: tuple[int, int]) -> np.ndarray:
        """Both neighbours a and b inside, their inward directions more than 90 degrees apart."""
        return at(padded, *a) & at(padded, *b) & ((at(inward, *a) * at(inward, *b)).sum(0) < 0)

    # Medial axis: where the inward direction turns by more than 90 degrees from a pixel to a neighbour
    # (a pair straddling the axis) or across a pixel (the axis through its centre, where it vanishes).
    axis = np.zeros_like(padded)
    neighbours = [(dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1) if (dr, dc) != (0, 0)]
    at(axis, 0, 0)[...] = np.any([turned((0, 0), n) | turned((-n[0], -n[1]), n) for n in neighbours], axis=0)
    if not axis.any():  # a one-pixel-wide mask
        axis = padded.copy()
    _, axis_index = ndimage.distance_transform_edt(~axis, return_indices=True)
    # An axis pixel o < 1 px off the axis lies o nearer the edge than the axis, and its distance's slope
    # (central differences across the ridge) is o.
    at_axis = (axis_index[0], axis_index[1])
    radius = np.where(padded, dist[at_axis] + np.minimum(slope[at_axis], 1.0), 0.0)
    return at(radius, 0, 0), at(np.minimum(dist, radius), 0, 0), at(axis_index, 0, 0) - 2


def inflation_half_thickness(mask: np.ndarray) -> np.ndarray:
    """Half the object's thickness (H,W) in pixels, 0 off the mask, from round cross-sections (medial_balls)."""
    radius, d, _ = medial_balls(mask)
    return np.sqrt(np.maximum(radius ** 2 - (radius - d) ** 2, 0.0))


@dataclass
class ObjectDepth:
    """Camera-space depths (H,W) in metres of one object's front and back surface, NaN off the object; base
    (H,W) bool: the pixels whose front lies on the flat base the body stands on (closure.standing_cut); body:
    the solid itself (body.Body), None where the depths are all that is known."""

    front: np.ndarray
    back: np.ndarray
    base: Optional[np.ndarray] = None
    body: Optional[Any] = None

    @property
    def pixels(self) -> np.ndarray:
        """Boolean (H,W): the object's pixels."""
        return np.isfinite(self.front)

    def volume(self, K: np.ndarray) -> float:
        """m^3 between the front and back surfaces within each pixel's pyramid of rays (K the (3,3)
        intrinsics at this resolution): at depth z a pixel covers z^2 / (fx fy) m^2, so its column holds
        (back^3 - front^3) / (3 fx fy). The body the depth prior describes, whatever the closure the
        Gaussians take (lift.lift_object's back lies straight behind the front, and holds less)."""
        pixels = self.pixels
        return float(np.sum(self.back[pixels] ** 3 - self.front[pixels] ** 3) / (3.0 * K[0, 0] * K[1, 1]))

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


def edge_points(mask: np.ndarray) -> np.ndarray:
    """(N,2) row, column (pixel-centre units) of the silhouette's edge: midway between every inside pixel
    and each of its outside 4-neighbours (the edge lies between them, in no known place: the midpoint is
    off by at most half a pixel and, over a curved edge, by nothing on average)."""
    padded = np.pad(mask.astype(bool), 1)
    rows, cols = np.nonzero(padded[:-1] != padded[1:])
    across_rows = np.stack([rows + 0.5, cols], axis=1)
    rows, cols = np.nonzero(padded[:, :-1] != padded[:, 1:])
    across_cols = np.stack([rows, cols + 0.5], axis=1)
    return np.concatenate([across_rows, across_cols]) - 1.0


def tip_px(along: np.ndarray, across: np.ndarray) -> float:
    """Where an edge ends along a direction: the top of a parabola along(across) fitted to the edge points
    within TIP_WINDOW_PX of the farthest one (a round end's edge, sampled by dozens of points), at most the
    fit's value at the window's sides (a flat end's corners)."""
    near = along > along.max() - TIP_WINDOW_PX
    a, b = along[near], across[near]
    if np.unique(b).size < 3:
        return float(a.max())
    coefficients = np.polyfit(b, a, 2)
    candidates = [b.min(), b.max()]
    vertex = -coefficients[1] / (2 * coefficients[0]) if coefficients[0] < 0 else np.nan
    if b.min() < vertex < b.max():
        candidates.append(vertex)
    return float(np.polyval(coefficients, candidates).max())


def largest_extent_px(mask: np.ndarray) -> float:
    """Largest extent (pixels) of a silhouette: its length along the longer of the principal axes of its
    pixels (a tilted object measures its own length, not an axis-aligned box's width), between the ends
    of its edge located to a fraction of a pixel (tip_px). Counted in whole pixels it would be up to
    a pixel long or short: 7 % of a 14 px disc, 2 % of a 54 px one, three times that in volume."""
    points = np.argwhere(mask).astype(np.float64)
    centre = points.mean(0)
    _, axes = np.linalg.eigh((points - centre).T @ (points - centre))
    edge = (edge_points(mask) - centre) @ axes
    return max(tip_px(edge[:, k], edge[:, 1 - k]) + tip_px(-edge[:, k], edge[:, 1 - k]) for k in range(2))


def aligned_front(depth: ObjectDepth, inverse_depth: np.ndarray) -> ObjectDepth:
    """``depth`` with its front replaced by a relative inverse depth (H,W) such as MiDaS gives (any scale and
    shift), aligned to the front by least squares in inverse depth (as MiDaS is evaluated); the back keeps
    its distance behind the front."""
    mask = depth.pixels
    design = np.stack([inverse_depth[mask], np.ones(mask.sum())], axis=1)
    (scale, shift), *_ = np.linalg.lstsq(design, 1.0 / depth.front[mask], rcond=None)
    floor = 1.0 / np.nanmax(depth.back)  # never behind the prior's back
    front = np.where(mask, 1.0 / np.maximum(scale * inverse_depth + shift, floor), np.nan)
    return ObjectDepth(front, front + (depth.back - depth.front), depth.base, depth.body)


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
