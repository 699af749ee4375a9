"""The photograph with its objects inpainted away, for the enhancement's compositing (I_B^0).

Inside the hole the fill is by exemplar: each missing patch is copied from the
best-matching patch of the known background around the hole, coarse to fine
(PatchMatch, Barnes et al. 2009, with patchmatch-cython's solver). Three things
keep the copies a continuation of the hole's surroundings rather than a piece
of whatever else the photograph shows (docs/decisions/0042-the-fill-continues-its-surroundings.md):
patches are copied only from a band around the hole as wide as the hole is
thick; the coarsest level of the pyramid is the one at which the hole is about
two patches across, not one patch for the whole photograph; and there the hole
starts from the diffusion fill and each missing patch from the nearest known
one, not from black. Diffusion (OpenCV's Telea method) carries the hole's rim
inwards and smears a hole wider than a few pixels into streaks, and once the
object moves away the whole hole is on screen. Along the seam, though, the
rim's own colours are the better guess: the dilation ring around the object
shows at rest, where the video should look like the photograph, and a copied
patch of another material (the table's wood where the cup stood on its
saucer) would outline the object. So the fill cross-fades from diffusion at
the seam to exemplar past twice the dilation.

The hole is each object's mask grown past its edge's whole transition in the
photograph, read per boundary pixel along the outline's normal: a segmentation
ends inside a blurred object's soft edge, and the edge's outer part, or a dark
rim just outside, left in the photograph outlines the object's place once it
moves away. The transition ends where the photograph varies no more than the
ground beyond it does, and at most a fifth of the object's size out.

The objects' own shadows go too: an object that moves away takes its shadow
with it (the enhancement draws it anew under the object, stages/enhance/shadow.py).
A shadow is a smooth darkening of the ground that starts at an object's foot, so
it is found as the photograph's brightness (the hole filled by diffusion),
smoothed past its texture, against the brightness around it and below it (a
high percentile over twice the object's size), given the photograph's own
edges, and divided out of every channel before the hole is filled
(docs/decisions/0025-shadows.md).
"""
from __future__ import annotations

import logging
import warnings

import cv2
import numpy as np
from patchmatch_cython import CythonSolver
from patchmatch_cython.imageops import (build_query_patch_centers, build_valid_patch_centers, sanitize_nnf,
                                         upsample)
from scipy import ndimage
from scipy.spatial import cKDTree

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
"""Neighbourhood of Telea's method: the fill along the seam, and where the exemplar fill starts from."""
SOURCE_REACH = 1.0
"""Patches are copied from known pixels at most this many hole thicknesses (twice the largest distance
inside the hole to its edge) from the hole, and at least 4 patches: the hole continues its surroundings.
Searched over the whole photograph, the fill of the shuttle's place beside scikit-image's astronaut copies
her hair, an eye and her suit (0042-the-fill-continues-its-surroundings.md)."""
COARSE_PATCHES = 2
"""The pyramid's coarsest level is the one at which the hole is about this many patches thick: there the
copies are chosen, and every finer level refines them. At 1 a hole beside the astronaut's hair fills with a
block of hair; at 3 the loaf's brick floor blurs into streaks (0042-the-fill-continues-its-surroundings.md)."""
SEAM_WIDTH = 2
"""Width of the cross-fade from diffusion to exemplar fill, in dilation radii. Measured on the
coffee scene, whose ring shows around the cup at rest: frame-0 PSNR 36.7 dB with Telea alone,
34.4 / 36.1 / 36.5 dB with 1 / 2 / 3 radii, 32.6 dB with exemplar alone."""


SHADOW_WORKING_PX = 128
"""The shadow is estimated on a copy in which the objects' size (the square root of their pixel
count) is this many pixels, smoothed by one of them: the example ball's shadow is 16 of them tall, and
the loaf's hard-edged shadow band, 24 px under it, keeps its depth; on a coarser copy its edge becomes a
ramp as wide as the band, which divided out leaves the band's outline (0033-which-darkening-is-a-shadow.md)."""
SHADOW_REFERENCE_PX = 64
"""The unshadowed brightness (SHADOW_REFERENCE), smooth by its nature, is taken on a copy in which the
objects are this many pixels across: its percentile window costs the square of this."""
SHADOW_REFERENCE = (2.0, 80)
"""The unshadowed brightness at a pixel: this percentile of the smoothed brightness over a window of
this many object sizes across and a quarter of that high (a shadow fills less than a fifth of it;
the ground's brightness changes with its distance, from row to row), the lesser of the window centred
on the pixel and the one from its row down. Below a pixel of the ground lies more of the same ground,
nearer the camera; above it may lie a lighter wall, by which the floor along their edge would read as
shadowed. Around it lies the same surface where the one below differs (a saucer on a lighter table)."""
SHADOW_REACH = 1.0
"""Shadows are looked for up to this many object sizes from the objects' masks."""
SHADOW_DEPTH = (0.08, 0.16)
"""Darkening (1 - brightness / unshadowed brightness) below which a pixel is taken as unshadowed,
and from which it is taken in full; smooth between. Both are raised by the texture that smoothing
leaves (TEXTURE_SPREADS)."""
TEXTURE_SPREADS = 4.0
"""A pixel counts as darkened only past this many robust standard deviations of the darkening away
from the objects, where the ground's own texture left after smoothing sets it: the exemplar fill of
a coarse periodic texture (tests/reconstruct) would otherwise read as a shadow."""
FOOT = 0.2
"""An object stands on the ground with the lowest part of its outline, this share of its height: a cast
shadow starts at that contact, so a darkening that touches no object's foot (a dark room behind the
object, a dark patch beside its top) is no shadow of it. An object cut by the photograph's lower
border shows no contact and is given no shadow."""
PENUMBRA = 0.1
"""Around the pixels found shadowed, this share of the objects' size is taken as their penumbra,
darkened by however little: cut off at SHADOW_DEPTH, its edge would outline the shadow that left."""
EDGE_RADIUS = 2
"""Half the side of the guided filter's window, in pixels of the working copy (the blur it undoes is one)."""
EDGE_EPS = 1e-3
"""Regularisation of the guided filter (He et al. 2010) that gives the shadow found on the working copy the
photograph's own edges (brightness in [0, 1], squared): a hard-edged shadow, smoothed on the copy and
divided out, left its outline; the ground's texture varies the brightness more than this and stays."""
EDGE_REACH = 0.2
"""The hole reaches past an object's mask at most this share of its size (the square root of its pixel
count): an edge's transition is read no farther, and nothing of the ground beyond it is filled."""
EDGE_GROUND = (90, 2.0)
"""An edge's transition goes on while the photograph varies, over a window, more than this factor times
this percentile of how the ground beyond it varies over such windows: a textured ground varies too. At
the median, the mortar lines that touch the example loaf were taken into its hole."""
EDGE_GROUND_BAND = (1.5, 2.5)
"""The ground beyond an edge is read this many reaches (EDGE_REACH) out along its normal: past the reach
itself, so that a transition that runs up to it does not pass for the ground's texture (read from one to
two reaches, the fade beside a clock that GrabCut cut short stopped at 13-16 px of its 22)."""
EDGE_FLOOR = 1.5
"""sRGB levels (of 255) over a window below which the photograph counts as not varying, whatever the ground."""
MAX_SHADOW = 0.8
"""Darkening divided out at most: deeper, the ground's colour is mostly noise."""


def touching_feet(taken: np.ndarray, labels: np.ndarray, reach_px: int) -> np.ndarray:
    """(h, w) bool: the connected parts of ``taken`` (h, w bool) that come within ``reach_px`` of an
    object's foot (FOOT; ``labels`` h x w, 0 the background). Objects touching the lower border have none."""
    feet = np.zeros(labels.shape, np.uint8)
    for k in np.unique(labels[labels > 0]):
        rows = np.nonzero((labels == k).any(1))[0]
        if rows.max() >= labels.shape[0] - 1:
            continue
        lowest = rows.max() - FOOT * (rows.max() - rows.min() + 1)
        feet[(labels == k) & (np.arange(labels.shape[0])[:, None] >= lowest)] = 1
    feet = cv2.dilate(feet, np.ones((2 * reach_px + 1,) * 2, np.uint8))
    _, parts = cv2.connectedComponents(taken.astype(np.uint8))
    touching = np.unique(parts[(feet > 0) & taken])
    return np.isin(parts, touching[touching > 0])


def guided_filter(guide: np.ndarray, values: np.ndarray, radius: int, eps: float) -> np.ndarray:
    """(H, W) float32: ``values`` (H, W) made locally linear in ``guide`` (H, W) over windows of
    2 radius + 1 pixels (He, Sun and Tang 2010): smooth where the guide is, with its edges where they
    coincide with the values'."""
    box = lambda a: cv2.boxFilter(a, cv2.CV_32F, (2 * radius + 1,) * 2)  # noqa: E731
    mean_guide, mean_values = box(guide), box(values)
    covariance = box(guide * values) - mean_guide * mean_values
    variance = box(guide * guide) - mean_guide * mean_guide
    slope = covariance / (variance + eps)
    return box(slope) * guide + box(mean_values - slope * mean_guide)


def smoothed_copy(brightness: np.ndarray, size: float, working_px: int) -> tuple[float, np.ndarray]:
    """The scale of a copy of ``brightness`` (H, W) in which objects ``size`` pixels across are
    ``working_px`` across (at most 1), and that copy smoothed by one of their pixels."""
    scale = min(1.0, working_px / max(size, 1.0))
    height, width = brightness.shape
    small = cv2.resize(brightness, (max(1, round(width * scale)), max(1, round(height * scale))),
                       interpolation=cv2.INTER_AREA)
    return scale, cv2.GaussianBlur(small, (0, 0), max(1.0, size * scale / working_px))


def photographed_shadow(background: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """(H, W) float32 in [0, MAX_SHADOW]: how much the objects' shadows darken the (filled) photograph,
    0 where no shadow is found. Darkening is measured on the sRGB values' mean: a shadow scales linear
    light, and so (up to sRGB's linear toe) scales sRGB values too. A shadow is darker than the ground
    nearer the camera (SHADOW_REFERENCE) and touches an object's foot (FOOT)."""
    objects = labels > 0
    size = float(np.sqrt(objects.sum()))
    height, width = labels.shape
    full_brightness = background.astype(np.float32).mean(-1)
    scale, smooth = smoothed_copy(full_brightness, size, SHADOW_WORKING_PX)
    coarse_scale, coarse = smoothed_copy(full_brightness, size, SHADOW_REFERENCE_PX)
    across = SHADOW_REFERENCE[0] * size * coarse_scale
    window = (2 * round(across / 8) + 1, 2 * round(across / 2) + 1)
    around, below = (cv2.resize(ndimage.percentile_filter(coarse, SHADOW_REFERENCE[1], size=window, mode="nearest",
                                                          origin=(origin, 0)), smooth.shape[::-1],
                                interpolation=cv2.INTER_LINEAR) for origin in (0, -(window[0] // 2)))
    darkening = lambda unshadowed: np.clip(1 - smooth / np.maximum(unshadowed, 1.0), 0, MAX_SHADOW)  # noqa: E731
    dark = darkening(np.minimum(around, below))
    small_labels = cv2.resize(labels.astype(np.uint8), smooth.shape[::-1], interpolation=cv2.INTER_NEAREST)
    away = cv2.distanceTransform((small_labels == 0).astype(np.uint8), cv2.DIST_L2, 3) / max(size * scale, 1e-6)
    ground = darkening(around)[away > 0.25]
    spread = 1.4826 * float(np.median(np.abs(ground - np.median(ground)))) if ground.size else 0.0
    low = max(SHADOW_DEPTH[0], TEXTURE_SPREADS * spread)
    taken = np.clip((dark - low) / (SHADOW_DEPTH[1] - SHADOW_DEPTH[0]), 0, 1)
    near = np.clip((SHADOW_REACH - away) / (0.25 * SHADOW_REACH), 0, 1)
    reach = max(1, round(PENUMBRA * size * scale))
    taken = np.where(touching_feet((taken * near) > 0, small_labels, reach), taken, 0.0)
    # around what is surely shadow its faint penumbra is shadow too, however little it darkens
    core = (taken * taken * (3 - 2 * taken)).astype(np.float32)
    penumbra = cv2.GaussianBlur(cv2.dilate(core, np.ones((2 * reach + 1,) * 2, np.uint8)), (0, 0), 1.0)
    shadow = cv2.resize(dark * np.maximum(core, penumbra) * near, (width, height), interpolation=cv2.INTER_LINEAR)
    if not shadow.any():
        return shadow.astype(np.float32)
    edges = guided_filter(full_brightness / 255, shadow.astype(np.float32), max(1, round(EDGE_RADIUS / scale)), EDGE_EPS)
    return np.clip(np.where(cv2.dilate((shadow > 0).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0, edges, 0),
                   0, MAX_SHADOW).astype(np.float32)


def without_shadow(background: np.ndarray, shadow: np.ndarray) -> np.ndarray:
    """(H, W, 3) u8: ``background`` with ``shadow`` (H, W, from photographed_shadow) divided out."""
    lifted = background.astype(np.float32) / (1 - shadow[..., None])
    return np.where(shadow[..., None] > 0, np.clip(lifted + 0.5, 0, 255), background).astype(np.uint8)


def nearest_sources(valid: np.ndarray) -> np.ndarray:
    """(h, w, 2) int32 (x, y): for every pixel the nearest of the ``valid`` (h, w bool) patch centres."""
    _, (rows, cols) = ndimage.distance_transform_edt(~valid, return_indices=True)
    return np.stack([cols, rows], -1).astype(np.int32)


def surroundings(hole: np.ndarray) -> tuple[np.ndarray, int]:
    """The known pixels that patches are copied from (h, w bool: within SOURCE_REACH of the ``hole``,
    h x w bool) and the number of pyramid levels above the photograph's, at whose coarsest the hole is
    about COARSE_PATCHES patches thick."""
    inside = cv2.distanceTransform(np.pad(hole, 1).astype(np.uint8), cv2.DIST_L2, 5)[1:-1, 1:-1]
    thickness = 2.0 * float(inside.max())
    away = cv2.distanceTransform((~hole).astype(np.uint8), cv2.DIST_L2, 5)
    sources = (away <= max(SOURCE_REACH * thickness, 4 * PATCH_PX)) & ~hole
    return sources, max(0, int(np.log2(max(thickness, 1.0) / (COARSE_PATCHES * PATCH_PX))))


def copied_patches(photo: np.ndarray, hole: np.ndarray, sources: np.ndarray, start: np.ndarray,
                   levels: int) -> np.ndarray:
    """(h, w, 3) float32: ``photo`` (h, w, 3) with ``hole`` (h, w bool) filled by patches copied from
    ``sources`` (h, w bool), coarse to fine over ``levels`` halvings. At the coarsest level the hole holds
    ``start`` (h, w, 3, the diffusion fill) and each missing patch is matched first to its nearest source;
    every finer level starts from the coarser's fill and matches. Known pixels that are no source are
    filled along with the hole (the solver copies from every known pixel) and count for nothing."""
    half = PATCH_PX // 2
    unknown = (hole | ~sources).astype(np.float32)
    height, width = hole.shape
    fill = matches = None
    for level in range(levels, -1, -1):
        size = (max(PATCH_PX, width >> level), max(PATCH_PX, height >> level))
        image = cv2.resize(photo.astype(np.float32), size, interpolation=cv2.INTER_AREA)
        mask = cv2.resize(unknown, size, interpolation=cv2.INTER_AREA) > 0
        valid = build_valid_patch_centers(mask, half)
        if fill is None:
            image[mask] = cv2.resize(start.astype(np.float32), size, interpolation=cv2.INTER_AREA)[mask]
            matches = nearest_sources(valid)
        else:
            image[mask] = cv2.resize(fill, size, interpolation=cv2.INTER_LINEAR)[mask]
            matches = sanitize_nnf(upsample(matches, size[1], size[0]), build_query_patch_centers(mask, half),
                                   valid, rng=np.random.default_rng(0))
        solver = CythonSolver(image, mask, PATCH_PX)
        fill = solver(iterations=2 * (levels - level) + 5, randomize_nnf=False, nnf=matches, seed=0)
        matches = solver.nnf
    return fill


def exemplar_fill(photo: np.ndarray, hole: np.ndarray, start: np.ndarray) -> np.ndarray:
    """(H, W, 3) u8: ``photo`` with the ``hole`` (H, W bool) filled by patches copied from its
    surroundings (:func:`surroundings`), starting from ``start`` (H, W, 3, the diffusion fill); computed
    on the surroundings' bounding box, at most EXEMPLAR_MAX_PX on the photograph's long side."""
    height, width = hole.shape
    size = (width, height)
    if max(size) > EXEMPLAR_MAX_PX:
        size = tuple(round(side * EXEMPLAR_MAX_PX / max(width, height)) for side in size)
        photo, start = (cv2.resize(image, size, interpolation=cv2.INTER_AREA) for image in (photo, start))
        hole = cv2.resize(hole.astype(np.uint8), size, interpolation=cv2.INTER_AREA) > 0
    sources, levels = surroundings(hole)
    if not cv2.erode(sources.astype(np.uint8), np.ones((PATCH_PX, PATCH_PX), np.uint8), borderValue=0).any():
        raise ValueError("no whole patch of background around the hole")
    rows, cols = np.nonzero(sources | hole)
    box = np.s_[rows.min():rows.max() + 1, cols.min():cols.max() + 1]
    # the solver compares a patch that crosses the photograph's border with black there, and so fills a
    # hole near the border with dark copies: past the border lies unknown ground, mirrored to start with,
    # as far as the patches around the hole reach at the coarsest level
    margin = (PATCH_PX // 2 + 1) << levels
    hole_rows, hole_cols = np.nonzero(hole)
    height_px, width_px = hole.shape
    top, left, bottom, right = (margin if box_gap == 0 and hole_gap < margin else 0 for box_gap, hole_gap in (
        (rows.min(), hole_rows.min()), (cols.min(), hole_cols.min()),
        (height_px - 1 - rows.max(), height_px - 1 - hole_rows.max()),
        (width_px - 1 - cols.max(), width_px - 1 - hole_cols.max())))

    def pad(image: np.ndarray, border_type: int, value: int = 0) -> np.ndarray:
        """``image`` (the box's pixels) with those margins added, filled by cv2's border_type (or value)."""
        return cv2.copyMakeBorder(image, top, bottom, left, right, borderType=border_type, value=value)

    unknown = pad(hole[box].astype(np.uint8), cv2.BORDER_CONSTANT, 1) > 0
    copied = copied_patches(pad(photo[box], cv2.BORDER_REFLECT), unknown,
                            pad(sources[box].astype(np.uint8), cv2.BORDER_CONSTANT, 0) > 0,
                            pad(start[box], cv2.BORDER_REFLECT), levels)
    filled = photo.astype(np.float32)
    filled[box] = copied[top:copied.shape[0] - bottom, left:copied.shape[1] - right]
    filled = np.where(hole[..., None], np.clip(filled + 0.5, 0, 255), photo).astype(np.uint8)
    return cv2.resize(filled, (width, height), interpolation=cv2.INTER_CUBIC) if size != (width, height) else filled


def dilation_px(height: int, width: int) -> int:
    """The least the hole reaches past the masks, pixels: GrabCut's misses and an edge's antialiasing
    (1 % of the photograph's size, at least 3 px). It is also the window over which an edge's transition
    is read (:func:`edge_widths`)."""
    return max(3, round(0.01 * max(height, width)))


def edge_widths(photo: np.ndarray, inside: np.ndarray, ground: np.ndarray,
                window_px: int) -> tuple[np.ndarray, np.ndarray]:
    """How far past the outline of ``inside`` (H, W bool, one object) the photograph (H, W, 3) still changes
    across it: the boundary pixels (N, 2 int, row and column) and, for each, the width (N,) in pixels of
    the edge's transition outside it, at most EDGE_REACH of the object's size.

    Along the outward normal the photograph (smoothed by a sixth of ``window_px``) is sampled; the transition
    ends where, over the next ``window_px``, it varies no more than the ``ground`` (H, W bool: no object's)
    does farther out (EDGE_GROUND, in EDGE_GROUND_BAND, along this boundary stretch), or than EDGE_FLOOR.
    A blurred outline's soft ramp and a dark rim, halo or shadow that starts at the outline are inside
    it; the ground's texture, and a structure past a flat gap, are not. Where no ground is seen (the
    photograph's border, other objects) the transition is taken as ended."""
    reach = EDGE_REACH * float(np.sqrt(inside.sum()))
    step = window_px / 6
    smooth = cv2.GaussianBlur(photo.astype(np.float32), (0, 0), window_px / 6)
    mask = inside.astype(np.uint8)
    boundary = inside & (cv2.dilate(1 - mask, np.ones((3, 3), np.uint8)) > 0)
    rows, cols = np.nonzero(boundary)
    if not rows.size:  # the object covers the whole photograph
        return np.zeros((0, 2), np.int64), np.zeros(0)
    soft = cv2.GaussianBlur(mask.astype(np.float32), (0, 0), window_px / 2)
    down, right = np.gradient(soft)
    normal = -np.stack([right[rows, cols], down[rows, cols]], 1)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-9)
    along = np.arange(0, EDGE_GROUND_BAND[1] * reach + window_px + step, step)
    where = [rows[:, None] + normal[:, 1:] * along, cols[:, None] + normal[:, :1] * along]
    profile = np.stack([ndimage.map_coordinates(smooth[..., c], where, order=1, mode="nearest")
                        for c in range(3)], -1)
    seen = ndimage.map_coordinates(ground.astype(np.uint8), where, order=0, mode="constant", cval=0) > 0
    # the variation of each channel over [s, s + window_px], the most of any channel
    span = round(window_px / step) + 1
    origin = -(span // 2)
    variation = (ndimage.maximum_filter1d(profile, span, axis=1, origin=origin, mode="nearest") -
                 ndimage.minimum_filter1d(profile, span, axis=1, origin=origin, mode="nearest")).max(-1)
    seen = ndimage.minimum_filter1d(seen, span, axis=1, origin=origin, mode="constant", cval=0)
    band = (along >= EDGE_GROUND_BAND[0] * reach) & (along <= EDGE_GROUND_BAND[1] * reach)
    points = np.stack([rows, cols], 1)
    tree = cKDTree(points)
    with warnings.catch_warnings():  # a profile, or a whole stretch, that sees no ground
        warnings.simplefilter("ignore", RuntimeWarning)
        texture = np.nanpercentile(np.where(seen, variation, np.nan)[:, band], EDGE_GROUND[0], axis=1)
        # a darker patch of ground beside one stretch understates the ground's texture there: at least
        # the median all around the object counts
        texture = np.maximum([np.nanmedian(texture[stretch]) for stretch in tree.query_ball_point(points, r=reach)],
                             np.nanmedian(texture))
    tolerance = np.where(np.isnan(texture), np.inf, np.maximum(EDGE_GROUND[1] * texture, EDGE_FLOOR))
    flat = (variation <= tolerance[:, None]) | (along > reach)
    width = along[np.argmax(flat, axis=1)]
    # one profile that meets a speck is no edge: the stretch's median
    width = np.array([np.median(width[stretch]) for stretch in tree.query_ball_point(points, r=window_px)])
    return points, width


def background_hole(photo: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """(H, W) u8, 1 where the background is filled: every object (``labels`` > 0) grown, per boundary
    pixel, past its edge's whole transition in the photograph (:func:`edge_widths`), and at least
    :func:`dilation_px`. A mask that ends inside an object's soft edge leaves its outer part, and a dark
    rim or halo just outside, in the photograph: once the object moves away, they outline its place."""
    least = dilation_px(*labels.shape)
    hole = (labels > 0).astype(np.uint8)
    radii = np.zeros(labels.shape, np.int32)
    for k in np.unique(labels[labels > 0]):
        points, width = edge_widths(photo, labels == k, labels == 0, least)
        # a pixel more: where the transition counts as ended it may still be off the ground by the tolerance
        # (tests/reconstruct/test_reconstruct_halo.py's dark rim: 3.4/255 off in the ring without it, 1.4 with)
        radii[points[:, 0], points[:, 1]] = np.maximum(radii[points[:, 0], points[:, 1]],
                                                       np.maximum(least, np.ceil(width) + 1).astype(np.int32))
    for radius in np.unique(radii[radii > 0]):
        disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1,) * 2)
        hole |= cv2.dilate((radii == radius).astype(np.uint8), disc)
    return hole


def inpaint_background(photo: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """RGB u8 (H,W,3): ``photo`` with every object (``labels`` > 0) and its edge's transition
    (:func:`background_hole`) filled from the rest of it, and the objects' shadows divided out
    (:func:`photographed_shadow`).

    Pixels outside that hole and the objects' shadows are the photograph's, unchanged; the fill is
    the same on every run (fixed seed)."""
    radius = dilation_px(*labels.shape)
    hole = background_hole(photo, labels)
    if not hole.any():
        return photo.copy()
    # the shadow is found around the hole filled by diffusion, and divided out before the exemplar
    # fill, so that no patch copied into the hole carries it
    shadow = photographed_shadow(cv2.inpaint(photo, hole, DIFFUSION_RADIUS_PX, cv2.INPAINT_TELEA), labels)
    photo = without_shadow(photo, shadow)
    rim = cv2.inpaint(photo, hole, DIFFUSION_RADIUS_PX, cv2.INPAINT_TELEA)
    try:
        texture = exemplar_fill(photo, hole > 0, rim)
    except ValueError as error:  # no whole patch of background to copy
        log.warning("background: %s; the objects cover too much of the photograph to copy patches from, "
                    "so their place is filled by diffusion alone", error)
        return np.where(hole[..., None] > 0, rim, photo)
    inside_px = cv2.distanceTransform(hole, cv2.DIST_L2, 5)  # from the nearest known pixel
    diffused = np.clip(1 - (inside_px - 0.5) / (SEAM_WIDTH * radius), 0, 1)[..., None]
    filled = diffused * rim + (1 - diffused) * texture
    return np.where(hole[..., None] > 0, filled + 0.5, photo).astype(np.uint8)
