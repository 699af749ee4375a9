"""Re-shading the photograph's pixels: its light stays where it was while the surface turns.

The photograph's colour at a surface point is albedo x shading, and the shading
belongs to the point's orientation at rest, not to the point: a ball that rolls
over carries its dark underside into the light. We fit one distant light to the
photograph on the rendered normals of frame 0 (first-order spherical harmonics:
brightness = ambient + light . n) and scale each pixel's colour, in linear
light, by shading(normal now) / shading(normal where it was in the photograph).
When one light does not explain the photograph's brightness (a flat graphic, a
scene lit from everywhere, texture that dominates shading) we leave it as it
is: a wrong light would paint shading onto the video.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Optional

import cv2
import numpy as np

from schemas.artifacts import CoarseArtifact

from .compositing import normalised_blur

log = logging.getLogger("physmotion.enhance.relight")

MIN_EXPLAINED = 0.5
"""The light is used only if it explains at least this fraction (R^2) of the brightness variance
inside the objects. Measured: ball 0.89, coffee 0.25, logo 0.22 (benchmarks/RESULTS.md)."""
NORMAL_SMOOTHING = 0.03
"""Blur of the rendered normals (standard deviation) per object size (square root of its pixel
count): shading is smooth, while the Gaussians' own relief is not."""
RIM_PX = 3
"""Pixels along the silhouette, whose colour in the photograph mixes in the background, are left
out of the fit."""
FLOOR = 0.15
"""Shading is never taken below this fraction of its brightest (ambient + |light|): near the
terminator the photograph holds little but noise and a small error in the normal moves the
terminator, so dividing by that shading must stay bounded (at 5 %, with gains up to 3, the ball
shows bright blotches along its terminator)."""


def to_linear(srgb: np.ndarray) -> np.ndarray:
    """sRGB in [0, 255] -> linear light in [0, 1] (IEC 61966-2-1)."""
    x = np.clip(srgb / 255.0, 0.0, 1.0)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def to_srgb(linear: np.ndarray) -> np.ndarray:
    """Linear light in [0, 1] -> sRGB in [0, 255] (clipped)."""
    x = np.clip(linear, 0.0, 1.0)
    return 255.0 * np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def smooth_normals(normals: np.ndarray, alpha: np.ndarray, sigma_px: float) -> np.ndarray:
    """(h, w, 3) a frame's rendered normals (coarse.h5 /frames/normal) blurred over the surface
    (alpha > 0.5) and renormalised; NaN off it.

    The blur is normalised over the surface's own pixels, so the background does not bend the rim:
    shading is smooth, while the Gaussians' own relief is not.
    """
    on = (alpha > 0.5) & np.isfinite(normals).all(-1)
    blurred, weight = normalised_blur(np.nan_to_num(normals), on, sigma_px)
    blurred /= np.linalg.norm(blurred, axis=-1, keepdims=True) + 1e-12
    return np.where(on[..., None] & (weight[..., None] > 0.01), blurred, np.nan).astype(np.float32)


@dataclass(frozen=True)
class Shading:
    """brightness(n) = ambient + light . n, for camera-space unit normals n, floored (see FLOOR)."""

    ambient: float
    light: np.ndarray  # (3,)

    def __call__(self, normals: np.ndarray) -> np.ndarray:
        brightest = self.ambient + float(np.linalg.norm(self.light))
        return np.maximum(self.ambient + normals @ self.light, FLOOR * brightest)


def fit_shading(value: np.ndarray, normals: np.ndarray, pixels: np.ndarray) -> tuple[Shading, float]:
    """Least-squares light of a photograph, and the fraction of brightness variance it explains.

    Args:
        value: (h, w) linear brightness, the largest of the three channels: a hue change at the
            same brightness (red to yellow stripes) leaves it alone, so it follows shading.
        normals: (h, w, 3) camera-space unit normals at rest.
        pixels: (h, w) bool, where to fit.
    Returns:
        The shading and its R^2 over ``pixels``.
    """
    v = value[pixels].astype(np.float64)
    design = np.concatenate([np.ones((len(v), 1)), normals[pixels].astype(np.float64)], axis=1)
    coef, *_ = np.linalg.lstsq(design, v, rcond=None)
    variance = float(np.var(v))
    # a photograph of even brightness over the objects says nothing of a light
    explained = 1.0 - np.mean((design @ coef - v) ** 2) / variance if variance > 1e-12 else 0.0
    return Shading(float(coef[0]), coef[1:]), float(explained)


class Relighting:
    """The light fitted to a coarse video's photograph: its shading, the blur of the normals it was
    fitted on (sigma_px, output pixels) and those normals at rest (h, w, 3, NaN off the objects).

    Use :meth:`fit`, which returns None when one light does not explain the photograph.
    unseen.Continuation applies it: each pixel's colour is scaled, in linear light, by the shading of
    where its surface faces now over the shading its source had in the photograph.
    """

    def __init__(self, shading: Shading, sigma_px: float, rest_normals: np.ndarray):
        self.shading, self.sigma_px, self.rest_normals = shading, sigma_px, rest_normals

    @classmethod
    def fit(cls, coarse: CoarseArtifact, photo: np.ndarray) -> Optional["Relighting"]:
        """Fit on frame 0 (the reconstruction at rest, seen as in the photograph).

        Args:
            coarse: the render; frame 0's normals are the photograph's.
            photo: (h, w, 3) the photograph at the render's size, sRGB in [0, 255].
        """
        on = coarse.alpha[0] > 0.5
        if on.sum() < 50:
            return None
        sigma = max(1.0, NORMAL_SMOOTHING * float(np.sqrt(on.sum())))
        normals = smooth_normals(coarse.normal[0], coarse.alpha[0], sigma)
        inner = cv2.erode(on.astype(np.uint8), np.ones((2 * RIM_PX + 1,) * 2, np.uint8)) > 0
        shading, explained = fit_shading(to_linear(photo.astype(np.float64)).max(axis=-1), normals, inner)
        if explained < MIN_EXPLAINED:
            log.info("relighting off: one light explains %.0f%% of the photograph's brightness (needs %.0f%%)",
                     100 * explained, 100 * MIN_EXPLAINED)
            return None
        direction = shading.light / (np.linalg.norm(shading.light) + 1e-12)
        log.info("relighting: light towards (%.2f, %.2f, %.2f) in the camera frame, ambient %.2f, "
                 "explains %.0f%% of the photograph's brightness", *direction, shading.ambient, 100 * explained)
        return cls(shading, sigma, normals)
