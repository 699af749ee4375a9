"""Interior filling: particles for an object's volume from its surface Gaussians.

The Gaussians of a reconstruction sit on the object's surface (front lifted,
back closed). Their means mark a shell of occupied cells on an occupancy grid;
a cell is inside when rays cast along the six axis directions cross the shell
an odd number of times in a majority of them (ray parity, robust to a few
holes in the shell). Shell and inside cells get a regular lattice of
particles; every cell's volume is shared equally by all particles in it,
Gaussians included, so the body's mass is density times its occupied volume
however the Gaussians cluster. The surface cuts through the cells on the
outside of the occupancy, so those count half their volume.

The occupancy grid is as fine as the particle lattice (one particle per
occupancy cell) wherever the Gaussians lie close enough to close the shell at
that spacing. Its cells' staircase is the body's surface as the simulation
sees it: with whole simulation cells it bulged up to a cell beyond the
Gaussians, added mass there, and, where the body met the ground, touched
first on one side and spun it.

Time and memory are O(G + cells) on a grid no finer than the particle
lattice, whatever the Gaussians' covariances (only their means are used).
"""
from __future__ import annotations

import numpy as np
from scipy.ndimage import binary_erosion
from scipy.spatial import cKDTree

# Inside when at least this many of the six axis rays see odd parity.
INSIDE_VOTES = 4
# The occupancy cell is at least this many times the Gaussians' median nearest-neighbour
# distance, so that the shell they mark has no holes for rays to slip through.
SHELL_CLOSING = 2.0


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


def occupancy_resolution(means: np.ndarray, dx: float, particles_per_cell: int) -> tuple[int, float]:
    """(particles per axis of an occupancy cell, occupancy cell size in m).

    The lattice has n = round(cbrt(particles_per_cell)) particles per simulation cell and axis,
    spacing dx / n. The occupancy cell is the smallest whole number of lattice spacings (at most n)
    that is at least SHELL_CLOSING median nearest-neighbour distances of the Gaussians.
    """
    n = max(1, int(round(particles_per_cell ** (1.0 / 3.0))))
    spacing = dx / n
    gap = float(np.median(cKDTree(means).query(means, k=2)[0][:, 1])) if len(means) > 1 else dx
    per_axis = int(np.clip(np.ceil(SHELL_CLOSING * gap / spacing - 1e-9), 1, n))
    return per_axis, per_axis * spacing


def fill_object(means: np.ndarray, dx: float, particles_per_cell: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fill one object's volume.

    Args:
        means: (G,3) Gaussian centres of the object, m.
        dx: cell size, m (the simulation grid's).
        particles_per_cell: lattice density; n = round(cbrt) per axis, at least 1.

    Returns:
        fill: (N,3) new particle positions, m.
        gaussian_volume: (G,) volume in m^3 each Gaussian particle represents.
        fill_volume: (N,) volume in m^3 of each fill particle.
    """
    per_axis, cell = occupancy_resolution(means, dx, particles_per_cell)
    origin = means.min(axis=0) - cell  # one empty cell of padding: rays start outside
    shape = tuple(int(n) for n in np.ceil((means.max(axis=0) - origin) / cell).astype(int) + 2)
    shell = shell_cells(means, origin, cell, shape)
    occupied = shell | inside_by_ray_parity(shell)

    offsets = (np.stack(np.meshgrid(*[np.arange(per_axis)] * 3, indexing="ij"), -1).reshape(-1, 3) + 0.5) / per_axis
    cells = np.argwhere(occupied)  # C-order: particles of neighbouring cells stay close in memory
    fill = origin + cell * (cells[:, None, :] + offsets[None, :, :]).reshape(-1, 3)

    # share each cell's volume among all particles in it
    gauss_cell = cell_index(means, origin, cell, shape)
    count = occupied.astype(np.int64) * len(offsets)
    np.add.at(count, tuple(gauss_cell.T), 1)
    cell_volume = cell ** 3 * np.where(occupied & ~binary_erosion(occupied), 0.5, 1.0)
    per_particle = cell_volume / np.maximum(count, 1)
    gaussian_volume = per_particle[tuple(gauss_cell.T)]
    fill_volume = np.repeat(per_particle[tuple(cells.T)], len(offsets))
    return fill, gaussian_volume, fill_volume
