"""Surfaces the photograph did not see, coloured as the surfaces they continue.

The reconstruction's body is mirror-symmetric about a vertical plane through each
object, across the view (docs/decisions/0001-back-closure.md): its back is its
front, mirrored. A pixel whose surface the photograph never saw therefore takes
the colour of the mirror image of that surface point, which the photograph did
see. pm-render gives such a pixel, as its source, the point of the photograph in
front of it (its surface point at rest, projected): the surface point lies on that
pixel's ray at rest, where the ray leaves the body, and its mirror image is where
the mirrored ray meets the front (:func:`mirrored_source`).

Colours are read as albedo: the photograph's pixel divided by the shading the
fitted light gave it (relight.py), times the shading of where the surface faces
now. The photograph's pixels are a poor record where it saw the surface edge-on
(a pixel spans a strip of surface, and along the silhouette mixes in the
background): there the albedo is continued inwards from the nearest pixels it
recorded well (:meth:`Albedo.fit`), so that a surface which turns from the limb
towards the camera shows a smooth continuation rather than the limb's rings. A
pixel the photograph recorded well, or one still seen about as it was, keeps the
photograph's own pixel, re-shaded.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Callable, Optional

import cv2
import numpy as np

from schemas.artifacts import CoarseArtifact, GaussiansArtifact
from schemas.camera import pixel_rays

from .compositing import normalised_blur, sample_at, standing_still
from .relight import NORMAL_SMOOTHING, Relighting, Shading, smooth_normals, to_linear, to_srgb

log = logging.getLogger("physmotion.enhance.unseen")

RECORDED_FACING = (0.3, 0.55)
"""Cosine between the surface's normal and the view ray (at rest) from which the photograph's pixel
starts to be, and is fully, a record of the surface's colour. Below, a pixel spans a strip of surface
(at 0.3, more than three times its width along it) and its colour is the limb's dark, blurred rim.
The first is the twin of stages/reconstruct/lift.py's RECORDED_FACING: change both together."""
UNCHANGED = 0.2
"""Change of the facing cosine (and of the shading, as a share of the brightest) over which a pixel the
photograph recorded poorly goes from its own pixel (seen as it was: at rest the video is the
photograph) to the continued albedo."""
CONTINUE_SIGMA_PX = 1.5
"""Blur (output pixels) of each step of the inward continuation: one step reaches about this far."""
CONTINUE_MARGIN_PX = 3
"""The continued albedo covers the objects' masks dilated by this much, so that sources which fall a
little off the silhouette still read the object."""
MIRROR_ITERATIONS = 4
"""Fixed-point steps of :func:`mirrored_source`: each divides the error by the slope of the front
over the mirror line; four leave under a hundredth of a pixel on the test sphere away from its limb."""
MIRROR_STRETCH = (np.log(3.0), np.log(6.0))
"""|log| of the ratio of the mirrored map's area scale to the sources' own from which the mirror starts
to be, and is fully, distrusted: a mirror image is its point seen from the same side at nearly the
same distance, so its map stretches like the sources'. Where the front is unknown or cut (an object
cut by the photograph's border, whose front meets no back) the fixed point lands anywhere: the cat of
benchmarks/scenes turned 135 degrees read a whole small face into its eye."""
MAX_GAIN = 2.5
"""Shading ratios applied to the photograph's own pixels are clipped to [1/MAX_GAIN, MAX_GAIN]."""


def ramp(x: np.ndarray, bounds: tuple[float, float]) -> np.ndarray:
    """0 up to bounds[0], 1 from bounds[1], smooth between."""
    s = np.clip((np.nan_to_num(x) - bounds[0]) / (bounds[1] - bounds[0]), 0.0, 1.0)
    return s * s * (3 - 2 * s)


def rest_in_camera(gaussians: GaussiansArtifact) -> tuple[np.ndarray, np.ndarray]:
    """The Gaussians' means at rest (G,3) m and gravity's unit direction (3,), both in the camera frame."""
    R, t = gaussians.world_to_camera[:3, :3], gaussians.world_to_camera[:3, 3]
    down = R @ np.array([0.0, 1.0, 0.0])  # the world's y runs along gravity
    return gaussians.means.astype(np.float64) @ R.T + t, down


def facing(normals: np.ndarray, rays: np.ndarray) -> np.ndarray:
    """(h, w) cosine between camera-facing normals and the view rays; NaN where there is no normal."""
    return -np.sum(normals * rays, axis=-1)


@dataclass(frozen=True)
class MirrorPlanes:
    """Each object's plane of symmetry, camera frame: points x with x . normal[k] = offset[k].

    normal (O, 3): horizontal, towards the object (its body is mirror-symmetric across the view);
    offset (O,) m: halfway between the object's nearest and farthest Gaussians along it.
    """

    normal: np.ndarray
    offset: np.ndarray

    @classmethod
    def of(cls, gaussians: GaussiansArtifact) -> "MirrorPlanes":
        means, down = rest_in_camera(gaussians)
        objects = int(gaussians.object_id.max()) + 1
        normal, offset = np.zeros((objects, 3)), np.zeros(objects)
        for k in range(objects):
            own = means[gaussians.object_id == k]
            if len(own) == 0:
                normal[k] = (0.0, 0.0, 1.0)
                continue
            centre = own.mean(0)
            towards = centre - (centre @ down) * down
            if np.linalg.norm(towards) < 0.25 * np.linalg.norm(centre):  # seen from high above: across the view
                towards = centre
            normal[k] = towards / np.linalg.norm(towards)
            along = own @ normal[k]
            offset[k] = 0.5 * (np.percentile(along, 1) + np.percentile(along, 99))
        return cls(normal, offset)


def mirrored_source(uv: np.ndarray, front_distance: np.ndarray, rays: np.ndarray, normal: np.ndarray,
                    offset: np.ndarray, K: np.ndarray) -> np.ndarray:
    """(h', w', 2) where the photograph saw the mirror image of the surface point behind each source.

    A source uv names the ray at rest on which the pixel's surface point lies; for an unseen surface,
    where that ray leaves the body. Its mirror image across the object's plane lies on the front. The
    point is found by fixed-point steps: take the front at the current guess p, put the back point on
    uv's ray at the mirrored distance from the plane, and project its mirror image as the next p.

    Args:
        uv: (h', w', 2) source points at output resolution, NaN where none.
        front_distance: (h, w) distance (m) from the camera to the surface at rest at each output
            pixel (frame 0's depth / alpha), NaN off the objects.
        rays: (h, w, 3) unit view rays of the output pixels (``schemas.camera.pixel_rays``).
        normal: (h', w', 3), offset: (h', w') each pixel's plane (its object's, :class:`MirrorPlanes`).
        K: (3, 3) output intrinsics.
    Returns:
        Image points at output resolution, always on the front; uv itself where the front is not known.
    """
    inverse_K = np.linalg.inv(K)
    ray = np.concatenate([uv, np.ones_like(uv[..., :1])], -1) @ inverse_K.T
    ray /= np.linalg.norm(ray, axis=-1, keepdims=True)
    along = np.sum(ray * normal, -1)
    known = np.isfinite(front_distance)
    distance_map = np.nan_to_num(front_distance).astype(np.float32)
    weight_map = known.astype(np.float32)
    p = uv.copy()
    for _ in range(MIRROR_ITERATIONS):
        weight = sample_at(weight_map, p)
        distance = sample_at(distance_map, p) / np.maximum(weight, 1e-6)
        front_ray = sample_at(rays, p)
        front = front_ray / (np.linalg.norm(front_ray, axis=-1, keepdims=True) + 1e-12) * distance[..., None]
        height = np.sum(front * normal, -1) - offset  # the front's signed distance from the plane (< 0)
        back = ray * ((offset - height) / np.where(np.abs(along) > 1e-6, along, 1e-6))[..., None]
        image = (back + 2 * height[..., None] * normal) @ K.T
        step = image[..., :2] / np.maximum(image[..., 2:], 1e-9)
        # a step off the front (near the limb, where the front is steep) is not taken
        on_front = (weight > 0.5) & np.isfinite(step).all(-1) & (sample_at(weight_map, step) > 0.5)
        p = np.where(on_front[..., None], step, p)
    return p.astype(np.float32)


def area_scale(uv: np.ndarray) -> np.ndarray:
    """(h, w) |det(d uv / d pixel)| of a map (h, w, 2), by central differences; NaN at its edges."""
    du, dv = np.gradient(uv, axis=1), np.gradient(uv, axis=0)
    return np.abs(du[..., 0] * dv[..., 1] - du[..., 1] * dv[..., 0])


@dataclass(frozen=True)
class Albedo:
    """The photograph as albedo (linear light over the fitted shading) at output resolution, continued
    inwards over the pixels it records poorly; and how well it records each of them. Use :meth:`fit`.

    shading_rest (h, w): the shading each photograph pixel was taken under (1 without a light);
    recorded (h, w) in [0, 1]: how well the pixel records its surface's colour; continued (h, w, 3):
    the albedo, continued over the objects and a margin; inside (h, w): 1 on that region;
    facing_rest (h, w): the facing cosine at rest (NaN off the objects); coverage (h, w) in [0, 1]:
    how purely the pixel shows an object.
    """

    shading_rest: np.ndarray
    recorded: np.ndarray
    continued: np.ndarray
    inside: np.ndarray
    facing_rest: np.ndarray
    coverage: np.ndarray

    @classmethod
    def fit(cls, photo: np.ndarray, mask: np.ndarray, rest_normals: np.ndarray, rays: np.ndarray,
            shading: Optional[Shading]) -> "Albedo":
        """Args:
            photo: (h, w, 3) sRGB in [0, 255] at output resolution.
            mask: (h, w) float in [0, 1], how purely a photograph pixel shows an object
                (flow.object_coverage, its silhouette already faded).
            rest_normals: (h, w, 3) frame 0's smoothed normals (relight.smooth_normals), NaN off it.
            rays: (h, w, 3) view rays.
            shading: the fitted light, or None (the photograph's own brightness is the albedo).
        """
        photo_linear = to_linear(photo.astype(np.float32)).astype(np.float32)
        facing_rest = facing(rest_normals, rays)
        if shading is None:
            shading_rest = np.ones(mask.shape, np.float32)
        else:
            shading_rest = np.nan_to_num(shading(np.nan_to_num(rest_normals)), nan=1.0).astype(np.float32)
        recorded = (mask * ramp(facing_rest, RECORDED_FACING)).astype(np.float32)
        albedo = photo_linear / shading_rest[..., None]
        inside = cv2.dilate((mask > 0).astype(np.uint8), np.ones((2 * CONTINUE_MARGIN_PX + 1,) * 2, np.uint8)) > 0
        continued = continue_inwards(albedo, recorded > 0.5, inside)
        log.info("unseen surfaces: %.0f%% of the objects' pixels record their colour well, the rest is continued",
                 100 * float((recorded > 0.5)[mask > 0.5].mean()) if (mask > 0.5).any() else 0.0)
        return cls(shading_rest, recorded, continued, inside.astype(np.float32), facing_rest, mask.astype(np.float32))


def continue_inwards(values: np.ndarray, known: np.ndarray, region: np.ndarray) -> np.ndarray:
    """(h, w, C) float32: ``values`` where known, elsewhere in ``region`` continued from the known
    pixels ring by ring (each ring the normalised blur of those known so far, CONTINUE_SIGMA_PX), so
    the continuation is as smooth as the known values and follows their nearest ones."""
    filled = np.where(known[..., None], values, 0.0).astype(np.float32)
    have = known & region
    if not have.any():
        return np.where(region[..., None], values, 0.0).astype(np.float32)
    while True:
        missing = region & ~have
        if not missing.any():
            break
        blurred, weight = normalised_blur(filled, have, CONTINUE_SIGMA_PX)
        reach = missing & (weight > 0.05)
        if not reach.any():  # a part of the region no known pixel reaches: its mean colour
            filled[missing] = filled[have].mean(0)
            break
        filled[reach] = blurred[reach]
        have = have | reach
    return filled


class Continuation:
    """Each frame's object colour from the photograph, unseen surfaces continuing seen ones.

    Use :meth:`fit`; call with a frame's index, source points and seen fraction.
    """

    def __init__(self, coarse, albedo, relighting, sigma_px, planes, labels, front_distance, rays, photograph_at):
        self.coarse, self.albedo, self.relighting, self.sigma_px = coarse, albedo, relighting, sigma_px
        self.planes, self.labels, self.front_distance, self.rays = planes, labels, front_distance, rays
        self.photograph_at = photograph_at

    @classmethod
    def fit(cls, coarse: CoarseArtifact, gaussians: GaussiansArtifact, photo: np.ndarray, coverage: np.ndarray,
            photograph_at: Callable[[np.ndarray], np.ndarray], relight: bool, planes: MirrorPlanes) -> "Continuation":
        """Args:
            photo: (h, w, 3) the photograph at output resolution; coverage: (h, w) flow.object_coverage;
            photograph_at: (h, w, 2) image points -> (h, w, 3) sRGB, the photograph read there with its
                detail (flow.photograph_at); relight: fit a light; planes: MirrorPlanes.of(gaussians).
        """
        h, w = coarse.alpha.shape[1:]
        relighting = Relighting.fit(coarse, photo) if relight else None
        on = coarse.alpha[0] > 0.5
        sigma = relighting.sigma_px if relighting else max(1.0, NORMAL_SMOOTHING * float(np.sqrt(max(on.sum(), 1))))
        rest_normals = relighting.rest_normals if relighting else smooth_normals(coarse.normal[0], coarse.alpha[0], sigma)
        rays = pixel_rays(coarse.K, h, w).astype(np.float32)
        albedo = Albedo.fit(photo, coverage, rest_normals, rays, relighting.shading if relighting else None)
        front_distance = np.where(on, coarse.depth[0] / np.maximum(coarse.alpha[0], 1e-6), np.nan)
        labels = cv2.resize(gaussians.mask, (w, h), interpolation=cv2.INTER_NEAREST)
        return cls(coarse, albedo, relighting, sigma, planes, labels, front_distance, rays,
                   photograph_at)

    def shading_now(self, t: int) -> tuple[np.ndarray, np.ndarray]:
        """(h, w) the shading and (h, w) the facing cosine of frame t's surface."""
        normals = smooth_normals(self.coarse.normal[t], self.coarse.alpha[t], self.sigma_px)
        shading = (np.ones(normals.shape[:2], np.float32) if self.relighting is None
                   else np.nan_to_num(self.relighting.shading(np.nan_to_num(normals)), nan=1.0))
        return shading.astype(np.float32), facing(normals, self.rays)

    def mirror(self, uv: np.ndarray) -> np.ndarray:
        """(h, w, 2) mirrored sources (:func:`mirrored_source`) of sources uv, each by its object's plane,
        where the mirrored map is as smooth as the sources' own (see MIRROR_STRETCH); uv elsewhere."""
        label = sample_at(self.labels.astype(np.float32), uv, cv2.INTER_NEAREST).astype(int)
        k = np.clip(label - 1, 0, len(self.planes.offset) - 1)
        mirrored = mirrored_source(uv, self.front_distance, self.rays, self.planes.normal[k], self.planes.offset[k],
                                   self.coarse.K)
        stretch = np.abs(np.log(np.maximum(area_scale(mirrored), 1e-6) / np.maximum(area_scale(uv), 1e-6)))
        kept = np.clip(1 - (np.nan_to_num(stretch, nan=0.0) - MIRROR_STRETCH[0])  # NaN: at the map's edge
                       / (MIRROR_STRETCH[1] - MIRROR_STRETCH[0]), 0, 1).astype(np.float32)
        # over regions, not pixel by pixel: a speckle of mirrored and direct reads would be noise
        kept = cv2.GaussianBlur(cv2.erode(kept, np.ones((5, 5), np.uint8)), (0, 0), 1.5)[..., None]
        return (kept * mirrored + (1 - kept) * uv).astype(np.float32)

    def read(self, uv: np.ndarray, shading_now: np.ndarray, facing_now: np.ndarray,
             still: np.ndarray) -> tuple[np.ndarray, ...]:
        """Colour (h, w, 3, linear), the shading its source had (h, w) and whether it is on an object
        (h, w), for a surface now shaded ``shading_now`` and facing ``facing_now`` whose colour the
        photograph holds at uv: its own pixel where recorded well or seen as it was, else continued.
        ``still`` (h, w) in [0, 1]: how much the pixel stands where its source is; the photograph's
        pixels along the silhouette, which mix in the background, are its own only there."""
        a = self.albedo
        # A source beyond the photograph's border (the cut of an object the border cuts) lies on none of
        # its objects (``inside`` falls to 0 there), but its colour and shading are the border pixels':
        # the zeros beyond the border would darken the colour and drive the gain to MAX_GAIN beside it.
        inside = sample_at(a.inside, uv)
        height, width = a.shading_rest.shape
        uv = np.clip(uv, 0.5, (width - 0.5, height - 0.5))
        shading_then = sample_at(a.shading_rest, uv)
        recorded = sample_at(a.recorded, uv)
        facing_then = sample_at(np.nan_to_num(a.facing_rest), uv)
        relit = 1.0 if self.relighting is None else self.relighting.shading.ambient + float(
            np.linalg.norm(self.relighting.shading.light))
        unchanged = (np.clip(1 - np.abs(np.nan_to_num(facing_now) - facing_then) / UNCHANGED, 0, 1)
                     * np.clip(1 - np.abs(shading_now - shading_then) / (UNCHANGED * relit), 0, 1))
        own = np.maximum(recorded, unchanged * np.maximum(sample_at(a.coverage, uv), still))[..., None]
        from_fine = to_linear(self.photograph_at(uv))
        gain = np.clip(shading_now / np.maximum(shading_then, 1e-6), 1 / MAX_GAIN, MAX_GAIN)[..., None]
        continued = sample_at(a.continued, uv) * shading_now[..., None]
        return own * from_fine * gain + (1 - own) * continued, shading_then, inside

    def __call__(self, t: int, uv: np.ndarray, seen: np.ndarray, rendered: np.ndarray, surface: np.ndarray,
                 unseen_from_photo: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Frame t's object colour from the photograph (h, w, 3) sRGB in [0, 255], the render re-shaded
        alike (h, w, 3), and where the photograph holds the pixel's surface (h, w) in [0, 1].

        Args:
            uv: (h, w, 2) the frame's smoothed source points at output resolution (flow.smooth_source).
            seen: (h, w) in [0, 1], how much of each pixel's surface the photograph saw.
            rendered: (h, w, 3) the render's colour, sRGB in [0, 255].
            surface: (h, w) in [0, 1], how surely the render shows the object's surface, carried smoothly
                from the photograph (the trusted source_coherence): only there is the render re-lit or gives
                way to the continued colour, never where it shows the interior, grains or tumbling material.
            unseen_from_photo: the unseen surfaces' render gives way to the continued colour too
                (enhance.hidden_surfaces "photo"); else only the seen ones' does.
        """
        shading_now, facing_now = self.shading_now(t)
        still = standing_still(uv)
        direct, shading_direct, inside_direct = self.read(uv, shading_now, facing_now, still)
        mirrored_uv = self.mirror(uv)
        mirrored, shading_mirrored, inside_mirrored = self.read(mirrored_uv, shading_now, facing_now,
                                                                np.zeros_like(still))
        s = np.clip(seen, 0, 1)
        colour = s[..., None] * direct + (1 - s[..., None]) * mirrored
        inside = s * inside_direct + (1 - s) * inside_mirrored
        then = s * shading_direct + (1 - s) * shading_mirrored
        # the render's colours carry the photograph's shading of their source, as the photograph does,
        # where it recorded that source well; at its limb they are the Gaussians' compromise with the
        # background beyond (re-lit by the limb's shading, the ambient alone, they would be light specks
        # along the seam): there the colour continued from the surface recorded well takes their place,
        # and beyond its reach they are not re-lit. Where the render shows what the source map does not
        # carry (the interior, grains, a jumbled map) neither happens: the shading its source had is not
        # known, and the render, drawn from the particles, is the only record of it
        recorded = s * sample_at(self.albedo.recorded, uv) + (1 - s) * sample_at(self.albedo.recorded, mirrored_uv)
        recorded = np.where(np.isfinite(uv[..., 0]), recorded, 1.0)[..., None]
        gain = np.clip(shading_now / np.maximum(then, 1e-6), 1 / MAX_GAIN, MAX_GAIN)
        gain = 1 + recorded * surface[..., None] * (np.where(np.isfinite(uv[..., 0]), gain, 1.0)[..., None] - 1)
        continued = ((1 - recorded) * surface[..., None]
                     * (inside if unseen_from_photo else s * inside)[..., None])
        relit_render = (1 - continued) * to_linear(rendered) * gain + continued * colour
        return to_srgb(colour).astype(np.float32), to_srgb(relit_render).astype(np.float32), inside.astype(np.float32)
