"""The supervised views of the optimisation: the input view, and extra views (Eq. 9).

Extra views (reconstruct.extra_views) are images of the object from other
azimuths, e.g. from a multi-view diffusion model run elsewhere. Their camera
is the input camera orbited about the vertical axis through the object's
centre (geometry.orbit_world_to_camera); their intrinsics are unknown, so each
image's silhouette is scaled and shifted onto the silhouette the initial
Gaussians cast from that camera (matching heights, which an orbit about the
vertical axis keeps) before its inflation prior is built. Only the hard-depth
loss uses them, and it compares patch-normalised shape, not absolute depth.
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import torch
from scipy import ndimage

import splat
from schemas import InputError

from .depth import unit_distance_shape
from .geometry import intrinsics_from_fov, orbit_world_to_camera, working_size
from .lift import Gaussians
from .losses import SSIM_WINDOW
from .optimize import View
from .segment import largest_component, read_photo

BACKGROUND_THRESHOLD = 25
"""An extra view without alpha: pixels differing from the border's median colour by more than this (u8) are object."""


def _valid(mask: np.ndarray) -> np.ndarray:
    """Pixels whose depth is compared: the mask less its one-pixel rim, where rendered depth is partial."""
    return ndimage.binary_erosion(mask, border_value=0)


def input_view(photo: np.ndarray, labels: np.ndarray, depth_prior: np.ndarray, K: np.ndarray,
               resolution: int, device: str) -> View:
    """The input view at the working resolution: foreground target (premultiplied), coverage, prior depth."""
    height, width = labels.shape
    size = working_size(width, height, resolution)
    coverage = (labels > 0).astype(np.float32)
    target_rgb = cv2.resize(photo.astype(np.float32) / 255 * coverage[..., None], size, interpolation=cv2.INTER_AREA)
    target_alpha = cv2.resize(coverage, size, interpolation=cv2.INTER_AREA)
    prior = cv2.resize(depth_prior, size, interpolation=cv2.INTER_NEAREST)
    valid = _valid(np.isfinite(prior))
    camera = splat.Camera(K, np.eye(4), width, height).scaled_to_width(size[0])
    rows, cols = np.nonzero(target_alpha)
    crop = (slice(max(0, rows.min() - SSIM_WINDOW), rows.max() + 1 + SSIM_WINDOW),
            slice(max(0, cols.min() - SSIM_WINDOW), cols.max() + 1 + SSIM_WINDOW))
    as_tensor = lambda a: torch.tensor(a, device=device)  # noqa: E731
    return View(camera, as_tensor(np.nan_to_num(prior)), as_tensor(valid), as_tensor(target_rgb),
                as_tensor(target_alpha), crop)


def extra_view_mask(path: Path, field: str) -> np.ndarray:
    """Object mask (H,W) bool of an extra-view image: its alpha, else what differs from the border colour."""
    image, alpha = read_photo(path)
    if alpha is not None:
        mask = alpha > 127
    else:
        border = np.concatenate([image[0], image[-1], image[:, 0], image[:, -1]])
        diff = np.abs(image.astype(int) - np.median(border, axis=0)).max(axis=2)
        mask = diff > BACKGROUND_THRESHOLD
    mask = ndimage.binary_fill_holes(largest_component(mask))
    if mask.sum() < 16:
        raise InputError(path, field, "found no object in this extra view (it needs an alpha channel or a plain "
                         "background)", "give the view with an alpha channel, or on a plain white background")
    return mask


def _fit_mask(mask: np.ndarray, silhouette: np.ndarray) -> np.ndarray:
    """``mask`` scaled and shifted so that its bounding box has the height and centre of ``silhouette``'s."""
    def box(m):
        rows, cols = np.nonzero(m)
        return rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
    r0, r1, c0, c1 = box(mask)
    s0, s1, t0, t1 = box(silhouette)
    scale = (s1 - s0) / (r1 - r0)
    shift_x = (t0 + t1) / 2 - scale * (c0 + c1) / 2
    shift_y = (s0 + s1) / 2 - scale * (r0 + r1) / 2
    affine = np.array([[scale, 0, shift_x], [0, scale, shift_y]])
    height, width = silhouette.shape
    return cv2.warpAffine(mask.astype(np.uint8), affine, (width, height), flags=cv2.INTER_NEAREST) > 0


def extra_view(path: Path, azimuth_deg: float, field: str, initial: Gaussians, fov_deg: float,
               resolution: int, device: str) -> View:
    """The hard-depth supervision of one extra view (no colour: the paper finds generated views' poses too loose)."""
    mask = extra_view_mask(path, field)
    size = working_size(mask.shape[1], mask.shape[0], resolution)
    mask = cv2.resize(mask.astype(np.uint8), size, interpolation=cv2.INTER_NEAREST) > 0
    K = intrinsics_from_fov(fov_deg, *size)
    centre = (initial.means.min(0) + initial.means.max(0)) / 2
    camera = splat.Camera(K, orbit_world_to_camera(centre, azimuth_deg), *size)
    as_tensor = lambda a: torch.tensor(a, dtype=torch.float32, device=device)  # noqa: E731
    with torch.no_grad():
        alpha = splat.rasterize(as_tensor(initial.means), as_tensor(initial.opacities), as_tensor(initial.colors),
                                camera, scales=as_tensor(initial.scales),
                                rotations=as_tensor(initial.rotations)).alpha.cpu().numpy()
    if (alpha > 0.5).sum() < 16:
        raise InputError(path, field, f"the initial Gaussians are not visible from azimuth {azimuth_deg} degrees",
                         "check azimuth_deg (degrees, positive towards the photograph's right)")
    mask = _fit_mask(mask, alpha > 0.5)
    shape = unit_distance_shape(mask, K[1, 1])
    prior = np.nan_to_num(shape.along_ray(K))
    return View(camera, as_tensor(prior), torch.tensor(_valid(mask), device=device))
