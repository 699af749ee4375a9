"""Standing solids: a body of revolution about the vertical, or an upright box, where one explains the silhouette.

Things photographed standing are often turned (cups, bottles, tins) or boxed
(cartons, books). Where such a solid's own image overlaps the silhouette by at
least FIT_IOU it is taken for the body: a cylinder keeps its flat top and base
and a box its corners, which the medial balls (closure.ball_depths) round off
(which give an upright cylinder 0.58-0.69 of its volume, a turned box 0.56-0.70).
A body of revolution wider than tall is taken only where its top is a face
whose rim the outline traces: a loaf or a capsule lying across the picture
shows the same outline as a lens turned about the vertical (Revolution.seen_turned,
docs/decisions/0035-lying-or-turned.md).

Every fit is made in the gravity frame of a view turned to face the object
(GravityView: x horizontal across, y down along gravity, z horizontal towards
the silhouette), at an arbitrary scale that closure.object_depths sets from
size_m and the solid's exact largest extent. The silhouette is read through a
Gaussian-blurred signed distance of the mask, to a fraction of a pixel.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import cv2
import numpy as np
from scipy import ndimage

from schemas.camera import project_points

from .upright_box import UprightBox, upright_box

FIT_IOU = 0.95
"""A solid is the body where its image overlaps the silhouette (less a thin handle) by at least this."""
NEAR_PX = 2.0
"""Silhouette pixels within this distance of the solid's image belong to the solid (a rim it grazes)."""
HANDLE_THICKNESS = 0.35
"""A piece of the silhouette outside the solid's image is a handle, with balls of its own, where its
thickness is at most this share of the solid's image's; a thicker piece counts against the overlap."""
STEEPEST_DEG = 60.0
"""Seen from more than this far above, a solid's height and depth are one unknown: no solid is tried."""
SMALLEST_PX = 32
"""A silhouette narrower than this keeps its medial balls: a 24 px ball seen from 40 degrees above came out
0.97 of its volume as a body of revolution, 0.99 in balls."""
BLUR_PX = 1.5
"""Gaussian sigma (pixels) on the signed distance: the staircase of the pixels smoothed to its edge."""
CIRCLE_POINTS = 72
"""Points on each horizontal circle read against the outline."""
SLICES = 240
"""Horizontal slabs of a body of revolution: a quarter of a pixel each on a 60 px body."""
HIDDEN_PX = 0.3
"""The widest circles that fit along a face's rim touch the outline all along it, and the pixels'
staircase leaves them a fifth of a pixel short there: circles beyond the face, which touch it at a point
or two, fill that band. An end may uncover a band this wide along the silhouette's width (seen_ends)."""
END_SEARCH = 0.1
"""The face of a flat end is looked for within this share of the height seen inside the last slab seen
(which may be one of the widest circles that fit beyond the face: up to 8 px of 100)."""
TRACE_PX = 0.75
"""A point of a circle's image within this of the outline traces it..."""
TRACED_SHARE = 0.4
"""... and a circle whose image traces the outline along this share of its points can be a flat face
(an upright cylinder's end: 0.43-0.65 of its points; a ball's circles, which touch it at a point or two
and curve away, 0.31-0.47)..."""
NARROW_SPAN = 0.1
NARROW_SHARE = 0.92
"""... where the body does not narrow towards it: it keeps NARROW_SHARE of the widest radius over the
NARROW_SPAN of the height seen before it (a ball's circles, 0.8 of its radius above its centre, keep 0.76
of it; an upright cylinder's 0.98-1.02)..."""
FACE_RMS_PX = 0.15
"""... and it is a face where the half of its circle that faces the outline lies this close to it (rms,
flat_end): an upright cylinder's 0.05-0.12 px, ray-cast 16-86 px in radius, the pixels' staircase; a
ball's or a capsule's circles, whose images are flatter than its outline, 0.28-1.16 px, 0.011-0.025 of
their radius in pixels..."""
RIM_SHARE = 0.004
"""... widened by this share of the face's radius in pixels (rim_allowance): a photographed rim departs from
the image of a circle by a share of its size (a lens's distortion, a focal length or pitch told a few
degrees off, a cup not quite round), which the pixels' staircase does not tell. The coffee example's rim
(105-115 px) misses by 0.26-0.30 px, 0.0023-0.0028 of its radius, told its photograph's pitch of 60-63
degrees. TRACE_PX is widened alike where a circle is looked for..."""
ROUND_WIDEST = 1.2
ROUND_END = 0.88
"""... or where the end is not round and its circle traces the outline by TRACED_SHARE within TRACE_PX
unwidened: the sphere fitted to the profile before it (dome_end) is wider than ROUND_WIDEST of the body,
or the last slab seen keeps ROUND_END of the widest radius (a ball's, seen from 0-40 degrees above,
0.48-0.78). Seen level, a cylinder's end face is an edge whose circle fits the
outline to 0.17 px rms, and its last slab seen keeps 0.93."""
FACE_PX = 1.5
FACE_SPAN = 0.3
"""A flat face's height and radius are refined together, within FACE_PX of the slab it ends on and 4 % of
the radius a line through the profile over FACE_SPAN of its height gives there."""
WIDEST_SPAN = 0.15
"""The widest radius is the top of a parabola fitted to the profile over this share of its height either
side of its widest slab (the widest single slab is the noisiest: 2-3 % long on an upright cylinder)."""
SUPERSAMPLE = 4
"""Raster cells per pixel side, for which slice covers which part of the image."""
BALL_AGREE = 0.05
"""Where the spheres of both round ends agree within this share of their radius, the body is a ball, and
its extent their mean diameter: the widest circle alone, or the tips' span, was 0.5-1 % long at 192 px."""
AREA_ROUNDS = 2
"""A body of revolution's radii are scaled, this many times, until its image has as many pixels as the
silhouette (less a handle): the widest circles that fit touch the outline at a point or two, where the
pixels' staircase leaves them 0.1-0.2 px long or short; counting the pixels averages over all of them."""
ROUND_FIRST = 0.01
"""A box is taken over a body of revolution only where its image overlaps by this much more: seen level,
an upright cylinder's silhouette is a box's."""


def signed_distance_px(mask: np.ndarray) -> np.ndarray:
    """(H,W) float64: each pixel centre's signed distance in pixels to the outline of `mask` (H,W) bool, positive
    inside. The outline lies midway between the inside and the outside pixel centres on either side of it: the
    distance is exact wherever the nearest point of the outline lies on a straight run of pixel edges, and off by
    at most (sqrt 2 - 1) / 2 px beside a convex corner."""
    signed = ndimage.distance_transform_edt(mask) - ndimage.distance_transform_edt(~mask)
    return np.where(mask, signed - 0.5, signed + 0.5)


@dataclass
class GravityView:
    """A camera turned about the vertical to face the silhouette. R (3,3): rows the gravity frame's axes in the
    camera frame (x across, y down, z horizontal towards the silhouette's centroid); K (3,3) the input's
    intrinsics; mask (H,W) bool; sdf (H,W) px: blurred signed distance to the outline, positive inside."""

    R: np.ndarray
    K: np.ndarray
    mask: np.ndarray
    sdf: np.ndarray

    @staticmethod
    def of(mask: np.ndarray, K: np.ndarray, down: np.ndarray) -> "GravityView":
        """The view of silhouette `mask` (H,W) bool under K (3,3), gravity along `down` (3,) in the camera frame."""
        rows, cols = np.nonzero(mask)
        towards = np.linalg.inv(K) @ np.array([cols.mean() + 0.5, rows.mean() + 0.5, 1.0])
        across = np.cross(down, towards)
        across /= np.linalg.norm(across)
        forward = np.cross(across, down)
        return GravityView(np.stack([across, down, forward]), K, mask,
                           ndimage.gaussian_filter(signed_distance_px(mask), BLUR_PX))

    def elevation_deg(self) -> float:
        """How far above the horizontal the camera sees the silhouette's centroid, degrees."""
        rows, cols = np.nonzero(self.mask)
        ray = np.linalg.inv(self.K) @ np.array([cols.mean() + 0.5, rows.mean() + 0.5, 1.0])
        return math.degrees(math.asin(float(ray @ self.R[1]) / float(np.linalg.norm(ray))))

    def project(self, points: np.ndarray) -> np.ndarray:
        """Image coordinates (...,2) (u, v; pixel centres at +0.5) of points (...,3) in the gravity frame."""
        return project_points(points @ self.R, self.K)

    def sdf_at(self, points: np.ndarray) -> np.ndarray:
        """Blurred signed distance (...) px of the images of points (...,3), bilinear; behind the camera -inf."""
        uv = self.project(points)
        values = ndimage.map_coordinates(self.sdf, [uv[..., 1].ravel() - 0.5, uv[..., 0].ravel() - 0.5],
                                         order=1, mode="nearest").reshape(uv.shape[:-1])
        return np.where(points @ self.R[:, 2] > 0, values, -np.inf)

    def rays(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """(N,3) gravity-frame rays through pixel centres, scaled to camera z = 1 (so t is the camera z)."""
        rays = np.stack([cols + 0.5, rows + 0.5, np.ones(len(rows))], axis=1) @ np.linalg.inv(self.K).T
        return rays @ self.R.T


def circles(centres: np.ndarray, radii: np.ndarray, count: int = CIRCLE_POINTS) -> np.ndarray:
    """Points (S,count,3) on horizontal circles about centres (S,3) of radii (S,)."""
    angle = 2 * math.pi * np.arange(count) / count
    ring = np.stack([np.cos(angle), np.zeros(count), np.sin(angle)], axis=1)
    return centres[:, None, :] + radii[:, None, None] * ring


@dataclass
class Revolution:
    """A body of revolution about the vertical line x = axis_x, z = 1 of the gravity frame: slabs between
    heights edges (S+1,) (y, downwards) of radii (S,); ball its diameter if it is a ball; top_face whether its
    top is a flat face whose rim the outline traces (flat_end), not a dome."""

    axis_x: float
    edges: np.ndarray
    radii: np.ndarray
    ball: Optional[float] = None
    top_face: bool = False
    kind = "body of revolution"

    def seen_turned(self) -> bool:
        """Whether the picture tells it from a body lying across the view: a ball, a body no wider than tall
        (whose depth, its width, a mirror closure gives it too), or one whose top is a face (a rim traced along
        the outline, as a cup's, a tin's, a cake's seen from above). A body wider than tall with a domed top
        is what a loaf or a capsule lying across the picture shows, every horizontal slice a circle."""
        return (self.ball is not None or self.top_face
                or 2 * float(self.radii.max()) <= float(self.edges[-1] - self.edges[0]))

    @property
    def extent(self) -> float:
        """Largest extent: a ball's diameter (both ends' spheres), else the larger of its widest diameter
        (WIDEST_SPAN) and the height of its slabs that hold anything."""
        if self.ball is not None:
            return self.ball
        heights = 0.5 * (self.edges[:-1] + self.edges[1:])
        held = np.flatnonzero(self.radii > 0)
        tall = float(self.edges[held[-1] + 1] - self.edges[held[0]])
        widest = int(np.argmax(ndimage.uniform_filter1d(self.radii, 9)))
        near = np.abs(heights - heights[widest]) <= WIDEST_SPAN * tall
        fit = np.polyfit(heights[near], self.radii[near], 2)
        top = -fit[1] / (2 * fit[0]) if fit[0] < 0 else heights[widest]
        radius = float(np.polyval(fit, np.clip(top, heights[near].min(), heights[near].max())))
        return max(2 * radius, tall)

    def intersect(self, rays: np.ndarray, chunk: int = 2048) -> tuple[np.ndarray, np.ndarray]:
        """(t_in, t_out) (N,) where rays t * rays (N,3) enter and leave it; NaN where they miss."""
        t_in, t_out = np.full(len(rays), np.nan), np.full(len(rays), np.nan)
        for start in range(0, len(rays), chunk):
            d = rays[start:start + chunk]
            a = (d[:, 0] ** 2 + d[:, 2] ** 2)[:, None]
            b = (-2 * (d[:, 0] * self.axis_x + d[:, 2]))[:, None]
            disc = b * b - 4 * a * (self.axis_x ** 2 + 1 - self.radii ** 2)[None, :]
            root = np.sqrt(np.maximum(disc, 0.0))
            near, far = (-b - root) / (2 * a), (-b + root) / (2 * a)
            with np.errstate(divide="ignore", invalid="ignore"):
                low, high = self.edges[None, :-1] / d[:, 1:2], self.edges[None, 1:] / d[:, 1:2]
            level = d[:, 1:2] == 0
            y_in = np.where(level, -np.inf, np.minimum(low, high))
            y_out = np.where(level, np.inf, np.maximum(low, high))
            enter, leave = np.maximum(near, y_in), np.minimum(far, y_out)
            hit = (disc > 0) & (enter < leave)
            entry, exit_ = np.where(hit, enter, np.inf).min(1), np.where(hit, leave, -np.inf).max(1)
            met = np.isfinite(entry)
            t_in[start:start + chunk] = np.where(met, entry, np.nan)
            t_out[start:start + chunk] = np.where(met, exit_, np.nan)
        return t_in, t_out

    def base_height(self) -> float:
        """The height (y, downwards) of its lowest slab's bottom."""
        return float(self.edges[-1])


def widest_radii(view: GravityView, axis_x: float, heights: np.ndarray, iterations: int = 22) -> np.ndarray:
    """For each height (S,) the radius of the widest horizontal circle about the axis whose image lies inside
    the silhouette (bisection; 0 where its centre's image lies outside)."""
    centres = np.stack([np.full(len(heights), axis_x), heights, np.ones(len(heights))], axis=1)
    rows, cols = np.nonzero(view.mask)
    low, high = np.zeros(len(heights)), np.full(len(heights), (np.ptp(cols) + 2) / view.K[0, 0])
    for _ in range(iterations):
        middle = 0.5 * (low + high)
        fits = view.sdf_at(circles(centres, middle)).min(1) >= 0
        low, high = np.where(fits, middle, low), np.where(fits, high, middle)
    return np.where(view.sdf_at(centres) >= 0, low, 0.0)


def axis_span(view: GravityView, axis_x: float) -> Optional[tuple[float, float]]:
    """The heights (top, bottom) between which the axis's image lies inside the silhouette (its longest run,
    ends by bisection), None if nowhere."""
    rows, _ = np.nonzero(view.mask)
    focal = view.K[1, 1]
    # the silhouette's rows as heights on the plane z = 1, with a margin
    rays = view.rays(np.array([rows.min() - 2, rows.max() + 2]), np.full(2, view.K[0, 2]))
    y0, y1 = sorted(rays[:, 1] / rays[:, 2])
    margin = 0.5 * (y1 - y0)
    heights = np.arange(y0 - margin, y1 + margin, 0.25 / focal)
    inside = view.sdf_at(np.stack([np.full(len(heights), axis_x), heights, np.ones(len(heights))], 1)) > 0
    if not inside.any():
        return None
    edges = np.flatnonzero(np.diff(np.concatenate([[0], inside.astype(int), [0]])))
    starts, ends = edges[::2], edges[1::2]
    k = int(np.argmax(ends - starts))
    first, last = starts[k], ends[k] - 1

    def crossing(inner: float, outer: float) -> float:
        for _ in range(30):
            middle = 0.5 * (inner + outer)
            point = np.array([[axis_x, middle, 1.0]])
            inner, outer = (middle, outer) if view.sdf_at(point)[0] > 0 else (inner, middle)
        return 0.5 * (inner + outer)

    return (crossing(heights[first], heights[max(first - 1, 0)]),
            crossing(heights[last], heights[min(last + 1, len(heights) - 1)]))


def covering_slices(view: GravityView, axis_x: float, edges: np.ndarray, radii: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """For each raster cell (SUPERSAMPLE per pixel) covered by the images of the slabs (heights edges (S+1,),
    radii (S,) about the axis), the highest-index and the lowest-index slab covering it: (kmax, kmin) (N,)."""
    height, width = view.mask.shape
    last = np.full((height * SUPERSAMPLE, width * SUPERSAMPLE), -1, np.int32)
    first = last.copy()
    polygons = []
    for k in range(len(radii)):
        ends = np.array([[axis_x, edges[k], 1.0], [axis_x, edges[k + 1], 1.0]])
        points = view.project(circles(ends, np.full(2, radii[k]))).reshape(-1, 2)
        polygons.append(cv2.convexHull(np.round(points * SUPERSAMPLE * 16).astype(np.int32)) if radii[k] > 0 else None)
    for order, image in ((range(len(radii)), last), (reversed(range(len(radii))), first)):
        for k in order:
            if polygons[k] is not None:
                cv2.fillConvexPoly(image, polygons[k], int(k), shift=4)
    covered = last >= 0
    return last[covered], first[covered]


def rim_allowance(view: GravityView, radius: float) -> float:
    """How many times the pixel-level tolerances (TRACE_PX, FACE_RMS_PX) a face of `radius` (gravity frame,
    at z = 1) is allowed: the staircase's FACE_RMS_PX and RIM_SHARE of its radius in pixels, added in
    quadrature, over FACE_RMS_PX (1 for a small face; 3 for a rim 110 px in radius)."""
    return math.hypot(1.0, RIM_SHARE * radius * view.K[0, 0] / FACE_RMS_PX)


def traced_share(view: GravityView, centre: np.ndarray, radius: float, widened: bool = True) -> float:
    """The share of the image of the horizontal circle (centre (3,), radius) within TRACE_PX of the outline,
    widened by its rim_allowance unless `widened` is False."""
    sdf = view.sdf_at(circles(centre[None], np.array([radius])))[0]
    return float(np.mean(np.abs(sdf) < TRACE_PX * (rim_allowance(view, radius) if widened else 1.0)))


def revolution(view: GravityView) -> Optional[Revolution]:
    """The body of revolution about the vertical that the silhouette shows: at each height the widest circle
    whose image fits inside it, about the axis offset whose circles hold the most; None if the axis meets
    the silhouette nowhere.

    Seen from above (or below), circles beyond an end fit inside the images of the others (seen_ends): the
    widest that fit there are no evidence. Where the last circle seen traces the outline (a rim) and the
    body does not narrow towards it, the end is flat there (flat_end); else it is a dome continuing the
    slices before it (dome_end). Where both ends' domes agree the body is a ball; otherwise its lower end
    stands on the ground or on what hides it (a saucer's rim, the picture's edge), and is cut flat at the
    last slab seen."""
    focal = view.K[0, 0]
    _, cols = np.nonzero(view.mask)
    half_width = 0.5 * np.ptp(cols) / focal

    def profile(axis_x: float, slices: int = SLICES // 3) -> tuple[np.ndarray, np.ndarray]:
        span = axis_span(view, axis_x)
        if span is None:
            return np.zeros(1), np.zeros(1)
        edges = np.linspace(span[0], span[1], slices + 1)
        return edges, widest_radii(view, axis_x, 0.5 * (edges[:-1] + edges[1:]))

    def held(axis_x: float) -> float:
        edges, radii = profile(axis_x)
        return float(np.sum(radii ** 2 * np.diff(edges)))

    offsets = np.linspace(-0.25, 0.25, 11) * half_width
    best = offsets[int(np.argmax([held(x) for x in offsets]))]
    step = offsets[1] - offsets[0]
    fine = best + np.linspace(-step, step, 9)
    axis_x = float(fine[int(np.argmax([held(x) for x in fine]))])
    edges, radii = profile(axis_x, SLICES)
    if radii.max() <= 0:
        return None
    top, bottom = seen_ends(view, axis_x, edges, radii)
    heights = 0.5 * (edges[:-1] + edges[1:])
    rows, _ = np.nonzero(view.mask)
    pixel = abs(edges[-1] - edges[0]) / max(np.ptp(rows), 1)  # about a pixel of height
    span = int(math.ceil(NARROW_SPAN * (bottom - top)))
    ends = []
    for end, outward in ((top, -1), (bottom, 1)):
        # the face, if any: near the end seen, a circle that traces the outline where the body does not narrow
        inward = outward * (heights[end] - heights)
        near = np.flatnonzero((inward >= -pixel) & (inward <= END_SEARCH * (heights[bottom] - heights[top]))
                              & (radii > 0))
        widest_before = np.array([radii[k - outward * np.arange(span + 1)].max() if 0 <= k - outward * span < len(radii)
                                  else np.inf for k in near])
        near = near[radii[near] >= NARROW_SHARE * widest_before]
        shares = [traced_share(view, np.array([axis_x, heights[k], 1.0]), radii[k]) for k in near]
        face = None
        if shares and max(shares) >= TRACED_SHARE:
            rim = int(near[int(np.argmax(shares))])
            face, misfit = flat_end(view, axis_x, edges, radii, rim, outward, pixel)
            fits = misfit <= FACE_RMS_PX * rim_allowance(view, radii[rim])
            # an end that is not round is a face where its circle traces the outline unwidened
            traced = max(traced_share(view, np.array([axis_x, heights[k], 1.0]), radii[k], False) for k in near)
        dome = dome_end(edges, radii, end, outward, pixel)
        round_end = dome[1][2] <= ROUND_WIDEST * radii.max() and radii[end] <= ROUND_END * radii.max()
        takes_face = face is not None and (fits or not round_end and traced >= TRACED_SHARE)
        ends.append((face, None) if takes_face else dome)
    (top_y, top_dome), (bottom_y, bottom_dome) = ends
    ball = None
    if top_dome is not None and bottom_dome is not None:  # one sphere, if both ends' agree: a ball
        (_, top_centre, top_rho), (_, bottom_centre, bottom_rho) = top_dome, bottom_dome
        if abs(top_centre - bottom_centre) <= BALL_AGREE * top_rho and abs(top_rho - bottom_rho) <= BALL_AGREE * top_rho:
            ball = top_rho + bottom_rho
    if ball is None and bottom_dome is not None:  # it stands on what hides its lower end: a cut, not a dome
        bottom_y, bottom_dome = float(edges[bottom + 1]), None
    edges = np.linspace(top_y, bottom_y, SLICES + 1)
    heights = 0.5 * (edges[:-1] + edges[1:])
    radii = widest_radii(view, axis_x, heights)
    for dome in (top_dome, bottom_dome):
        if dome is not None:
            (start, stop), centre, rho = dome
            beyond = (heights > min(start, stop)) & (heights < max(start, stop))
            radii[beyond] = np.minimum(radii[beyond], np.sqrt(np.maximum(rho ** 2 - (heights[beyond] - centre) ** 2, 0)))
    return Revolution(axis_x, edges, radii, ball, top_dome is None)


def seen_ends(view: GravityView, axis_x: float, edges: np.ndarray, radii: np.ndarray) -> tuple[int, int]:
    """The first and last slab (indices) whose images are not hidden inside the others': seen from above (or
    below), circles beyond an end face fit inside its image. An end may uncover a band HIDDEN_PX wide along
    the silhouette's width."""
    kmax, kmin = covering_slices(view, axis_x, edges, radii)
    _, cols = np.nonzero(view.mask)
    spare = int(HIDDEN_PX * np.ptp(cols) * SUPERSAMPLE ** 2)
    top = int(np.sort(kmax)[min(spare, len(kmax) - 1)])
    bottom = int(np.sort(kmin)[max(len(kmin) - 1 - spare, 0)])
    return top, bottom


def flat_end(view: GravityView, axis_x: float, edges: np.ndarray, radii: np.ndarray, end: int, outward: int,
             pixel: float) -> tuple[float, float]:
    """A flat end near slab `end` (outward -1 up, +1 down): past it as long as the body does not narrow (by a
    quarter of a pixel), then to the height where the half of the face's circle that faces the outline lies
    on it best (FACE_PX; least squares of the signed distance, the radius fitted with it: one slab's
    radius is a fifth of a pixel off, and the face's height with it). Returns the face's height and the rms
    distance (px) of that half circle's image from the outline."""
    focal = view.K[0, 0]
    k = end
    while 0 <= k + outward < len(radii) and radii[k + outward] >= radii[end] - 0.25 / focal:
        k += outward
    face = float(edges[k + (outward > 0)])
    heights = face + np.linspace(-FACE_PX, FACE_PX, 61) * pixel
    # the radius near the face: a line through the profile over FACE_SPAN of the height before it
    middle = 0.5 * (edges[:-1] + edges[1:])
    before = (outward * (face - middle) >= 0) & (outward * (face - middle) <= FACE_SPAN * abs(edges[-1] - edges[0]))
    radius = float(np.polyval(np.polyfit(middle[before], radii[before], 1), face))
    sizes = radius * (1 + np.linspace(-0.04, 0.04, 17))
    centres = np.stack([np.full(len(heights), axis_x), heights, np.ones(len(heights))], axis=1)
    points = circles(np.repeat(centres, len(sizes), axis=0), np.tile(sizes, len(heights)))
    v = view.project(points)[..., 1] - view.project(np.repeat(centres, len(sizes), axis=0))[:, None, 1]
    facing = outward * v > 0  # the half beyond the centre's image, towards the end
    misfit = np.sum(np.where(facing, view.sdf_at(points), 0.0) ** 2, axis=1) / np.maximum(facing.sum(1), 1)
    best = int(np.argmin(misfit))
    return float(heights[best // len(sizes)]), math.sqrt(float(misfit[best]))


def dome_end(edges: np.ndarray, radii: np.ndarray, end: int, outward: int, pixel: float):
    """A round end: the sphere about the axis fitted (least squares, r^2 + (y - c)^2 = rho^2) to the profile
    over the quarter of its height before the last slab seen, then again to every slab within a pixel of
    it (a ball's whole profile), continued beyond the end. Returns the tip's height and ((from, to)
    heights, centre height, rho) of the dome; a hemisphere of the last radius where the profile widens
    towards its end."""
    heights = 0.5 * (edges[:-1] + edges[1:])
    tall = abs(edges[-1] - edges[0])
    near = (np.abs(heights - heights[end]) <= 0.25 * tall) & (np.sign(heights - heights[end]) != outward) \
        & (radii > 0)
    centre, rho = heights[end], radii[end]
    for _ in range(3):
        y, r = heights[near], radii[near]
        if len(y) < 5:
            break
        (c2, const), *_ = np.linalg.lstsq(np.stack([2 * y, np.ones(len(y))], 1), r ** 2 + y ** 2, rcond=None)
        if not (const + c2 ** 2 > radii[end] ** 2 and (c2 - heights[end]) * outward <= 0):
            break
        centre, rho = float(c2), float(math.sqrt(const + c2 ** 2))
        near = (np.abs(np.hypot(radii, heights - centre) - rho) <= pixel) & (np.abs(heights - centre) < rho) \
            & (radii > 0) & (outward * (heights - heights[end]) <= 0)
    tip = centre + outward * rho
    return tip, ((heights[end], tip), centre, rho)


@dataclass
class StandingSolid:
    """The solid taken for a body, at the scale of its fit: its depths along each silhouette pixel's ray
    (camera z, NaN where it misses), its image (H,W) bool and the share of the silhouette it explains."""

    solid: Revolution | UprightBox
    t_in: np.ndarray
    t_out: np.ndarray
    on_base: np.ndarray
    image: np.ndarray
    overlap: float


def image_of(view: GravityView, solid: Revolution | UprightBox) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(image (H,W) bool, t_in, t_out (H,W), NaN off it): the pixels whose centre's ray meets the solid, near
    the silhouette."""
    height, width = view.mask.shape
    rows, cols = np.nonzero(ndimage.binary_dilation(view.mask, iterations=6))
    t_in, t_out = solid.intersect(view.rays(rows, cols))
    front, back = np.full((height, width), np.nan), np.full((height, width), np.nan)
    front[rows, cols], back[rows, cols] = t_in, t_out
    return np.isfinite(front), front, back


def overlap(view: GravityView, image: np.ndarray) -> tuple[float, np.ndarray]:
    """IoU of the solid's image (H,W) bool with the silhouette less its handles, and that part of the
    silhouette (H,W) bool. A piece of the silhouette outside the image is a handle where it is thin
    (HANDLE_THICKNESS) and has no twin across the image's middle (mirrored_pieces): a handle stands out on
    one side, where a solid of the wrong shape (a turned body for a loaf lying across the picture) misses
    the outline on both."""
    mask = view.mask
    rest = mask & (ndimage.distance_transform_edt(~image) > NEAR_PX)
    pieces, count = ndimage.label(rest)
    own = float(ndimage.distance_transform_edt(image).max())
    twinned = mirrored_pieces(image, pieces)
    handles = np.zeros_like(mask)
    for k, piece in enumerate(ndimage.find_objects(pieces), start=1):
        if k in twinned:
            continue
        part = pieces[piece] == k
        thickness = ndimage.distance_transform_edt(np.pad(part, 1))[1:-1, 1:-1].max()
        if thickness <= HANDLE_THICKNESS * own:
            handles[piece] |= part
    target = mask & ~handles
    return float(np.sum(image & target) / max(np.sum(image | target), 1)), target


def mirrored_pieces(image: np.ndarray, pieces: np.ndarray) -> set[int]:
    """The labels of the pieces (H,W) int (0: none) whose mirror image across the middle of the solid's
    image (H,W) bool, row by row (above or below the image, its first or last row's), comes within NEAR_PX
    of a piece (itself included)."""
    rows, cols = np.nonzero(image)
    if len(rows) == 0:
        return set()
    held = np.unique(rows)
    middle = np.array([0.5 * (cols[rows == r].min() + cols[rows == r].max()) for r in held])
    height, width = image.shape
    axis = np.interp(np.arange(height), held, middle)  # beyond the image: its first or last row's
    near = ndimage.grey_dilation(pieces, size=(2 * int(NEAR_PX) + 1,) * 2)
    r, c = np.nonzero(pieces)
    mirrored = np.round(2 * axis[r] - c).astype(int)
    inside = (mirrored >= 0) & (mirrored < width)
    meets = np.zeros(len(r), bool)
    meets[inside] = near[r[inside], mirrored[inside]] > 0
    return set(np.unique(pieces[r[meets], c[meets]]).tolist())


def standing_solid(mask: np.ndarray, K: np.ndarray, down: np.ndarray) -> Optional[StandingSolid]:
    """The standing solid (a body of revolution or an upright box) whose image best overlaps the silhouette
    `mask` (H,W) bool under K (3,3), gravity along `down` (3,) (camera frame), where it reaches FIT_IOU;
    None otherwise, when seen from more than STEEPEST_DEG above, and for a silhouette under SMALLEST_PX
    across."""
    rows, cols = np.nonzero(mask)
    if min(np.ptp(rows), np.ptp(cols)) + 1 < SMALLEST_PX:
        return None
    view = GravityView.of(mask, K, down)
    if view.elevation_deg() > STEEPEST_DEG:
        return None
    found = None
    for fit in (revolution, upright_box):
        solid = fit(view)
        if solid is None or isinstance(solid, Revolution) and not solid.seen_turned():
            continue
        image, front, back = image_of(view, solid)
        share, target = overlap(view, image)
        if isinstance(solid, Revolution):
            for _ in range(AREA_ROUNDS):  # its pixels as many as the silhouette's, less a handle
                area = math.sqrt(target.sum() / image.sum())
                solid = Revolution(solid.axis_x, solid.edges, solid.radii * area, solid.ball and solid.ball * area,
                                   solid.top_face)
                image, front, back = image_of(view, solid)
                share, target = overlap(view, image)
        if share >= FIT_IOU and (found is None or share > found.overlap + ROUND_FIRST):
            rays = view.rays(*np.nonzero(mask))
            base = solid.base_height()
            t_in, t_out = front[mask], back[mask]
            on_base = np.abs(t_in * rays[:, 1] - base) < 1e-7 * max(abs(base), 1.0)
            found = StandingSolid(solid, t_in, t_out, on_base, image, share)
    return found
