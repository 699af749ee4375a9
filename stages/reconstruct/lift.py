"""Initial Gaussians: the front surface lifted from the depth prior, the back closed, the rim walled.

The simulator fills each object's interior by ray parity on an occupancy grid,
so the Gaussians of one object must enclose a volume: front sheet + back sheet
+ a wall along the silhouette between them. Each surface Gaussian is a flat
disc (surfel) tangent to its sheet, sized to cover its pixel's footprint.

The front takes the photograph's pixels. A surface the photograph does not see
takes the colour of the seen surface it continues (:func:`continued_colours`):
the body is mirror-symmetric about a vertical plane across the view
(docs/decisions/0001-back-closure.md), so its back is its front mirrored, and
the pixel in front of a back point is some other surface (a cup's white inside
in front of its red outer wall).
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from schemas.camera import pixel_rays

from .closure import across_view
from .depth import ObjectDepth

SIGMA_PER_SPACING = 0.6
"""Surfel standard deviation per sample spacing: neighbours overlap, so the sheet has no gaps."""
MAX_STRETCH = 4.0
"""A steep surfel stretches along the slope at most this many spacings (the rim wall closes the rest)."""
THICKNESS_PER_SPACING = 0.15
"""Surfel thickness (along its normal) per sample spacing."""
INITIAL_OPACITY = 0.9
AGREE_COS = 0.8
"""An unseen Gaussian continues a surface whose outward normal lies within 37 degrees of its own (mirrored):
a cup's outer wall, not the rim or the inside above it."""
RECORDED_FACING = 0.3
"""A seen surface whose normal meets the view ray at a cosine under this is a poor record of its colour (a pixel
spans more than three times its width along it). Its twin is the first of stages/enhance/unseen.py's
RECORDED_FACING (a stage imports no other): change both together."""
SPREAD_COS = 0.95
"""Where the mirror image shows no such surface, the colour spreads between neighbours whose normals lie within
18 degrees: over a curved face, not round an edge (a cup's outer wall onto its flat cut base)."""
REACH_SPACINGS = 3.0
"""It looks for that surface within this many of the back's sample spacings of its mirror image (or, where
the mirror image is hidden, of its own place, from the unseen surface already coloured)."""
NEIGHBOURS = 12
"""How many of the nearest Gaussians (within the reach) are searched for an agreeing normal, round a mirror
image or a Gaussian the colour spreads to: more than the 8 of a sheet's nearest ring."""
NORMAL_STEP = 0.01
"""The normals' central differences span this share of the body's extent."""
PLANE_STEPS = 41
PLANE_YAW_DEG = 10.0
"""The mirror plane is searched on PLANE_STEPS offsets across the body, then as many within a step, then as
many turns about the vertical within this many degrees of across the view."""


@dataclass
class Gaussians:
    """G Gaussians (DESIGN.md conventions): means (G,3) m, scales (G,3) m, rotations (G,4) wxyz,
    opacities (G,) in [0,1], colors (G,3) sRGB in [0,1], object_id (G,) int."""

    means: np.ndarray
    scales: np.ndarray
    rotations: np.ndarray
    opacities: np.ndarray
    colors: np.ndarray
    object_id: np.ndarray

    def __len__(self) -> int:
        return len(self.means)

    @staticmethod
    def concatenate(parts: list["Gaussians"]) -> "Gaussians":
        return Gaussians(**{f.name: np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(Gaussians)})

    def select(self, keep: np.ndarray) -> "Gaussians":
        return Gaussians(**{f.name: getattr(self, f.name)[keep] for f in fields(Gaussians)})


def _filled(depth: np.ndarray) -> np.ndarray:
    """``depth`` with NaNs replaced by the nearest valid value, so finite differences work at the rim."""
    invalid = ~np.isfinite(depth)
    _, (rows, cols) = ndimage.distance_transform_edt(invalid, return_indices=True)
    return depth[rows, cols]


def _surfels(points: np.ndarray, pixels: np.ndarray, stride: int, colors: np.ndarray, object_id: int) -> Gaussians:
    """Surfels at ``points`` (H,W,3) on the pixels (H,W bool) of a stride-``stride`` grid."""
    d_col = np.gradient(points, axis=1) * stride  # metres between neighbouring samples
    d_row = np.gradient(points, axis=0) * stride
    d_col, d_row, centres = d_col[pixels], d_row[pixels], points[pixels]
    normal = np.cross(d_col, d_row)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True) + 1e-12
    axis1 = d_col - (d_col * normal).sum(1, keepdims=True) * normal
    axis1 /= np.linalg.norm(axis1, axis=1, keepdims=True) + 1e-12
    axis2 = np.cross(normal, axis1)
    # The un-stretched spacing: one sample's footprint, the smaller of the two tangent lengths' in-plane parts.
    len1 = np.abs((d_col * axis1).sum(1))
    len2 = np.abs((d_row * axis2).sum(1))
    spacing = np.minimum(len1, len2)
    scales = SIGMA_PER_SPACING * np.stack([np.minimum(len1, MAX_STRETCH * spacing),
                                           np.minimum(len2, MAX_STRETCH * spacing),
                                           THICKNESS_PER_SPACING / SIGMA_PER_SPACING * spacing], axis=1)
    rotations = Rotation.from_matrix(np.stack([axis1, axis2, normal], axis=2)).as_quat(scalar_first=True)
    count = len(centres)
    return Gaussians(centres, scales, rotations, np.full(count, INITIAL_OPACITY), colors[pixels],
                     np.full(count, object_id))


def _rim_wall(front: np.ndarray, back: np.ndarray, pixels: np.ndarray, spacing: np.ndarray, colors: np.ndarray,
              object_id: int) -> Gaussians:
    """Isotropic Gaussians from the front surface (H,W,3) to the back (H,W,3) along the rays of the
    silhouette's edge pixels, one spacing (H,W) apart."""
    edge = pixels & ~ndimage.binary_erosion(pixels, border_value=0)
    rows, cols = np.nonzero(edge)
    counts = np.maximum(1, np.ceil(np.linalg.norm(back - front, axis=-1)[edge] / spacing[edge]).astype(int) - 1)
    steps = np.concatenate([(np.arange(1, c + 1) / (c + 1)) for c in counts])
    idx = np.repeat(np.arange(len(rows)), counts)
    start, end = front[rows[idx], cols[idx]], back[rows[idx], cols[idx]]
    means = start + steps[:, None] * (end - start)
    sigma = SIGMA_PER_SPACING * spacing[rows[idx], cols[idx]]
    count = len(means)
    return Gaussians(means, np.repeat(sigma[:, None], 3, axis=1), np.tile([1.0, 0, 0, 0], (count, 1)),
                     np.full(count, INITIAL_OPACITY), colors[rows[idx], cols[idx]], np.full(count, object_id))


def lift_object(depth: ObjectDepth, K: np.ndarray, photo: np.ndarray, object_id: int,
                front_stride: int = 1, back_stride: int = 2) -> tuple[Gaussians, np.ndarray]:
    """Closed surface of Gaussians of one object: its front and back where each pixel's ray enters and
    leaves the body the prior describes (closure.py), walled along the silhouette's edge.

    Args:
        depth: camera-space front/back z (H,W) of the object at the lifting resolution, NaN off it.
        K: (3,3) intrinsics at that resolution.
        photo: RGB u8 (H,W,3) at that resolution; front and back take the pixel's colour.
        front_stride, back_stride: sample every n-th pixel (the back is never seen, so it can be coarser).

    Returns:
        The Gaussians, and which of them lie on the front, the surface the photograph sees, (G,) bool.
    """
    height, width = depth.front.shape
    rays = pixel_rays(K, height, width)
    rays = rays / rays[..., 2:3]  # point = ray * z
    colors = photo.astype(np.float64) / 255.0
    pixels = depth.pixels
    front = rays * _filled(depth.front)[..., None]
    back = rays * _filled(depth.back)[..., None]
    parts = []
    for points, stride in ((front, front_stride), (back, back_stride)):
        grid = np.zeros_like(pixels)
        grid[stride // 2::stride, stride // 2::stride] = True
        parts.append(_surfels(points, pixels & grid, stride, colors, object_id))
    wall_spacing = back_stride * depth.front / K[0, 0]  # metres per pixel at the front surface, times the stride
    parts.append(_rim_wall(front, back, pixels, wall_spacing, colors, object_id))
    # The photograph sees the front, but not where it was cut onto the base the body stands on.
    front_grid = np.zeros_like(pixels)
    front_grid[front_stride // 2::front_stride, front_stride // 2::front_stride] = True
    on_base = depth.base if depth.base is not None else np.zeros_like(pixels)
    seen = np.zeros(sum(map(len, parts)), bool)
    seen[:len(parts[0])] = ~on_base[pixels & front_grid]
    gaussians = Gaussians.concatenate(parts)
    if depth.body is not None:
        normals = outward_normals(depth.body, gaussians.means)
        spacing = float(np.nanmedian(wall_spacing[pixels]))
        plane = mirror_plane(gaussians.means, seen, depth.body.down, spacing)
        reach = REACH_SPACINGS * spacing
        on_cut = -(gaussians.means @ depth.body.down) <= depth.body.floor + 0.5 * spacing
        gaussians.colors = continued_colours(gaussians.means, gaussians.colors, seen, normals, plane, reach, K,
                                             (width, height), on_cut)
    return gaussians, seen


def outward_normals(body, points: np.ndarray) -> np.ndarray:
    """(P,3) unit outward normals of ``body`` (body.Body: its signed distance) at points (P,3) m: central
    differences NORMAL_STEP of the points' extent wide, over the steps of a body of revolution's slabs (a
    quarter of a pixel each) but within a corner's rounding."""
    step = NORMAL_STEP * float(np.max(points.max(axis=0) - points.min(axis=0)))
    gradient = np.stack([body.distance(points + step * e) - body.distance(points - step * e) for e in np.eye(3)],
                        axis=1)
    return gradient / np.maximum(np.linalg.norm(gradient, axis=1, keepdims=True), 1e-12)


def reflect(points: np.ndarray, plane: tuple[np.ndarray, float]) -> np.ndarray:
    """Mirror images (P,3) of points (P,3) m across ``plane`` (unit normal (3,), offset m: x . normal = offset);
    directions (normals) reflect across the plane through the origin, offset 0."""
    normal, offset = plane
    return points - 2.0 * (points @ normal - offset)[:, None] * normal


def mirror_plane(means: np.ndarray, seen: np.ndarray, down: np.ndarray, spacing: float) -> tuple[np.ndarray, float]:
    """The plane of symmetry of the body whose surface the Gaussians at ``means`` (G,3) m cover, points x with
    x . normal = offset: across the view, vertical (gravity along ``down`` (3,)) unless seen from above
    (closure.across_view), placed and turned (by up to PLANE_YAW_DEG about the vertical) so that the mirror
    images of the unseen Gaussians (``seen`` (G,) bool) lie nearest the surface, their median distance to the
    nearest Gaussian least; of the turns within a tenth of the sample ``spacing`` (m) of the least, the one
    nearest across the view (a body of revolution is symmetric about every vertical plane through its axis).
    A centre of volume misses the plane by the weight of a handle or a cut (4 mm on the coffee cup)."""
    centre = means.mean(axis=0)
    view = centre / np.linalg.norm(centre)
    normal, vertical = across_view(view, down)
    if not vertical:  # seen from above: the plane across the view turns about the picture's vertical
        down = np.cross(view, [1.0, 0.0, 0.0])
    normal = normal / np.linalg.norm(normal)
    across = np.cross(down, normal)
    tree = cKDTree(means)
    unseen = means[~seen]

    def miss(normal: np.ndarray, offset: float) -> float:
        mirrored = reflect(unseen, (normal, offset))
        return float(np.median(tree.query(mirrored)[0]))

    along = means @ normal
    offsets = np.linspace(along.min(), along.max(), PLANE_STEPS)
    offset = min(offsets, key=lambda o: miss(normal, o))
    step = offsets[1] - offsets[0]
    offset = min(np.linspace(offset - step, offset + step, PLANE_STEPS), key=lambda o: miss(normal, o))
    turns = np.radians(np.linspace(-PLANE_YAW_DEG, PLANE_YAW_DEG, PLANE_STEPS))
    pivot = offset * normal + (centre @ across) * across
    normals = [np.cos(a) * normal + np.sin(a) * across for a in turns]
    misses = np.array([miss(n, pivot @ n) for n in normals])
    near_least = np.flatnonzero(misses <= misses.min() + 0.1 * spacing)
    normal = normals[near_least[np.argmin(np.abs(turns[near_least]))]]
    return normal, float(pivot @ normal)


def continued_colours(means: np.ndarray, colors: np.ndarray, seen: np.ndarray, normals: np.ndarray,
                      plane: tuple[np.ndarray, float], reach: float, K: np.ndarray, size: tuple[int, int],
                      kept: np.ndarray) -> np.ndarray:
    """(G,3) colours of Gaussians at ``means`` (G,3) m, ``colors`` (G,3) as lifted (each its pixel's), where
    those not ``seen`` (G,) bool take the colour of the seen surface they continue.

    Each unseen Gaussian takes the colour of the nearest seen one within ``reach`` m of its mirror image across
    ``plane`` (normal (3,), offset m) whose outward normal (``normals`` (G,3)) agrees with its own mirrored
    (AGREE_COS), among those the photograph recorded well (facing the camera, the origin, by RECORDED_FACING:
    along the silhouette a pixel mixes a strip of surface, darkened by shading, with the background). Where
    the mirror image is no such surface (near the silhouette, behind a handle, off a body that is not
    symmetric), the colour spreads over the unseen surface from the nearest one so coloured within ``reach`` of
    it whose normal agrees with its own (SPREAD_COS), ring by ring. A face that continues no seen one keeps
    the colour it was lifted with: ``kept`` (G,) bool (the flat cut the body stands on), one whose mirror
    image lies beyond the picture (K (3,3), size (w, h) px: an object cut by its border, whose front meets no
    back), and one the spread does not reach; and so does an unseen one that faces the camera (the wall along
    the silhouette, whose pixel is its own surface's, at the limb)."""
    out = colors.copy()
    facing = -np.einsum("gc,gc->g", normals, means) / np.linalg.norm(means, axis=1)  # the camera at the origin
    unseen = np.flatnonzero(~seen & ~kept & (facing < 0))
    recorded = seen & (facing >= RECORDED_FACING)
    if len(unseen) == 0 or not recorded.any():
        return out
    mirrored = reflect(means[unseen], plane)
    mirrored_normals = reflect(normals[unseen], (plane[0], 0.0))
    recorded_index = np.flatnonzero(recorded)
    distance, near = cKDTree(means[recorded]).query(mirrored, k=NEIGHBOURS, distance_upper_bound=reach)
    found = np.isfinite(distance)
    near = recorded_index[np.where(found, near, 0)]
    agree = found & (np.einsum("gkc,gc->gk", normals[near], mirrored_normals) >= AGREE_COS)
    first = np.argmax(agree, axis=1)  # the nearest agreeing one: neighbours come sorted by distance
    uv = mirrored @ K.T
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = uv[:, :2] / uv[:, 2:]
    beyond = ~((uv >= 0) & (uv <= size)).all(axis=1) | (mirrored[:, 2] <= 0)
    matched = agree.any(axis=1) & ~beyond
    out[unseen[matched]] = colors[near[matched, first[matched]]]
    coloured = np.zeros_like(seen)  # the colours that spread: the mirrored ones
    coloured[unseen[matched]] = True
    settled = np.ones_like(seen)
    settled[unseen[~matched & ~beyond]] = False
    tree = cKDTree(means)
    while True:
        pending = np.flatnonzero(~settled)
        if len(pending) == 0:
            break
        distance, near = tree.query(means[pending], k=NEIGHBOURS, distance_upper_bound=reach)
        found = np.isfinite(distance)
        near = np.where(found, near, 0)
        usable = found & coloured[near] & (np.einsum("gkc,gc->gk", normals[near], normals[pending]) >= SPREAD_COS)
        reached = usable.any(axis=1)
        if not reached.any():
            break
        out[pending[reached]] = out[near[reached, np.argmax(usable[reached], axis=1)]]
        coloured[pending[reached]] = settled[pending[reached]] = True
    return out
