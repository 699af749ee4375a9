"""The photograph with its objects inpainted away, for the enhancement's compositing (I_B^0).

Filled by exemplar: each missing patch is copied from the best-matching patch of
the known background, coarse to fine (PatchMatch, Barnes et al. 2009, through
patchmatch-cython). Diffusion-style methods (OpenCV's Telea, biharmonic) carry
the hole's rim inwards and smear a hole wider than a few pixels into streaks;
once the object moves away, the whole hole is on screen.
"""
from __future__ import annotations

import cv2
import numpy as np
from patchmatch_cython import inpaint_pyramid

PATCH_PX = 7
"""Side of the patches that are matched and copied, pixels. Measured on periodic test textures
(tests/reconstruct): 7 px copies stripes, a checkerboard and a weave exactly into a hole 46 px
wide; 5 px left the checkerboard 11/255 off."""


def dilation_px(height: int, width: int) -> int:
    """How far past the masks to inpaint: soft edges and GrabCut's misses (1 % of the size, at least 3 px)."""
    return max(3, round(0.01 * max(height, width)))


def inpaint_background(photo: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """RGB u8 (H,W,3): ``photo`` with every object (``labels`` > 0), dilated, filled from the rest of it.

    Pixels outside the dilated objects are the photograph's, unchanged; the fill is the same on
    every run (fixed seed)."""
    radius = dilation_px(*labels.shape)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
    hole = cv2.dilate((labels > 0).astype(np.uint8), kernel) > 0
    if not hole.any():
        return photo.copy()
    # No Poisson cross-fade at the seam: it blends the copied texture with the rim's colours,
    # 16-36/255 off on those textures.
    filled = inpaint_pyramid(photo, hole, patch_size=PATCH_PX, seed=0, poisson_blend=False)
    return np.where(hole[..., None], filled, photo).astype(np.uint8)
