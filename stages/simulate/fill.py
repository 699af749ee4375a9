"""Interior filling: particles for an object's volume from its surface Gaussians.

The Gaussians of a reconstruction sit on the object's surface (front lifted,
back closed). Their means mark a shell of occupied cells on an occupancy grid
as fine as the particle lattice. Gaussians lie a few lattice spacings apart
on a small or coarsely reconstructed object, so the shell has holes that rays
slip through; it is closed first (dilated by a ball as wide as the largest
gap between neighbouring means), a cell is inside when rays cast along the
six axis directions cross the closed shell an odd number of times in a
majority of them (ray parity; its rare misses, cells enclosed by solid, are
filled), and the solid is eroded back by the same ball,
so that its surface is the means' again (a morphological closing). Cells of
the solid get a regular lattice of particles, laid from the body's centre
(a symmetric body gets a symmetric solid, a copy of a body the same solid);
every cell's volume is shared equally by all particles in it, Gaussians
included, so the body's mass is density times its occupied volume however
the Gaussians cluster. The surface cuts the outer cells where the means lie
(`inside_fraction`): each holds the part of it inside, so the volume does
not depend on the lattice's phase or size (counted as half cells, a 10 cm
box would hold 0.78 to 1.10 of its volume at three cell sizes; this way it
holds it within 5 %).

The means lie inside the silhouette the photograph saw: a reconstruction's
Gaussians reach past their means to the silhouette (on the 12 cm synthetic
ball of tests/simulate, the means span 105 mm across and 120 mm in depth).
So the solid is grown by a skin across the view (`skin`, measured by
`silhouette_gap` on the means) until its silhouette has the mask's area:
the photograph is the one measurement of the object's extent across the
view, and the depth prior the one along it. Where the depth prior's volume
is known, what the solid still lacks of it lies on its sides (its back
keeps the front's scale where the camera's rays spread), and `carry_volume`
lays it on the side walls' particles.

Time and memory are O(G + cells) on a grid no finer than the particle
lattice, whatever the Gaussians' covariances (only their means are used).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
import cv2
from scipy.ndimage import (binary_dilation, binary_erosion, binary_fill_holes, distance_transform_edt,
                           gaussian_filter)
from scipy.spatial import cKDTree

from schemas.camera import project_points

# Inside when at least this many of the six axis rays see odd parity.
INSIDE_VOTES = 4
# The shell is closed with a ball of this quantile of the means' nearest-neighbour distances
# (nearly the widest gap, not an outlier's).
GAP_QUANTILE = 0.99
# The surface's offset in an outer cell is the median over this many nearest means.
NORMAL_NEIGHBOURS = 8
# Cells this close to the solid's boundary (in cells) are cut by the surface; deeper ones are whole.
SURFACE_DEPTH = 2.0
# A cell less than this much inside the surface gets no particle (a particle must carry mass).
MIN_FRACTION = 0.05


def cell_index(points: np.ndarray, origin: np.ndarray, dx: float, shape: tuple[int, int, int]) -> np.ndarray:
    """(N, 3) index of the cell holding each point, clipped to the grid."""
    return np.clip(np.floor((points - origin) / dx).astype(np.int64), 0, np.array(shape) - 1)


def shell_cells(points: np.ndarray, origin: np.ndarray, dx: float, shape: tuple[int, int, int]) -> np.ndarray:
    """Boolean occupancy (shape) of the cells that contain at least one point."""
    idx = cell_index(points, origin, dx, shape)
    occupied = np.zeros(shape, dtype=bool)
    occupied[idx[:, 0], idx[:, 1], idx[:, 2]] = True
    return occupied


def inside_by_ray_parity(shell: np.ndarray) -> np.ndarray:
    """Empty cells enclosed by the shell: odd crossings in >= INSIDE_VOTES of the 6 axis directions.

    A crossing is one contiguous run of shell cells along the ray, so a shell
    several cells thick still counts once.
    """
    votes = np.zeros(shell.shape, dtype=np.int8)
    for axis in range(3):
        s = np.moveaxis(shell, axis, -1)
        run_starts = s & ~np.concatenate([np.zeros_like(s[..., :1]), s[..., :-1]], axis=-1)
        before = np.cumsum(run_starts, axis=-1) - run_starts  # runs strictly before (to -axis)
        after = run_starts.sum(axis=-1, keepdims=True) - np.cumsum(run_starts, axis=-1)  # runs after (to +axis)
        # a shell cell itself counts its own run on neither side
        votes += np.moveaxis(((before % 2 == 1) & ~s).astype(np.int8) + ((after % 2 == 1) & ~s), -1, axis)
    return votes >= INSIDE_VOTES


def closing_radius(means: np.ndarray, cell: float) -> int:
    """Radius in cells of the ball that closes the shell the means mark: half their widest gap, plus one."""
    if len(means) < 2:
        return 1
    gap = float(np.quantile(cKDTree(means).query(means, k=2)[0][:, 1], GAP_QUANTILE))
    return int(np.ceil(0.5 * gap / cell)) + 1


def ball(radius: int) -> np.ndarray:
    """Boolean structuring element: the cells within `radius` cells of the centre."""
    r = np.arange(-radius, radius + 1)
    return (r[:, None, None] ** 2 + r[None, :, None] ** 2 + r[None, None, :] ** 2) <= radius ** 2


def lattice_spacing(dx: float, particles_per_cell: int) -> float:
    """Spacing in m of the fill lattice: n = round(cbrt(particles_per_cell)) particles per cell and axis."""
    return dx / max(1, int(round(particles_per_cell ** (1.0 / 3.0))))


def silhouette_gap(means: np.ndarray, mask: np.ndarray, K: np.ndarray) -> float:
    """How far (m) the means' surface must grow for its silhouette to have the photographed mask's area.

    Args:
        means: (G,3) the object's Gaussian centres, camera frame (x right, y down, z forward), m.
        mask: (H,W) bool, the object in the photograph.
        K: (3,3) intrinsics of the photograph.

    The means are drawn into the photograph at twice its resolution, their gaps closed by a disc of
    half the widest (a morphological closing, as the fill closes its shell); the missing area over
    the two outlines' mean perimeter is the gap in pixels (plus half a drawn pixel: each mean marks
    the whole pixel around it), taken to metres at the means' median depth. Measured on the means, not on
    the lattice, it does not depend on the cell size.
    """
    up = 2  # drawn pixels per photograph pixel
    contours, _ = cv2.findContours((mask > 0).astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    perimeter = up * sum(cv2.arcLength(c, True) for c in contours)
    if perimeter <= 0 or len(means) < 2:
        return 0.0
    uv = up * project_points(means, K)
    radius = closing_radius(uv, 1.0)  # in drawn pixels, as the fill's in lattice cells
    H, W = mask.shape
    ij = np.floor(uv).astype(int) + radius  # drawn on a canvas padded by the closing's radius
    canvas = np.zeros((up * H + 2 * radius, up * W + 2 * radius), bool)
    inside = (ij[:, 0] >= 0) & (ij[:, 1] >= 0) & (ij[:, 0] < canvas.shape[1]) & (ij[:, 1] < canvas.shape[0])
    canvas[ij[inside, 1], ij[inside, 0]] = True
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
    closed = cv2.morphologyEx(canvas.astype(np.uint8), cv2.MORPH_CLOSE, disc).astype(bool)
    drawn = binary_fill_holes(closed)
    outline, _ = cv2.findContours(drawn.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    # over the mean of the two perimeters: exact for a ring between concentric circles
    between = 0.5 * (perimeter + sum(cv2.arcLength(c, True) for c in outline))
    gap = (up * up * float(np.count_nonzero(mask)) - float(drawn.sum())) / between + 0.5
    return max(0.0, gap) / up * float(np.median(means[:, 2])) / float(K[0, 0])


def inside_fraction(candidates: np.ndarray, means: np.ndarray, origin: np.ndarray, cell: float,
                    skin: float, view: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fraction (shape of candidates) of each candidate cell inside the surface, 0 elsewhere; and how
    much each cell's surface faces across the view (the sine of its normal's angle to `view`, 0 off the
    surface layer: 1 on the side walls, 0 on the front and the back).

    The surface is the means' grown by `skin` across the unit `view` direction (so by skin times the
    normal's component across it). Cells more than SURFACE_DEPTH cells inside the
    candidates' boundary are whole; nearer it, a cell holds 1/2 + (s + skin) / cell of itself, s the
    means' offset from its centre along the outward normal (the occupancy's smoothed gradient; the
    median over the nearest means): a surface a fifth of a cell in from a cell's outer face leaves
    0.2 of it inside, whatever the lattice's phase against the surface.
    """
    fraction = candidates.astype(float)
    sideways = np.zeros(candidates.shape)
    near = np.argwhere(candidates & (distance_transform_edt(candidates) <= SURFACE_DEPTH))
    if len(near) == 0:
        return fraction, sideways
    inward = np.stack(np.gradient(gaussian_filter(fraction, 1.0)), axis=-1)[tuple(near.T)]
    outward = -inward / np.maximum(np.linalg.norm(inward, axis=1, keepdims=True), 1e-12)
    centres = origin + cell * (near + 0.5)
    _, nearest = cKDTree(means).query(centres, k=min(NORMAL_NEIGHBOURS, len(means)))
    nearest = nearest.reshape(len(near), -1)
    offset = np.median(np.einsum("nkj,nj->nk", means[nearest] - centres[:, None, :], outward), axis=1)
    across = np.sqrt(np.clip(1.0 - (outward @ view) ** 2, 0.0, 1.0))
    fraction[tuple(near.T)] = np.clip(0.5 + (offset + skin * across) / cell, 0.0, 1.0)
    sideways[tuple(near.T)] = across
    return fraction, sideways


def across_view_disc(radius: float, view: np.ndarray) -> np.ndarray:
    """Boolean structuring element: the cells within `radius` cells of the centre, across the unit
    `view` direction and within half a cell along it (a disc seen face on by the camera)."""
    n = int(np.ceil(radius))
    r = np.stack(np.meshgrid(*[np.arange(-n, n + 1)] * 3, indexing="ij"), axis=-1).astype(float)
    along = r @ view
    return (np.sum(r * r, axis=-1) - along ** 2 <= radius ** 2) & (np.abs(along) <= 0.5)


class Solid(NamedTuple):
    """One object's filled solid: its new particles, and per particle (the object's Gaussians first, then
    the new ones) the volume it represents and how its surface faces."""

    fill: np.ndarray
    """(N,3) new particle positions, m."""
    volume: np.ndarray
    """(G+N,) volume in m^3 each particle represents."""
    sideways: np.ndarray
    """(G+N,) how much the surface at each particle faces across the view, 0-1 (inside_fraction); 0 inside."""


def fill_object(means: np.ndarray, dx: float, particles_per_cell: int, skin: float = 0.0,
                view: np.ndarray = np.array([0.0, 0.0, 1.0])) -> Solid:
    """Fill one object's volume.

    Args:
        means: (G,3) Gaussian centres of the object, m.
        dx: cell size, m (the simulation grid's).
        particles_per_cell: lattice density; n = round(cbrt) per axis, at least 1.
        skin: grow the solid by this much beyond the means' surface across `view`, m.
        view: unit direction (3,) of the camera's rays through the object, in the means' frame. A
            reconstruction's means sit inside the silhouette (its Gaussians reach past them), but its
            front and back lie where the depth prior put them: the solid grows across the view only.

    Returns:
        The Solid: the fill particles, every particle's volume, and how much its surface faces across
        the view (for carry_volume).
    """
    cell = lattice_spacing(dx, particles_per_cell)  # one lattice particle per occupancy cell and axis
    radius = closing_radius(means, cell)
    pad = radius + int(np.ceil(skin / cell)) + 2  # the closed shell, skin and surface layer stay off the border
    # cell faces through the centre of the object's box: a mirror-symmetric body gets a mirror-symmetric
    # solid (its mass centred, no torque from the lattice), a copy of it elsewhere the same solid, and a
    # cut through its middle no particle on the cut
    centre = 0.5 * (means.min(axis=0) + means.max(axis=0))
    half_cells = np.ceil(0.5 * (means.max(axis=0) - means.min(axis=0)) / cell).astype(int) + pad + 1
    origin = centre - half_cells * cell
    shape = tuple(int(n) for n in 2 * half_cells)
    shell = shell_cells(means, origin, cell, shape)
    closed = binary_dilation(shell, ball(radius))
    # ray parity's odd misses inside are filled before the erosion, which would widen each by the ball
    solid = binary_fill_holes(closed | inside_by_ray_parity(closed))
    solid = binary_erosion(solid, ball(radius)) | shell
    if skin > 0:
        solid = binary_dilation(solid, across_view_disc(skin / cell, view))
    # the surface cuts the cells about the solid's boundary, one layer beyond it included: each holds
    # the part of it inside; a cell with a Gaussian is kept, however little of it is inside
    fraction, sideways = inside_fraction(binary_dilation(solid), means, origin, cell, skin, view)
    gauss_cell = cell_index(means, origin, cell, shape)
    fraction[tuple(gauss_cell.T)] = np.maximum(fraction[tuple(gauss_cell.T)], MIN_FRACTION)
    occupied = fraction >= MIN_FRACTION

    cells = np.argwhere(occupied)  # C-order: particles of neighbouring cells stay close in memory
    fill = origin + cell * (cells + 0.5)  # one particle at each cell's centre

    # share each cell's volume among all particles in it
    count = occupied.astype(np.int64)
    np.add.at(count, tuple(gauss_cell.T), 1)
    per_particle = cell ** 3 * fraction / np.maximum(count, 1)
    particle_cell = tuple(np.concatenate([gauss_cell, cells]).T)
    return Solid(fill, per_particle[particle_cell], sideways[particle_cell])


def carry_volume(volumes: np.ndarray, sideways: np.ndarray, target: float) -> np.ndarray:
    """The particles' volumes (m^3, shape of volumes) made to carry `target` m^3 in all.

    The solid's back lies straight behind its front, where the camera's rays spread: behind its rim the
    body the photograph saw is wider than the solid by the rays' spread, so a solid holds less than its
    depth prior encloses, and what it lacks lies on its sides. A lack is laid on the particles of the
    side walls, each in proportion to its volume and to how much its surface faces across the view
    (`sideways`), so that the mass sits as far out as the body's and its moment of inertia follows;
    the interior keeps its cell's volume. An excess has no known place and is taken from every
    particle alike, as is a lack where the solid has no side walls.
    """
    total = float(volumes.sum())
    on_sides = float(np.sum(volumes * sideways))
    if target <= total or on_sides <= 0.0:
        return volumes * (target / total)
    return volumes * (1.0 + (target - total) / on_sides * sideways)
