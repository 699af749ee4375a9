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

A reconstruction's objects carry their solid (schemas.solid.SolidGrid): `fill_solid` lays the lattice in
it, from its centre, each particle holding the share of its cell the signed distance puts inside.
`fill_object` is for an object without one (an init_ply's), whose Gaussians are its solid.

Time and memory are O(G + cells) on a grid no finer than the particle
lattice, whatever the Gaussians' covariances (only their means are used).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.ndimage import binary_dilation, binary_erosion, binary_fill_holes, distance_transform_edt, gaussian_filter
from scipy.spatial import cKDTree

from schemas.solid import SolidGrid

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


def inside_fraction(candidates: np.ndarray, means: np.ndarray, origin: np.ndarray, cell: float) -> np.ndarray:
    """Fraction (shape of candidates) of each candidate cell inside the means' surface, 0 elsewhere.

    Cells more than SURFACE_DEPTH cells inside the candidates' boundary are whole; nearer it, a cell holds
    1/2 + s / cell of itself, s the means' offset from its centre along the outward normal (the occupancy's
    smoothed gradient; the median over the nearest means): a surface a fifth of a cell in from a cell's
    outer face leaves 0.2 of it inside, whatever the lattice's phase against the surface.
    """
    fraction = candidates.astype(float)
    near = np.argwhere(candidates & (distance_transform_edt(candidates) <= SURFACE_DEPTH))
    if len(near) == 0:
        return fraction
    inward = np.stack(np.gradient(gaussian_filter(fraction, 1.0)), axis=-1)[tuple(near.T)]
    outward = -inward / np.maximum(np.linalg.norm(inward, axis=1, keepdims=True), 1e-12)
    centres = origin + cell * (near + 0.5)
    _, nearest = cKDTree(means).query(centres, k=min(NORMAL_NEIGHBOURS, len(means)))
    nearest = nearest.reshape(len(near), -1)
    offset = np.median(np.einsum("nkj,nj->nk", means[nearest] - centres[:, None, :], outward), axis=1)
    fraction[tuple(near.T)] = np.clip(0.5 + offset / cell, 0.0, 1.0)
    return fraction


class Solid(NamedTuple):
    """One object's filled solid: its new particles, and per particle (the object's Gaussians first, then
    the new ones) the volume it represents."""

    fill: np.ndarray
    """(N,3) new particle positions, m."""
    volume: np.ndarray
    """(G+N,) volume in m^3 each particle represents."""


def fill_solid(solid: SolidGrid, Q: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """The lattice in a reconstruction's solid: (N,3) particle positions in the simulation frame (x_sim =
    Q x_world, Q (3,3)), m, and (N,) the volume in m^3 each holds: its cell's share inside the solid.

    The lattice's cells, `spacing` m wide, lie along the simulation frame's axes with faces through the
    solid's centre: a solid symmetric about a vertical plane through its centre gets symmetric particles.
    """
    n = solid.distance.shape[0]
    reach = 0.5 * (n - 1) * solid.spacing  # the solid grid's half width
    half = int(np.ceil(reach / spacing))
    centre = Q @ solid.centre
    ticks = (np.arange(-half, half) + 0.5) * spacing
    cells = np.stack(np.meshgrid(ticks, ticks, ticks, indexing="ij"), axis=-1).reshape(-1, 3)
    points = centre + cells
    fraction = solid.inside_fraction(points @ Q, spacing)
    keep = fraction >= MIN_FRACTION
    return points[keep], spacing ** 3 * fraction[keep]


def fill_object(means: np.ndarray, dx: float, particles_per_cell: int) -> Solid:
    """Fill the volume one object's Gaussian means enclose (an object without a reconstruction's solid).

    Args:
        means: (G,3) Gaussian centres of the object, m.
        dx: cell size, m (the simulation grid's).
        particles_per_cell: lattice density; n = round(cbrt) per axis, at least 1.

    Returns:
        The Solid: the fill particles and every particle's volume.
    """
    cell = lattice_spacing(dx, particles_per_cell)  # one lattice particle per occupancy cell and axis
    radius = closing_radius(means, cell)
    pad = radius + 2  # the closed shell and its surface layer stay off the border
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
    # the surface cuts the cells about the solid's boundary, one layer beyond it included: each holds
    # the part of it inside; a cell with a Gaussian is kept, however little of it is inside
    fraction = inside_fraction(binary_dilation(solid), means, origin, cell)
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
    return Solid(fill, per_particle[particle_cell])
