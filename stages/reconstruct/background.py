"""The photograph with its objects inpainted away, for the enhancement's compositing (I_B^0).

Inside the hole the fill is by exemplar: each missing patch is copied from the
best-matching patch of the known background, coarse to fine (PatchMatch,
Barnes et al. 2009, through patchmatch-cython). Diffusion (OpenCV's Telea
method) carries the hole's rim inwards and smears a hole wider than a few
pixels into streaks, and once the object moves away the whole hole is on
screen. Along the seam, though, the rim's own colours are the better guess:
the dilation ring around the object shows at rest, where the video should look
like the photograph, and a copied patch of another material (the table's wood
where the cup stood on its saucer) would outline the object. So the fill
cross-fades from diffusion at the seam to exemplar past twice the dilation.
"""
from __future__ import annotations

import logging

import cv2
import numpy as np
from patchmatch_cython import inpaint_pyramid

log = logging.getLogger("physmotion.reconstruct.background")

PATCH_PX = 7
"""Side of the patches that are matched and copied, pixels. Measured on periodic test textures
(tests/reconstruct): 7 px copies stripes, a checkerboard and a weave exactly; 5 px left the
checkerboard 11/255 off. (The library's own Poisson cross-fade at the seam is off: it blended
the copies with the rim's colours, 16-36/255 off on the same textures.)"""
EXEMPLAR_MAX_PX = 1024
"""Long side (pixels) above which the exemplar fill is computed on a shrunk copy: its time grows
faster than the pixel count (a hole of 24 % of the photograph: 2.1 s at 451 px wide, 10.7 s at
902, 60 s at 1804 on 2 cores), and the video is rarely wider (render.width defaults to 512)."""
DIFFUSION_RADIUS_PX = 5
"""Neighbourhood of Telea's method along the seam."""
SEAM_WIDTH = 2
"""Width of the cross-fade from diffusion to exemplar fill, in dilation radii. Measured on the
coffee scene, whose ring shows around the cup at rest: frame-0 PSNR 36.7 dB with Telea alone,
34.4 / 36.1 / 36.5 dB with 1 / 2 / 3 radii, 32.6 dB with exemplar alone."""


def exemplar_fill(photo: np.ndarray, hole: np.ndarray) -> np.ndarray:
    """(H, W, 3) u8: ``photo`` with the ``hole`` (H, W bool) filled by copied patches, computed at
    most EXEMPLAR_MAX_PX on the long side and brought back to the photograph's size."""
    height, width = hole.shape
    size = (width, height)
    if max(size) > EXEMPLAR_MAX_PX:
        size = tuple(round(side * EXEMPLAR_MAX_PX / max(width, height)) for side in size)
        photo = cv2.resize(photo, size, interpolation=cv2.INTER_AREA)
        hole = cv2.resize(hole.astype(np.uint8), size, interpolation=cv2.INTER_AREA) > 0
    filled = inpaint_pyramid(photo, hole, patch_size=PATCH_PX, seed=0, poisson_blend=False)
    return cv2.resize(filled, (width, height), interpolation=cv2.INTER_CUBIC) if size != (width, height) else filled


def dilation_px(height: int, width: int) -> int:
    """How far past the masks to inpaint: soft edges and GrabCut's misses (1 % of the size, at least 3 px)."""
    return max(3, round(0.01 * max(height, width)))


def inpaint_background(photo: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """RGB u8 (H,W,3): ``photo`` with every object (``labels`` > 0), dilated, filled from the rest of it.

    Pixels outside the dilated objects are the photograph's, unchanged; the fill is the same on
    every run (fixed seed)."""
    radius = dilation_px(*labels.shape)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
    hole = cv2.dilate((labels > 0).astype(np.uint8), kernel)
    if not hole.any():
        return photo.copy()
    rim = cv2.inpaint(photo, hole, DIFFUSION_RADIUS_PX, cv2.INPAINT_TELEA)
    try:
        texture = exemplar_fill(photo, hole > 0)
    except ValueError as error:  # no whole patch of background left at some level of the pyramid
        log.warning("background: %s; the objects cover too much of the photograph to copy patches from, "
                    "so their place is filled by diffusion alone", error)
        return np.where(hole[..., None] > 0, rim, photo)
    inside_px = cv2.distanceTransform(hole, cv2.DIST_L2, 5)  # from the nearest known pixel
    diffused = np.clip(1 - (inside_px - 0.5) / (SEAM_WIDTH * radius), 0, 1)[..., None]
    filled = diffused * rim + (1 - diffused) * texture
    return np.where(hole[..., None] > 0, filled + 0.5, photo).astype(np.uint8)
