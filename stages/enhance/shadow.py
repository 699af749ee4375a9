"""The objects' shadows on the ground, drawn under them in every frame.

The inpainted background holds the ground without the objects' shadows
(reconstruct/background.py divides them out); the photograph's own shadow is
then the ratio of the photograph to that background. In each frame the
objects' bodies are cast onto the ground plane along the fitted light
(fitted to the photograph's shadow): every pixel of the object gives its surface point (the frame's
depth) and the body's back behind it (the object is mirror-symmetric across a
vertical plane, unseen.MirrorPlanes, which moves with it); the points are
projected along the light onto the ground and back into the frame, and blurred
into a soft shadow. How dark and how soft is fitted to the photograph's own
shadow at rest. Where the objects still stand as photographed the
photograph's shadow stays exactly; as they leave it fades, and the cast one
takes over (docs/decisions/0025-shadows.md).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Optional

import cv2
import numpy as np

from schemas.artifacts import CoarseArtifact, GaussiansArtifact
from schemas.camera import pixel_rays

from .compositing import resize_to
from .unseen import MirrorPlanes, rest_in_camera

log = logging.getLogger("physmotion.enhance.shadow")

MIN_ELEVATION = 0.3
"""Sine of the light's elevation above the ground at least: a light along the ground would cast
shadows to the horizon."""
AZIMUTH_STEP_DEG = 20
ELEVATIONS_DEG = (20, 35, 50, 65, 80, 90)
"""Lights tried for the shadow besides the fitted one (towards_light), which the shading of one view
places poorly along the view (the example-like test ball: fitted 36 degrees off the true light): the
one whose cast shadow best matches the photograph's is drawn."""
SOFTNESS = (0.01, 0.03, 0.06, 0.12)
"""Blurs (standard deviation, share of the objects' size) among which the one that best matches the
photograph's shadow is drawn."""
SAMPLES_THROUGH = 4
"""Points along each pixel's ray through the body, front to back, that cast the shadow."""
MIN_DARKENING = 0.03
"""A fitted shadow darker than this at its deepest is drawn; fainter, the photograph shows none."""
MAX_DARKENING = 0.8
"""Darkening drawn at most."""


@dataclass(frozen=True)
class Ground:
    """The ground plane, camera frame: points x with x . down = height (m); down (3,) unit, along gravity."""

    down: np.ndarray
    height: float

    @classmethod
    def of(cls, gaussians: GaussiansArtifact) -> "Ground":
        """Through the objects' lowest point at rest, normal to gravity (as pm-simulate lays it)."""
        means, down = rest_in_camera(gaussians)
        return cls(down, float((means @ down).max()))


def towards_light(light: Optional[np.ndarray], down: np.ndarray) -> np.ndarray:
    """(3,) unit direction towards the light, camera frame, at least MIN_ELEVATION above the ground;
    straight overhead where no light was fitted."""
    if light is None or np.linalg.norm(light) < 1e-9:
        return -down
    direction = light / np.linalg.norm(light)
    up = -direction @ down
    if up < MIN_ELEVATION:
        level = direction + up * down
        level /= max(np.linalg.norm(level), 1e-9)
        direction = np.sqrt(1 - MIN_ELEVATION ** 2) * level - MIN_ELEVATION * down
    return direction


def candidate_lights(down: np.ndarray, view: np.ndarray) -> list[np.ndarray]:
    """Unit directions towards a light (camera frame) over the sky above the ground: AZIMUTHS around
    gravity times ELEVATIONS above the horizon."""
    up = -down
    forward = view - (view @ up) * up
    forward /= np.linalg.norm(forward)
    side = np.cross(up, forward)
    return [np.cos(e) * (np.cos(a) * side + np.sin(a) * forward) + np.sin(e) * up
            for e in np.radians(ELEVATIONS_DEG) for a in np.radians(np.arange(0, 360, AZIMUTH_STEP_DEG))]


def cast_footprint(points: np.ndarray, light: np.ndarray, ground: Ground, K: np.ndarray, h: int, w: int) -> np.ndarray:
    """(h, w) float32 in [0, 1]: the frame's pixels onto which points (N, 3, camera frame) cast a shadow
    on the ground along ``light`` (towards the light), gaps between the points' images closed."""
    above = ground.height - points @ ground.down  # m above the ground (> 0)
    keep = above > 0
    along = above[keep] / (-light @ ground.down)
    on_ground = points[keep] - along[:, None] * light
    image = on_ground @ K.T
    front = image[:, 2] > 1e-6
    uv = image[front, :2] / image[front, 2:]
    cols, rows = np.floor(uv[:, 0]).astype(int), np.floor(uv[:, 1]).astype(int)
    inside = (cols >= 0) & (cols < w) & (rows >= 0) & (rows < h)
    hits = np.zeros((h, w), np.float32)
    hits[rows[inside], cols[inside]] = 1.0
    closed = cv2.morphologyEx(hits, cv2.MORPH_CLOSE, np.ones((5, 5), np.uint8))
    return closed


class Shadows:
    """Each frame's darkening of the background (h, w) in [0, MAX_DARKENING]. Use :meth:`fit`."""

    def __init__(self, coarse, ground, light, planes, rays, photographed, strength, softness_px, rest_cast,
                 rest_along):
        self.coarse, self.ground, self.light, self.planes, self.rays = coarse, ground, light, planes, rays
        self.photographed, self.strength, self.softness_px = photographed, strength, softness_px
        self.rest_cast, self.rest_along = rest_cast, rest_along

    @classmethod
    def fit(cls, coarse: CoarseArtifact, gaussians: GaussiansArtifact, light: Optional[np.ndarray],
            planes: MirrorPlanes) -> "Shadows":
        """Args:
            light: (3,) the fitted light (relight.Shading.light, camera frame), or None: from overhead.
            planes: the objects' planes of symmetry at rest (MirrorPlanes.of(gaussians)).
        """
        h, w = coarse.alpha.shape[1:]
        ground = Ground.of(gaussians)
        direction = towards_light(light, ground.down)
        rays = pixel_rays(coarse.K, h, w)
        photo = resize_to(gaussians.photo, w, h).astype(np.float32).mean(-1)
        background = resize_to(gaussians.background, w, h).astype(np.float32).mean(-1)
        objects = resize_to((gaussians.mask > 0).astype(np.float32), w, h) > 0
        size = float(np.sqrt(max(objects.sum(), 1)))
        # beside the objects the background is the photograph, but for its shadow; under and around
        # them it is inpainted, and the ratio says nothing
        beyond = cv2.dilate(objects.astype(np.uint8), np.ones((3,) * 2, np.uint8), iterations=max(1, round(0.03 * size)))
        photographed = np.where(beyond > 0, 0.0, np.clip(1 - photo / np.maximum(background, 1.0), 0, MAX_DARKENING))
        shadows = cls(coarse, ground, direction, planes, rays, photographed.astype(np.float32), 0.0, 1.0, None, None)
        fitted = beyond == 0
        best = None
        for candidate in [direction] + candidate_lights(ground.down, rays[h // 2, w // 2]):
            shadows.light = candidate
            footprint, along = shadows.footprint(0)
            for share in SOFTNESS:
                cast = cv2.GaussianBlur(footprint, (0, 0), max(0.5, share * size))
                energy = float((cast[fitted] ** 2).sum())
                strength = float(np.clip((cast[fitted] * photographed[fitted]).sum() / max(energy, 1e-9), 0,
                                         MAX_DARKENING))
                residual = float(((photographed - strength * cast)[fitted] ** 2).sum())
                if best is None or residual < best[0]:
                    best = (residual, candidate, strength, share * size, cast, along)
        _, shadows.light, strength, softness, cast, along = best
        if strength * float(cast.max()) < MIN_DARKENING:
            strength = 0.0
        log.info("shadows: the photograph's is %.0f%% dark at its deepest; cast along the light towards "
                 "(%.2f, %.2f, %.2f) onto the ground %.3f m along gravity from the camera, drawn up to %.0f%% "
                 "dark, blurred by %.1f px", 100 * float(photographed.max()), *shadows.light, ground.height,
                 100 * strength * float(cast.max()), softness)
        shadows.strength, shadows.softness_px, shadows.rest_cast, shadows.rest_along = strength, softness, cast, along
        return shadows

    def footprint(self, t: int, rest_along: Optional[np.ndarray] = None) -> tuple[np.ndarray, np.ndarray]:
        """Frame t's shadow footprint (h, w) and the median of its surface along each object's plane
        normal (O,). The body's back is behind each surface point, mirrored across the object's plane,
        which moves along its normal as the surface does from rest (``rest_along``, frame 0's medians)."""
        alpha = self.coarse.alpha[t]
        on = alpha > 0.5
        h, w = alpha.shape
        if not on.any():
            return np.zeros((h, w), np.float32), np.zeros(len(self.planes.offset))
        front = self.rays[on] * (self.coarse.depth[t][on] / alpha[on])[:, None]
        # each pixel belongs to the object whose plane its surface lies nearest to
        distance = np.abs(front @ self.planes.normal.T - self.planes.offset)
        k = distance.argmin(1)
        along = np.array([np.median(front[k == o] @ self.planes.normal[o]) if (k == o).any() else np.nan
                          for o in range(len(self.planes.offset))])
        offset = self.planes.offset + (np.nan_to_num(along - rest_along) if rest_along is not None else 0.0)
        normal = self.planes.normal[k]
        ray = self.rays[on]
        towards = np.sum(ray * normal, -1)
        depth = np.maximum(2 * (offset[k] - np.sum(front * normal, -1)) / np.maximum(towards, 1e-3), 0.0)
        samples = [front + ray * (depth * s / (SAMPLES_THROUGH - 1))[:, None] for s in range(SAMPLES_THROUGH)]
        return cast_footprint(np.concatenate(samples), self.light, self.ground, self.coarse.K, h, w), along

    def __call__(self, t: int, staying: np.ndarray) -> np.ndarray:
        """(h, w) float32: how much frame t's background is darkened by the objects' shadows.

        Args:
            staying: (h, w) compositing.standing_still of frame t's source map at output resolution.
        """
        # how much of the objects stands where it stood in the photograph
        still = float(np.clip((self.coarse.alpha[t] * staying).sum() / max(self.coarse.alpha[0].sum(), 1e-6), 0, 1))
        footprint, _ = self.footprint(t, self.rest_along)
        cast = self.strength * cv2.GaussianBlur(footprint, (0, 0), max(0.5, self.softness_px))
        left = still * (self.photographed - self.strength * self.rest_cast)
        return np.clip(cast + left, 0, MAX_DARKENING).astype(np.float32)
