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


STILL_PX = 0.5
"""Motion (output pixels) of the object's surface at which the photograph's own pixels beside it
fade out of the background: one pixel of motion leaves e^-4 of them. Twin of stages/render/silhouette.py's."""


def standing_still(source_uv: np.ndarray) -> np.ndarray:
    """(h, w) in [0, 1]: how surely each pixel shows the point that stood there at rest, from its source point
    (source_uv (h, w, 2), output image points, NaN off the objects: 0 there) within STILL_PX of its centre."""
    h, w = source_uv.shape[:2]
    moved = np.linalg.norm(source_uv - (np.stack(np.meshgrid(np.arange(w), np.arange(h)), -1) + 0.5), axis=-1)
    return np.exp(-(np.nan_to_num(moved, nan=np.inf) / STILL_PX) ** 2)


class Backdrop:
    """Each frame's background: the photograph beside the object where it still stands as at rest,
    the inpainted fill where it moved or left.

    The fill covers the objects' masks and a ring around them, since the photograph's pixels just
    outside a mask may hold some of the object (soft edges, segmentation misses): shown once the
    object has gone, they would leave its outline behind. While the object still stands next to
    them, as in the photograph, they are what the photograph shows there, and the fill in their
    place would outline the object instead (at rest the ring held 80-94 % of frame 0's squared
    error on the example and unseen scenes). There, too, the render's fringe beyond the masks gives
    way to the photograph (objects_alpha), for every backend that composites over the backdrop.

    Args:
        photo, fill: (h, w, 3) the photograph and the inpainted background at output resolution.
        mask: (H, W) the objects' mask at the photograph's resolution (> 0 on an object).
        alpha_rest: (h, w) the rendered alpha of frame 0.
    """

    def __init__(self, photo: np.ndarray, fill: np.ndarray, mask: np.ndarray, alpha_rest: np.ndarray):
        h, w = alpha_rest.shape
        self.photo, self.fill = photo.astype(np.float32), fill.astype(np.float32)
        self.objects_share = resize_to((mask > 0).astype(np.float32), w, h)
        """(h, w) in [0, 1]: how much of each output pixel the objects' mask covers."""
        self.outside = 1.0 - self.objects_share
        self.touched = (self.objects_share > 0).astype(np.float32)
        """(h, w) 1 on the output pixels the objects' mask covers at least in part, else 0."""
        beyond = (self.outside > 0.5).astype(np.uint8)
        ring = beyond.astype(bool) & (np.abs(self.fill - self.photo).max(-1) > 0)
        # the ring's width: how far the fill reaches past the masks (output pixels)
        reach = cv2.distanceTransform(beyond, cv2.DIST_L2, 3)[ring]
        self.reach_px = float(max(1.0, reach.max())) if ring.any() else 1.0
        self.near_rest = cv2.GaussianBlur(alpha_rest.astype(np.float32), (0, 0), self.reach_px)

    def __call__(self, alpha: np.ndarray, still: np.ndarray, shadow: np.ndarray | None = None) -> np.ndarray:
        """(h, w, 3) float32 in [0, 255], the background of a frame.

        Args:
            alpha: (h, w) the frame's rendered alpha.
            still: (h, w) standing_still of its source map at output resolution, as rendered (unsmoothed:
                smoothing pulls it inwards by a fraction of a pixel at the silhouette).
            shadow: (h, w) in [0, 1], how much the objects' shadows darken the fill (shadow.Shadows),
                or None. The photograph beside an object that still stands shows its own.
        """
        near_now = cv2.GaussianBlur((alpha * still).astype(np.float32), (0, 0), self.reach_px)
        beside = np.clip(near_now / np.maximum(self.near_rest, 1e-3), 0.0, 1.0) * (self.near_rest > 1e-3)
        fill = self.fill if shadow is None else self.fill * (1 - shadow[..., None])
        return fill + (beside * self.outside)[..., None] * (self.photo - fill)

    def objects_alpha(self, alpha: np.ndarray, source_uv: np.ndarray, still: np.ndarray) -> np.ndarray:
        """(h, w) float32 in [0, 1]: the frame's rendered alpha (h, w), less its fringe where it stands at rest.

        The reconstruction's Gaussians along the silhouette reach past the objects' mask (on the examples the
        render's alpha is still 1 two pixels beyond it, and falls to 0 over the next three): the photograph
        shows the background there, so at rest that fringe has no colour of the objects to show, and it drew
        a halo around them. A pixel that stands where its source is keeps its alpha by the share of that
        source on the pixels the objects touch, so at rest the background (the photograph) shows beside them,
        exactly. A pixel that moved keeps its alpha: the limb at rest projects onto the silhouette's pixels and
        their neighbours, and a surface turned towards the camera from there is the object, not a fringe.

        Args:
            alpha: (h, w) the frame's rendered alpha.
            source_uv: (h, w, 2) its source points at output resolution as rendered (unsmoothed: at rest
                exactly each pixel's centre), NaN where there is no surface.
            still: (h, w) standing_still(source_uv).
        """
        return alpha * (1 - still * (1 - sample_at(self.touched, source_uv))).astype(np.float32)
