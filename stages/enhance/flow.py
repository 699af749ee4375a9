"""The flow backend: the photograph's own pixels, carried along with the simulated motion.

Every coarse pixel knows (``source_uv``) where its surface was in the
photograph at rest, (``source_coherence``) whether the photograph maps smoothly
onto the frame there and (``source_confidence``) how visible that surface was
in the photograph. Where the surface was seen we take the photograph's colour
from that point. A surface the photograph never saw (the back) takes, with
``hidden_surfaces="photo"``, the colour of the surface it continues, wherever
the map is smooth: the photograph where it saw the mirror image of that surface
(unseen.py), which keeps the photograph's detail where the render would blur
it; with ``"render"`` we keep the render. Where the map is not smooth
(tumbling, flowing material) the render is used. Colours are read as albedo
and shaded for where the surface faces now under the light fitted to the
photograph (relight.py, unseen.py), and blended with the rendered alpha over
the inpainted, shadow-free background, which the objects' shadows darken where
they are now (shadow.py) and which shows the photograph itself beside an
object wherever it still stands as at rest, where the render's fringe beyond
the objects' mask gives way to it (compositing.Backdrop).
"""
from __future__ import annotations

import logging
from typing import Callable

import cv2
import numpy as np
from scipy import signal

from schemas.artifacts import CoarseArtifact, GaussiansArtifact

from .compositing import (Backdrop, blend_over_background, normalised_blur, resize_to, sample_at, standing_still,
                          unpremultiply)
from .shadow import Shadows
from .unseen import Continuation, MirrorPlanes, continue_inwards

log = logging.getLogger("physmotion.enhance.flow")

SOURCE_SMOOTHING_PX = 1.0
"""Standard deviation (output pixels) of the blur that takes the jitter out of source_uv."""
EDGE_SOFTNESS_PX = 0.5
"""Blur (output pixels) of the photograph's eroded object mask: photo pixels on the silhouette mix in
the old background, so their trust fades out over about this distance instead of leaving a halo."""


def object_coverage(mask: np.ndarray, width: int, height: int) -> np.ndarray:
    """(height, width) float32 in [0, 1]: how purely a photo pixel shows an object, at output resolution."""
    inside = resize_to((mask > 0).astype(np.float32), width, height)
    eroded = cv2.erode(inside, np.ones((3, 3), np.uint8))
    return cv2.GaussianBlur(eroded, (0, 0), EDGE_SOFTNESS_PX)


OVERSAMPLING = 2
"""The photograph is read from a band-limited copy at this many times the output resolution.
Lanczos' 8-tap window softens detail near the Nyquist limit at sub-pixel offsets (the ball's
photograph moved by a quarter / half a pixel kept 0.75 / 0.59 of its variance of the Laplacian);
read from the copy it keeps 0.95 / 0.99, and whole-pixel offsets stay exact."""
PAD_PX = 16
"""Reflected border added before the FFT, so that its wrap-around does not ring into the image."""


def band_limited_upsample(image: np.ndarray, factor: int = OVERSAMPLING) -> np.ndarray:
    """(h * factor, w * factor, C) float32: the (h, w, C) image interpolated by zero-padding its
    spectrum (scipy.signal.resample), so that sample (i, j) of the image is sample
    (factor i, factor j) of the result and nothing in between is smoothed."""
    padded = np.pad(image.astype(np.float64), ((PAD_PX, PAD_PX), (PAD_PX, PAD_PX), (0, 0)), mode="reflect")
    h, w = padded.shape[:2]
    fine = signal.resample(signal.resample(padded, h * factor, axis=0), w * factor, axis=1)
    return fine[PAD_PX * factor:(h - PAD_PX) * factor, PAD_PX * factor:(w - PAD_PX) * factor].astype(np.float32)


def objects_continued(photo: np.ndarray, on_objects: np.ndarray) -> np.ndarray:
    """(h, w, 3) float32: the photograph (h, w, 3) on its objects (on_objects (h, w) bool, output
    resolution) and, beyond them, their colours continued outwards (unseen.continue_inwards)."""
    continued = continue_inwards(photo.astype(np.float32), on_objects, np.ones(on_objects.shape, bool))
    return np.where(on_objects[..., None], photo, continued).astype(np.float32)


def photograph_at(fine_photo: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """(h', w', 3) float32 in [0, 255]: the photograph at image points uv (h', w', 2, output
    resolution), read from its band-limited copy (:func:`band_limited_upsample`) by Lanczos."""
    return np.clip(sample_at(fine_photo, uv, cv2.INTER_LANCZOS4, OVERSAMPLING), 0, 255)


SILHOUETTE_PX = 2.0
"""Depth (output pixels) inside the objects' mask over which the objects' colours go from the photograph's
own copy (on the silhouette) to the copy of the objects continued beyond it (:func:`objects_reader`)."""


def objects_reader(photo: np.ndarray, on_objects: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """photograph_at for the objects' colours: image points uv (h', w', 2) -> (h', w', 3) float32 sRGB.

    The band-limited copy of a step rings (sinc ripples decaying over tens of pixels), and the step from
    an object to its background is the photograph's largest: read a quarter / half a pixel off the grid,
    the clay example's smooth photograph gained 4 / 7 times its high-frequency energy inside the object.
    Inside the objects the colours are read from the copy of the photograph whose background is the
    objects' colours continued (:func:`objects_continued`), which holds no silhouette: the clay keeps its
    energy within 5 %, the textured ball, cat and logo keep 0.94-1.0 of theirs either way. On and beyond
    the silhouette, and over SILHOUETTE_PX inside it, the photograph's own copy takes over, so that every
    pixel is read exactly on the grid (frame 0 is the photograph, its silhouette's pixels included).

    Args:
        photo: (h, w, 3) the photograph at output resolution; on_objects: (h, w) bool, its objects' mask.
    """
    plain = band_limited_upsample(photo)
    objects = band_limited_upsample(objects_continued(photo, on_objects))
    depth = cv2.distanceTransform(on_objects.astype(np.uint8), cv2.DIST_L2, 5) - 0.5  # px from the edge
    inside = np.clip(depth / SILHOUETTE_PX, 0.0, 1.0).astype(np.float32)

    def read(uv: np.ndarray) -> np.ndarray:
        weight = sample_at(inside, uv)[..., None]
        return weight * photograph_at(objects, uv) + (1 - weight) * photograph_at(plain, uv)

    return read


def smooth_source(uv: np.ndarray, sigma_px: float = SOURCE_SMOOTHING_PX) -> np.ndarray:
    """The source map with its per-pixel jitter removed, NaN where it was NaN.

    A normalised Gaussian blur (over the pixels that have a source only) leaves any affine
    map unchanged, so the surface does not move; what it removes is the jitter of a few tenths
    of a pixel that Gaussians stacked a millimetre apart in depth give a surface once it turns,
    which, sampled over a textured photograph, reads as added noise (measured on the coffee
    scene as it sways: texture sharpness up to 1.30x the photograph's, 1.16x smoothed).

    Args:
        uv: (h, w, 2) image points, NaN where there is no surface.
    """
    valid = np.isfinite(uv[..., 0])
    mean, _ = normalised_blur(uv, valid, sigma_px)
    return np.where(valid[..., None], mean, np.nan)


def trust(confidence: np.ndarray, threshold: float) -> np.ndarray:
    """Smooth step from 0 to 1 around ``threshold`` (width 0.2), so the switch between photo and render never pops."""
    x = np.clip((np.nan_to_num(confidence) - threshold) / 0.2 + 0.5, 0.0, 1.0)
    return x * x * (3 - 2 * x)


def seen_fraction(confidence: np.ndarray, coherence: np.ndarray) -> np.ndarray:
    """(h, w) in [0, 1]: how much of each pixel's surface the photograph saw (source_confidence is
    that times source_coherence; where the coherence is 0 it does not say, and the pixel counts as seen)."""
    return np.where(coherence > 1e-3, np.clip(confidence / np.maximum(coherence, 1e-3), 0, 1), 1.0)


def enhance_frames(coarse: CoarseArtifact, gaussians: GaussiansArtifact, threshold: float,
                   hidden_surfaces: str = "photo", relight: bool = True, ground: bool = False) -> np.ndarray:
    """The flow-enhanced video.

    Args:
        coarse: the render, T frames of h x w.
        gaussians: the reconstruction: photograph, object mask and inpainted background at full resolution.
        threshold: source_confidence (source_coherence, for hidden surfaces read as "photo") above which
            the photograph is trusted.
        hidden_surfaces: "photo" or "render", see the module docstring.
        relight: re-shade the object for where its surface faces in each frame (relight.py),
            when one light explains the photograph's shading.
        ground: the objects stand on a ground, on which their shadows follow them (shadow.py).
    Returns:
        (T, h, w, 3) uint8 RGB frames.
    """
    T, h, w = coarse.alpha.shape
    scale = w / gaussians.width  # full-resolution image points -> output image points
    photo = resize_to(gaussians.photo, w, h)
    backdrop = Backdrop(photo, resize_to(gaussians.background, w, h), gaussians.mask, coarse.alpha[0])
    read_objects = objects_reader(photo, backdrop.objects_share > 0.5)
    coverage = object_coverage(gaussians.mask, w, h)
    planes = MirrorPlanes.of(gaussians)
    continuation = Continuation.fit(coarse, gaussians, photo, coverage, read_objects, relight, planes)
    if ground:
        relighting = continuation.relighting
        shadows = Shadows.fit(coarse, gaussians, relighting.shading.light if relighting is not None else None, planes)
    frames = np.empty((T, h, w, 3), np.uint8)
    for t in range(T):
        rendered_uv = coarse.source_uv[t] * scale
        still = standing_still(rendered_uv)
        uv = smooth_source(rendered_uv)
        seen = seen_fraction(coarse.source_confidence[t], coarse.source_coherence[t])
        rendered = unpremultiply(coarse.rgb[t], coarse.alpha[t])
        surface = trust(coarse.source_coherence[t], threshold)
        from_photo, rendered, inside = continuation(t, uv, seen, rendered, surface, hidden_surfaces == "photo")
        trusted = trust(coarse.source_confidence[t], threshold)
        if hidden_surfaces == "photo":
            trusted = np.maximum(trusted, surface)
        weight = (trusted * inside)[..., None]
        colour = weight * from_photo + (1.0 - weight) * rendered
        background = backdrop(coarse.alpha[t], still, shadows(t, still) if ground else None)
        alpha = backdrop.objects_alpha(coarse.alpha[t], rendered_uv, still)
        frames[t] = blend_over_background(colour, alpha, background)
        on = coarse.alpha[t] > 0.5
        log.info("frame %d/%d: %.0f%% of the object's pixels from the photograph, %.0f%% of them continuing "
                 "surfaces it did not see", t + 1, T, 100.0 * float(weight[..., 0][on].mean()) if on.any() else 0.0,
                 100.0 * float((1 - seen)[on].mean()) if on.any() else 0.0)
    return frames
