"""Interior filling: particles for an object's volume from its surface Gaussians.

The Gaussians of a reconstruction sit on the object's surface (front lifted,
back closed). Their means mark a shell of occupied cells on a grid of the
simulation's cell size; a cell is inside when rays cast along the six axis
directions cross the shell an odd number of times in a majority of them
(ray parity, robust to a few holes in the shell). Shell and inside cells get a
regular lattice of particles; every cell's volume is shared equally by all
particles in it, Gaussians included, so the body's mass is density times its
occupied volume however the Gaussians cluster. The surface cuts through the
cells on the outside of the occupancy, so those count half their volume.

Time and memory are O(G + cells) on a grid no larger than the simulation's,
whatever the Gaussians' covariances (only their means are used).
"""
from __future__ import annotations

import numpy as np
from scipy.ndimage import binary_erosion

# Inside when at least this many of the six axis rays see odd parity.
INSIDE_VOTES = 4


def shell_cells(points: np.ndarray, origin: np.ndarray, dx: float, shape: tuple[int, int, int]) -> np.ndarray:
    """Boolean occupancy (shape) of the cells that contain at least one point."""
    idx = np.clip(np.floor((points - origin) / dx).astype(np.int64), 0, np.array(shape) - 1)
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
    origin = means.min(axis=0) - dx  # one empty cell of padding: rays start outside
    shape = tuple(int(n) for n in np.ceil((means.max(axis=0) - origin) / dx).astype(int) + 2)
    shell = shell_cells(means, origin, dx, shape)
    occupied = shell | inside_by_ray_parity(shell)

    n = max(1, int(round(particles_per_cell ** (1.0 / 3.0))))
    offsets = (np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), -1).reshape(-1, 3) + 0.5) / n
    cells = np.argwhere(occupied)  # C-order: particles of neighbouring cells stay close in memory
    fill = origin + dx * (cells[:, None, :] + offsets[None, :, :]).reshape(-1, 3)

    # share each cell's volume among all particles in it
    gauss_cell = np.clip(np.floor((means - origin) / dx).astype(np.int64), 0, np.array(shape) - 1)
    count = occupied.astype(np.int64) * len(offsets)
    np.add.at(count, tuple(gauss_cell.T), 1)
    cell_volume = dx ** 3 * np.where(occupied & ~binary_erosion(occupied), 0.5, 1.0)
    per_particle = cell_volume / np.maximum(count, 1)
    gaussian_volume = per_particle[tuple(gauss_cell.T)]
    fill_volume = np.repeat(per_particle[tuple(cells.T)], len(offsets))
    return fill, gaussian_volume, fill_volume
