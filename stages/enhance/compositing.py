"""Image-space compositing of rendered frames over the inpainted background (paper Sec. 3.4.1),
and the resampling it needs.

Blending in image space rather than latent space keeps object edges sharp and
temporally stable (the paper's Fig. 7).
"""
from __future__ import annotations

import cv2
import numpy as np


def resize_to(image: np.ndarray, width: int, height: int) -> np.ndarray:
    """Resize an (H, W, ...) image to (height, width); area filter when shrinking, cubic when growing."""
    if image.shape[1] == width and image.shape[0] == height:
        return image
    shrink = width < image.shape[1]
    return cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA if shrink else cv2.INTER_CUBIC)


def blend_over_background(colour: np.ndarray, alpha: np.ndarray, background: np.ndarray) -> np.ndarray:
    """alpha * colour + (1 - alpha) * background, rounded to uint8.

    Args:
        colour: (..., h, w, 3) object colour, uint8 or float in [0, 255], NOT premultiplied by alpha.
        alpha: (..., h, w) float in [0, 1].
        background: (h, w, 3) uint8, broadcast over leading frame dimensions.
    Returns:
        (..., h, w, 3) uint8.
    """
    a = np.clip(alpha, 0.0, 1.0)[..., None].astype(np.float32)
    out = a * colour.astype(np.float32) + (1.0 - a) * background.astype(np.float32)
    return np.clip(out + 0.5, 0, 255).astype(np.uint8)


def unpremultiply(rgb_over_black: np.ndarray, alpha: np.ndarray, min_alpha: float = 1.0 / 255) -> np.ndarray:
    """Recover the object colour from a render over black: rgb / alpha where alpha is meaningful, else 0.

    Args:
        rgb_over_black: (..., h, w, 3) uint8 render over a black background.
        alpha: (..., h, w) float.
    Returns:
        (..., h, w, 3) float32 in [0, 255].
    """
    a = alpha[..., None].astype(np.float32)
    colour = rgb_over_black.astype(np.float32) / np.maximum(a, min_alpha)
    return np.where(a >= min_alpha, np.clip(colour, 0, 255), 0.0).astype(np.float32)


def sample_at(image: np.ndarray, uv: np.ndarray, interpolation: int = cv2.INTER_LINEAR,
              oversampling: int = 1) -> np.ndarray:
    """Samples of an image at image points (pixel centres at +0.5), bilinear by default.

    Args:
        image: (h, w) or (h, w, C) float32 at output resolution, or ``oversampling`` times it
            as made by :func:`flow.band_limited_upsample`.
        uv: (h', w', 2) image points at output resolution; NaN where there is nothing to sample.
    Returns:
        (h', w') or (h', w', C) float32; 0 where uv is NaN or outside the image.
    """
    # cv2.remap puts pixel centres at integers; sample i of the input is sample i * oversampling of the copy
    maps = np.nan_to_num((uv - 0.5) * oversampling, nan=-10.0 * oversampling).astype(np.float32)
    return cv2.remap(image, maps[..., 0], maps[..., 1], interpolation, borderMode=cv2.BORDER_CONSTANT, borderValue=0)


def normalised_blur(values: np.ndarray, valid: np.ndarray, sigma_px: float) -> tuple[np.ndarray, np.ndarray]:
    """Gaussian blur over the valid pixels only, so that invalid ones (NaN, off the object) pull nothing in.

    Args:
        values: (h, w, C) float; anything where not valid.
        valid: (h, w) bool.
    Returns:
        The weighted mean of the valid neighbours (h, w, C) float32 (meaningless where the weight is 0),
        and that weight (h, w): the blurred valid mask.
    """
    mask = valid.astype(np.float32)
    weight = cv2.GaussianBlur(mask, (0, 0), sigma_px)
    blurred = cv2.GaussianBlur((np.nan_to_num(values) * mask[..., None]).astype(np.float32), (0, 0), sigma_px)
    return blurred / np.maximum(weight, 1e-6)[..., None], weight
