"""The unseen half: each object's body from its silhouette, upright in the gravity frame.

The photograph gives a silhouette and, where the object is seen, its colours;
what lies behind is a prior (docs/decisions/0001-back-closure.md, 0019). Where
a standing solid, a body of revolution about the vertical or an upright box,
explains the silhouette (standing.standing_solid), it is the body, a handle
keeping its own balls (solid_depths). Otherwise the body
is swept by the balls of the silhouette's medial axis (depth.medial_balls):
each pixel lies on the ball of its nearest axis point, as wide as the
silhouette there. The axis is read in a view that faces the object (a ball
is round there; off the optical axis the picture stretches it), and the balls'
centres lie on the vertical plane across that view: the body is
mirror-symmetric about that plane, so its back continues its front, a ball
becomes a ball and a capsule a capsule, and the lowest point of a round body
lies under its centre of mass whatever the camera's pitch. Each pixel's ray
enters and leaves the union of the balls: there lie the body's front, which
keeps the photograph's pixels, and its back. A body that would rest off its
centre of mass is cut flat where its base holds it (standing_cut).
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Optional, Sequence

import cv2
import numpy as np
from scipy import ndimage
from scipy.spatial import ConvexHull, QhullError

from schemas.camera import pixel_rays

from .body import Balls, Body, Prism, Standing
from .depth import ObjectDepth, aligned_front, medial_balls
from .standing import NEAR_PX, GravityView, StandingSolid, standing_solid

log = logging.getLogger("physmotion.reconstruct")

AXIS_SPACING_PX = 2.5
AXIS_SPACING_SHARE = 0.2
"""Medial axis points nearer than AXIS_SPACING_PX, or this share of its radius, to one with a larger ball
are dropped (sparse_axis): balls 0.2 r apart leave a surface 0.005 r from their envelope."""
MAX_CUT = 0.2
"""A body is cut flat by at most this share of its height to stand on its base (a cup seen 28 degrees
shallower than its photograph stands on the tip of its handle and needs 18 %)..."""
MAX_CUT_VOLUME = 0.03
"""... and at most this share of its volume (that cup loses 2.6 %; a capsule leaning 20 degrees would
lose 7 %, and is left to fall)."""
STAND_MARGIN = 0.02
"""A base holds the centre of mass at least this share of size_m inside its edge."""
STAND_TILT_DEG = 10.0
"""A body cut to stand gets a base that holds it tilted this far, where the caps allow: on the narrowest
base that held it at all the coffee cup, pushed at its rim by 0.15 N for 0.25 s, fell over."""
BASE_LAYER = 0.005
"""The base: the body within this share of size_m of the cut, or a pixel's footprint and a half."""
SAMPLES_PER_RAY = 8
"""Points along each pixel's ray through the body, for its centre of mass."""
STEEPEST_VERTICAL_PLANE = math.cos(math.radians(75.0))
"""Seen from more than 75 degrees above, the balls' centres lie on the plane across the view instead of a
vertical one (which the view would see edge on)."""


def down_direction(pitch_deg: float) -> np.ndarray:
    """Gravity's unit direction (3,) in the frame of a camera pitched down by pitch_deg."""
    p = math.radians(pitch_deg)
    return np.array([0.0, math.cos(p), math.sin(p)])


def across_view(view: np.ndarray, down: np.ndarray) -> tuple[np.ndarray, bool]:
    """The normal (3,) of the plane across the unit direction `view` (3,), not normalised, and whether that
    plane is vertical: the view made horizontal (gravity along `down` (3,)), or, seen from above (the
    horizontal part shorter than STEEPEST_VERTICAL_PLANE), the view itself."""
    normal = view - (view @ down) * down
    if np.linalg.norm(normal) < STEEPEST_VERTICAL_PLANE:
        return view, False
    return normal, True


@dataclass
class FacingView:
    """The silhouette as a camera at the input camera's centre, turned to face the object, sees it: its
    optical axis the ray through the silhouette's centroid, its x axis horizontal.

    mask: (h,w) bool in the facing image; K: (3,3) its intrinsics (the input's focal length, the principal
    point where the whole silhouette fits); R: (3,3) camera -> facing frame; to_facing: (3,3) homography
    from input pixels to facing pixels (pixel centres at +0.5).
    """

    mask: np.ndarray
    K: np.ndarray
    R: np.ndarray
    to_facing: np.ndarray

    @staticmethod
    def of(mask: np.ndarray, K: np.ndarray, down: np.ndarray, margin_px: int = 4) -> "FacingView":
        """The input silhouette (H,W) bool under intrinsics K (3,3), gravity along `down` (3,) (camera frame)."""
        axis = input_rays(mask, K).mean(0)
        axis /= np.linalg.norm(axis)
        across = np.cross(down, axis)  # horizontal, the picture's right
        across /= np.linalg.norm(across)
        R = np.stack([across, np.cross(axis, across), axis])
        homography = K @ R @ np.linalg.inv(K)
        rows, cols = np.nonzero(mask)
        corners = np.array([[c, r, 1.0] for r in (rows.min(), rows.max() + 1) for c in (cols.min(), cols.max() + 1)])
        mapped = corners @ homography.T
        mapped = mapped[:, :2] / mapped[:, 2:]
        low = np.floor(mapped.min(0)) - margin_px
        size = (np.ceil(mapped.max(0)) + margin_px - low).astype(int)
        shift = np.array([[1.0, 0.0, -low[0]], [0.0, 1.0, -low[1]], [0.0, 0.0, 1.0]])
        to_facing = shift @ homography
        centre = np.array([[1.0, 0.0, 0.5], [0.0, 1.0, 0.5], [0.0, 0.0, 1.0]])  # OpenCV's pixel centres are at 0
        warped = cv2.warpPerspective(mask.astype(np.float32), np.linalg.inv(centre) @ to_facing @ centre,
                                     (int(size[0]), int(size[1])), flags=cv2.INTER_LINEAR)
        return FacingView(warped >= 0.5, shift @ K, R, to_facing)

    def pixels_of(self, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(rows, cols) in the facing image of each input pixel of `mask` (N,), the nearest pixel of the
        facing silhouette (a pixel at the outline may land just outside it)."""
        rows, cols = np.nonzero(mask)
        points = np.stack([cols + 0.5, rows + 0.5, np.ones(len(rows))], axis=1) @ self.to_facing.T
        fc = np.clip(np.floor(points[:, 0] / points[:, 2]).astype(int), 0, self.mask.shape[1] - 1)
        fr = np.clip(np.floor(points[:, 1] / points[:, 2]).astype(int), 0, self.mask.shape[0] - 1)
        _, (near_r, near_c) = ndimage.distance_transform_edt(~self.mask, return_indices=True)
        return near_r[fr, fc], near_c[fr, fc]

    def rays(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """(N,3) unit camera-frame rays through facing pixel centres."""
        rays = np.stack([cols + 0.5, rows + 0.5, np.ones(len(rows))], axis=1) @ np.linalg.inv(self.K).T @ self.R
        return rays / np.linalg.norm(rays, axis=1, keepdims=True)


def input_rays(mask: np.ndarray, K: np.ndarray) -> np.ndarray:
    """(N,3) camera-frame rays, z = 1, through the centres of the pixels of `mask` (row-major order)."""
    rays = pixel_rays(K, *mask.shape)[mask]
    return rays / rays[:, 2:3]


def ray_ball(rays: np.ndarray, centres: np.ndarray, radii: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where rays t * rays (N,3) from the origin enter and leave balls (centres (N,3), radii (N,)): (t_in,
    t_out) (N,); a ray that misses its ball (by perspective, at the outline) grazes it at its closest
    approach, t_in = t_out."""
    a = np.sum(rays * rays, axis=1)
    b = np.sum(rays * centres, axis=1)
    c = np.sum(centres * centres, axis=1) - radii ** 2
    root = np.sqrt(np.maximum(b * b - a * c, 0.0))
    return (b - root) / a, (b + root) / a


def sparse_axis(mask: np.ndarray, radius: np.ndarray, axis: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The medial balls (depth.medial_balls: radius (H,W) px, axis (2,H,W)) with each axis point kept only
    where no kept point with a larger ball lies within AXIS_SPACING_PX or AXIS_SPACING_SHARE of that
    ball's radius, and each pixel of `mask` (H,W) bool on the ball of its nearest kept point: (radius,
    axis rows, axis cols) (H,W). A digitised disc's axis is a cluster of a few pixels about its centre,
    whose discs, scaled to cover it, are each a pixel short (a ball 9.5 degrees off the optical axis lost
    5 % of its volume so); and every ray meets every ball (ray_union), so their number sets the time."""
    points, first = np.unique(axis[:, mask].T, axis=0, return_index=True)
    radii = radius[mask][first]
    order = np.argsort(-radii, kind="stable")
    kept = np.zeros(len(points), bool)
    reach = np.maximum(AXIS_SPACING_PX, AXIS_SPACING_SHARE * radii)
    for i in order:  # largest first: a point is kept unless a kept larger one lies near it
        near = kept & (np.hypot(*(points - points[i]).T) <= reach)
        kept[i] = not near.any()
    centres = np.zeros(mask.shape, bool)
    centres[points[kept, 0], points[kept, 1]] = True
    _, (rows, cols) = ndimage.distance_transform_edt(~centres, return_indices=True)
    ball_radius = np.zeros(mask.shape)
    ball_radius[points[kept, 0], points[kept, 1]] = radii[kept]
    return np.where(mask, ball_radius[rows, cols], 0.0), rows, cols


def disc_cover_scale(mask: np.ndarray, axis_r: np.ndarray, axis_c: np.ndarray, radius: np.ndarray,
                     rounds: int = 3) -> float:
    """The factor on the medial radii (H,W) px whose discs, about their axis points (axis_r, axis_c (H,W)),
    cover as many pixels as the silhouette `mask` (H,W) bool: the medial radius runs a few tenths of a pixel
    long, 4-10 % of a body's volume at 20-60 px across. A silhouette under about 30 px across has a
    cluster of axis points where a larger one has one, and their discs cover it at radii 5 % short: a
    ball 20 px across comes out 12 % light."""
    centres, at = np.unique(np.stack([axis_r[mask], axis_c[mask]], axis=1), axis=0, return_index=True)
    radii = radius[mask][at]
    centres, radii = centres[radii > 0], radii[radii > 0]  # a disc of radius 0 covers nothing (and divides by it)
    rows, cols = np.nonzero(ndimage.binary_dilation(mask, iterations=3))
    # each pixel's depth inside its deepest disc, over its radius
    reach = np.full(len(rows), -np.inf)
    for (r, c), rho in zip(centres, radii):
        reach = np.maximum(reach, 1.0 - np.hypot(rows - r, cols - c) / rho)
    factor = 1.0
    for _ in range(rounds):  # covered where factor * rho exceeds the distance
        covered = int(np.count_nonzero(reach > 1.0 - factor))
        factor *= math.sqrt(mask.sum() / max(covered, 1))
    return factor


def union_extent(centres: np.ndarray, radii: np.ndarray, focal: float) -> float:
    """Largest extent at unit distance of the balls whose discs in a view (centres (N,2) px, radii (N,) px,
    focal length px) are given: along the principal axis of the centres where the union reaches farthest,
    the span between the two outermost discs' centres across the picture (l / f) and each end ball's own
    radius, r / sqrt(f^2 + r^2) (its tangent cone)."""
    centred = centres - centres.mean(0)
    _, axes = np.linalg.eigh(centred.T @ centred)
    along = centred @ axes
    reach = (along + radii[:, None]).max(0) - (along - radii[:, None]).min(0)
    k = int(np.argmax(reach))
    far, near = int(np.argmax(along[:, k] + radii)), int(np.argmin(along[:, k] - radii))
    ends = radii[[far, near]]
    return float((along[far, k] - along[near, k]) / focal + np.sum(ends / np.hypot(focal, ends)))


def ray_union(rays: np.ndarray, centres: np.ndarray, radii: np.ndarray, own: np.ndarray,
              chunk: int = 4096) -> tuple[np.ndarray, np.ndarray]:
    """Where rays t * rays (N,3) enter and leave the union of balls (centres (M,3), radii (M,)): the first
    entry and the last exit among the balls each meets (t_in, t_out) (N,); a ray that meets none grazes
    its own ball own (N,) int at its closest approach."""
    t_in, t_out = ray_ball(rays, centres[own], radii[own])
    for start in range(0, len(rays), chunk):
        part = slice(start, start + chunk)
        r = rays[part]
        a = np.sum(r * r, axis=1)[:, None]
        b = r @ centres.T
        disc = b * b - a * (np.sum(centres * centres, axis=1) - radii ** 2)[None, :]
        hit = disc > 0
        root = np.sqrt(np.where(hit, disc, 0.0))
        entry = np.where(hit, (b - root) / a, np.inf).min(axis=1)
        leave = np.where(hit, (b + root) / a, -np.inf).max(axis=1)
        met = np.isfinite(entry)
        t_in[part] = np.where(met, entry, t_in[part])
        t_out[part] = np.where(met, leave, t_out[part])
    return t_in, t_out


def ball_depths(mask: np.ndarray, K: np.ndarray, down: np.ndarray, size_m: float,
                through: Optional[np.ndarray] = None) -> tuple[np.ndarray, np.ndarray, Balls]:
    """Front and back camera z (N,) m along the rays of the pixels of `mask` (H,W) bool (row-major), of the
    body swept by the medial balls of the silhouette as seen facing the object (gravity along `down` (3,)
    in the camera frame), their centres on the vertical plane across the view at the distance that makes
    the body's largest extent (its balls' along their axis) size_m, or through the camera-frame point
    `through` (3,) m (a handle, where it meets its standing solid).

    A ball whose centre lies at distance D subtends R_px of the facing view when its radius is
    D R_px / sqrt(f^2 + R_px^2): its silhouette is the cone of rays tangent to it, so every ray of the
    silhouette meets the body (a radius of D R_px / f misses the outer rays by the perspective: a
    0.2 m ball 0.47 m away loses 9 % of its volume). Facing the object, a ball's silhouette is a circle
    (off the optical axis the picture stretches it into an ellipse, whose medial axis is a segment). Each
    ray's front and back are where it enters and leaves the union of the balls, which is returned too."""
    view = FacingView.of(mask, K, down)
    radius, _, axis = medial_balls(view.mask)
    radius, axis_r, axis_c = sparse_axis(view.mask, radius, axis)
    radius = radius * disc_cover_scale(view.mask, axis_r, axis_c, radius)
    focal = view.K[1, 1]
    unit_extent = union_extent(np.stack([axis_r, axis_c], axis=-1)[view.mask], radius[view.mask], focal)
    towards, _ = across_view(view.R[2], down)  # the plane's normal

    def balls(rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Centres (N,3) on the plane X . towards = 1 and radii (N,) of the balls of facing pixels (N,)."""
        directions = view.rays(axis_r[rows, cols], axis_c[rows, cols])
        centres = directions / (directions @ towards)[:, None]
        r_px = radius[rows, cols]
        return centres, np.linalg.norm(centres, axis=1) * r_px / np.hypot(focal, r_px)

    if through is None:  # the plane at the distance that gives size_m
        scale = size_m / unit_extent * (view.R[2] @ towards)
    else:
        scale = float(through @ towards)
    axis_points, own = np.unique(np.stack([axis_r, axis_c], axis=-1)[view.mask], axis=0, return_inverse=True)
    centres, radii = balls(*axis_points.T)
    facing = np.zeros(view.mask.shape, int)
    facing[view.mask] = own.ravel()
    t_in, t_out = ray_union(input_rays(mask, K), scale * centres, scale * radii, facing[view.pixels_of(mask)])
    return t_in, t_out, Balls(scale * centres, scale * radii)


def solid_depths(mask: np.ndarray, K: np.ndarray, down: np.ndarray, size_m: float,
                 solid: StandingSolid) -> tuple[np.ndarray, np.ndarray, np.ndarray, list]:
    """Front and back camera z (N,) m along the rays of the pixels of `mask` (H,W) bool (row-major) of the
    standing solid (standing.standing_solid) whose largest extent is size_m, and (N,) bool: those whose
    front lies on its base. A pixel whose ray grazes by it (within standing.NEAR_PX of its image) lies on
    the surface of the nearest pixel it holds, with no thickness; the rest (a handle) keep their own medial
    balls, on the vertical plane through the solid's middle where they meet it, brought nearer where that
    would hang them below the solid's base (a handle pointing at a camera that looks down: what the picture
    shows below the base is nearer, not lower). The fourth value: the body's parts (body.Standing, and the
    handle's body.Balls)."""
    scale = size_m / solid.solid.extent
    parts = [Standing(solid.solid, GravityView.of(mask, K, down).R, scale)]
    t_in, t_out = scale * solid.t_in, scale * solid.t_out
    held = np.zeros(mask.shape, bool)
    held[mask] = np.isfinite(t_in)
    mid = np.full(mask.shape, np.nan)
    mid[mask] = 0.5 * (t_in + t_out)
    gap, (rows, cols) = ndimage.distance_transform_edt(~held, return_indices=True)
    handle = mask & (gap > NEAR_PX)
    grazed = ~held[mask] & ~handle[mask]
    t_in[grazed] = t_out[grazed] = mid[rows, cols][mask][grazed]
    if handle.any():
        meets = held & (ndimage.distance_transform_edt(~handle) <= NEAR_PX + 2)
        if not meets.any():
            meets = held
        through = (input_rays(meets, K) * mid[meets][:, None]).mean(0)
        handle_in, handle_out, balls = ball_depths(handle, K, down, size_m, through)
        # every ball scales with the plane's distance, so its lowest point too
        lowest, base = float(np.max(balls.centres @ down + balls.radii)), scale * solid.solid.base_height()
        if lowest > base > 0:
            handle_in, handle_out, balls = ball_depths(handle, K, down, size_m, through * base / lowest)
        t_in[handle[mask]], t_out[handle[mask]] = handle_in, handle_out
        parts.append(balls)
    return t_in, t_out, solid.on_base, parts


def cut_to_thickness(thickness: float, mask: np.ndarray, K: np.ndarray, rays: np.ndarray, t_in: np.ndarray,
                     t_out: np.ndarray, down: np.ndarray) -> tuple[np.ndarray, np.ndarray, Prism]:
    """A flat object `thickness` m thick: its silhouette `mask` (H,W) bool, photographed by K (3,3), cut to a
    slab, where the body between t_in and t_out (N,) along its pixels' rays (N,3) (input_rays: row-major,
    camera frame, z = 1) places it. (N,) t_in, (N,) t_out, each ray's chord through the slab, and the body
    (body.Prism). The slab lies across the view made horizontal (gravity along `down` (3,)), as the medial
    balls' plane does, or across the view itself seen from above (STEEPEST_VERTICAL_PLANE); its middle is the
    placed body's centre of volume along its normal. The body's own shape across the view (a ball, a box) is
    the prior's guess, which the thickness replaces: every pixel of the silhouette holds the slab."""
    volume = np.where(np.isfinite(t_in) & np.isfinite(t_out), t_out ** 3 - t_in ** 3, 0.0)
    centre = (volume * np.nan_to_num(0.5 * (t_in + t_out))) @ rays / volume.sum()
    view = centre / np.linalg.norm(centre)
    normal, _ = across_view(view, down)
    normal = normal / np.linalg.norm(normal)
    along = rays @ normal
    middle, half = float(centre @ normal), 0.5 * thickness
    return (middle - half) / along, (middle + half) / along, Prism(mask, K, normal, middle, half)


def standing_cut(rays: np.ndarray, t_in: np.ndarray, t_out: np.ndarray, down: np.ndarray, margin: float,
                 layer: float) -> tuple[np.ndarray, np.ndarray, float]:
    """The body between t_in and t_out (N,) along rays (N,3) (camera frame, z = 1), cut flat where it
    stands on the ground (gravity along `down` (3,)). Its base is its part within `layer` m of its lowest
    plane normal to gravity. A body whose base holds its centre of mass at least `margin` m inside (a
    ball) is left whole. Otherwise (a cup on its handle's tip) the contact is a cut, not a point: the
    body is cut by the lowest plane above which its base holds its centre of mass against a tilt of
    STAND_TILT_DEG (inside by tan of it times the centre's height), as a thing made to stand does, else by
    the lowest on which it stands at all; at most MAX_CUT of its height and MAX_CUT_VOLUME of its volume.
    A body that needs more does not stand as photographed, and is left whole to fall. Returns the clipped
    (t_in, t_out), the cut (m above the lowest point) and the lowest point's height, -(x . down) m."""
    across = np.cross(down, [0.0, 0.0, 1.0]) if abs(down[2]) < 0.99 else np.array([1.0, 0.0, 0.0])
    across /= np.linalg.norm(across)
    along = np.cross(down, across)
    steep = rays @ down  # height above the camera falls by t * steep
    lowest = float(np.minimum(-t_in * steep, -t_out * steep).min())
    tall = float(np.maximum(-t_in * steep, -t_out * steep).max()) - lowest
    fractions = (np.arange(SAMPLES_PER_RAY) + 0.5) / SAMPLES_PER_RAY
    whole = float(np.sum(t_out ** 3 - t_in ** 3))  # each ray's pyramid holds (end^3 - start^3) / 3 of it

    def cut_at(cut: float) -> tuple[np.ndarray, np.ndarray]:
        with np.errstate(divide="ignore", invalid="ignore"):
            plane = np.where(steep != 0, -(lowest + cut) / steep, np.nan)  # where each ray meets the plane
        start = np.where(steep < 0, np.fmax(t_in, plane), t_in)
        end = np.where(steep > 0, np.fmin(t_out, plane), t_out)
        gone = start > end  # wholly below the plane: the point where its ray meets the plane
        on_plane = np.where(np.isfinite(plane), plane, t_in)
        return np.where(gone, on_plane, start), np.where(gone, on_plane, end)

    def held(cut: float) -> tuple[float, float]:
        """(how far its base holds its centre of mass inside, m; the centre's height above the cut, m)."""
        start, end = cut_at(cut)
        t = start[:, None] + (end - start)[:, None] * fractions
        weights = t ** 2 * (end - start)[:, None]
        if weights.sum() <= 0:
            return -math.inf, 0.0
        centre = np.tensordot(weights, rays[:, None, :] * t[..., None], axes=([0, 1], [0, 1])) / weights.sum()
        ends = np.concatenate([rays * start[:, None], rays * end[:, None]])
        base = ends[-(ends @ down) <= lowest + cut + (layer if cut == 0 else 1e-6 * tall)]
        inside = support_margin(np.stack([base @ across, base @ along], axis=1),
                                np.array([centre @ across, centre @ along]))
        return inside, -(centre @ down) - (lowest + cut)

    def lowest_cut(stands) -> float | None:
        """The lowest cut within MAX_CUT of the height at which stands(cut) holds (it only grows with the
        cut, as the base does), None if none; binary search."""
        if not stands(MAX_CUT * tall):
            return None
        low, high = 0.0, MAX_CUT * tall
        for _ in range(20):
            middle = 0.5 * (low + high)
            low, high = (low, middle) if stands(middle) else (middle, high)
        return high

    if held(0.0)[0] >= margin:
        return t_in, t_out, 0.0, lowest
    tilt = math.tan(math.radians(STAND_TILT_DEG))
    for stands in (lambda c: (lambda inside, h: inside >= max(margin, tilt * h))(*held(c)),
                   lambda c: held(c)[0] >= margin):
        cut = lowest_cut(stands)
        if cut is not None:
            start, end = cut_at(cut)
            if float(np.sum(end ** 3 - start ** 3)) >= (1.0 - MAX_CUT_VOLUME) * whole:
                return start, end, cut, lowest
    return t_in, t_out, 0.0, lowest  # a carve, not a base: a capsule leaning 20 degrees would lose 7 %


def support_margin(points: np.ndarray, centre: np.ndarray) -> float:
    """How far (m) centre (2,) lies inside the convex hull of points (N,2); negative outside, -inf without an
    area."""
    if len(points) < 3:
        return -math.inf
    try:
        hull = ConvexHull(points)
    except QhullError:  # all on one line
        return -math.inf
    return float(-np.max(hull.equations[:, :2] @ centre + hull.equations[:, 2]))


def object_depths(labels: np.ndarray, K: np.ndarray, sizes_m: Sequence[float], pitch_deg: float,
                  inverse_depth: Optional[np.ndarray] = None,
                  thicknesses_m: Optional[Sequence[Optional[float]]] = None) -> list[ObjectDepth]:
    """Metric front and back camera z (H,W) of each object (labels k + 1), NaN off it: its standing solid
    (solid_depths) or else the body of its medial balls (ball_depths), its largest extent sizes_m[k], or where
    thicknesses_m[k] is given its silhouette cut to a slab that thick there (cut_to_thickness), cut flat where it
    stands on the ground (standing_cut); and that body itself (ObjectDepth.body). With ``inverse_depth`` (a
    depth model's, (H,W)) the front follows the model, aligned to the body's front."""
    down = down_direction(pitch_deg)
    out = []
    for k, size in enumerate(sizes_m):
        mask = labels == k + 1
        front, back = np.full(mask.shape, np.nan), np.full(mask.shape, np.nan)
        solid = standing_solid(mask, K, down)
        if solid is None:
            t_in, t_out, balls = ball_depths(mask, K, down, size)
            on_solid_base, parts = np.zeros(len(t_in), bool), [balls]
        else:
            t_in, t_out, on_solid_base, parts = solid_depths(mask, K, down, size, solid)
            log.info("object %d: a standing %s (its image overlaps the silhouette by %.3f)", k, solid.solid.kind,
                     solid.overlap)
        rays = input_rays(mask, K)
        thickness = thicknesses_m[k] if thicknesses_m is not None else None
        if thickness is not None:
            t_in, t_out, prism = cut_to_thickness(thickness, mask, K, rays, t_in, t_out, down)
            on_solid_base, parts = np.zeros(len(t_in), bool), [prism]
            log.info("object %d: cut to a slab %.0f mm thick across the view (objects[%d].thickness_m)", k,
                     1e3 * thickness, k)
        # the base: the body within a pixel's footprint and a half of the cut, or BASE_LAYER of its size
        layer = max(BASE_LAYER * size, 1.5 * float(np.median(t_in)) / K[0, 0])
        front[mask], back[mask], cut, lowest = standing_cut(rays, t_in, t_out, down, STAND_MARGIN * size, layer)
        base = np.zeros(mask.shape, bool)
        base[mask] = (front[mask] != t_in) | (back[mask] != t_out) | on_solid_base
        if cut > 0:
            log.info("object %d: cut flat %.1f mm above its lowest point, where it stands on its base", k, 1e3 * cut)
        depth = ObjectDepth(front, back, base, Body(parts, down, lowest + cut))
        out.append(depth if inverse_depth is None else aligned_front(depth, inverse_depth))
    return out
