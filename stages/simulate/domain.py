"""Gravity, the simulation frame, the grid that covers the expected motion, and the CFL substep.

World = the input camera frame (x right, y down, z forward). The simulation
runs in a rotated copy of it, x_sim = Q x_world, whose +y points *up*
(against gravity), so the ground is a grid plane and walls are grid faces.

Condition vectors and regions are read in the gravity-aligned frame unless a
condition says `frame: camera`: x the picture's right made horizontal, y down
along gravity, z horizontal away from the camera (`gravity_frame`); with a
level camera it is the camera frame.
"""
from __future__ import annotations

import math

import numpy as np

from schemas.solid import gravity_axes

from .constitutive import SNOW_HARDENING_MAX, wave_speed
from .mpm import BOUNDARY_NODES, Grid

STANDARD_GRAVITY = 9.81  # m/s^2
# Substep = CFL * dx / (wave speed + particle speed): explicit MLS-MPM is stable well below 1.
CFL = 0.4


def world_gravity(gravity: tuple | None, pitch_deg: float) -> np.ndarray:
    """Gravity in the world (camera) frame, m/s^2.

    None: 9.81 m/s^2 down in the picture (+y) for a level camera. A camera
    pitched down by p looks partly along gravity, so gravity turns about the
    camera's x axis toward its forward axis: g (0, cos p, sin p).
    """
    if gravity is not None:
        return np.asarray(gravity, dtype=np.float64)
    p = math.radians(pitch_deg)
    return STANDARD_GRAVITY * np.array([0.0, math.cos(p), math.sin(p)])


def simulation_rotation(down: np.ndarray) -> np.ndarray:
    """Rotation Q (3,3), x_sim = Q x_world, taking the unit `down` direction to -y_sim: the axes the
    reconstruction's solids are sampled along (schemas.solid.gravity_axes)."""
    return gravity_axes(down)


def down_direction(gravity_world: np.ndarray, pitch_deg: float) -> np.ndarray:
    """Unit vector of 'down': along gravity, or the camera's default when gravity is zero."""
    norm = np.linalg.norm(gravity_world)
    if norm > 0:
        return gravity_world / norm
    return world_gravity(None, pitch_deg) / STANDARD_GRAVITY


def gravity_frame(Q: np.ndarray) -> np.ndarray:
    """Rotation (3,3) whose rows are the gravity-aligned axes in the world frame: x the simulation's
    (the picture's right, horizontal), y down, z = x cross y (horizontal, away from the camera)."""
    return np.diag([1.0, -1.0, -1.0]) @ Q


def condition_frame(condition, gravity_frame_rows: np.ndarray) -> np.ndarray:
    """Rotation (3,3) taking world vectors into the frame a condition is written in (rows: its axes in
    the world frame): the gravity-aligned frame, or the camera's (the world's) with `frame: camera`."""
    return np.eye(3) if condition.frame == "camera" else gravity_frame_rows


def _margins(size: float, ground: bool, walls: bool) -> tuple[np.ndarray, np.ndarray]:
    """Room (m, below and above along each axis) around objects of `size` m for them to deform: half
    their size on each side (a heap spreads, a body tips over), a quarter above and, without a ground,
    below; with walls a quarter all round (the walls are its faces)."""
    low = np.full(3, 0.25 * size if walls else 0.5 * size)
    high = low.copy()
    high[1] = low[1] = 0.25 * size
    if ground:
        low[1] = 0.0
    return low, high


def cell_size(points_sim: np.ndarray, cells: int, *, ground: bool, walls: bool) -> float:
    """Cell size in m of a grid of `cells` cells along the longest side of the domain around the points
    (N,3, simulation frame, m) with room for them to deform (`fit_grid`).

    Travel needs no room: without walls the grid follows the particles by whole cells
    (mpm.MPMSolver.follow), so the cell size is set by the objects alone and a fast condition
    cannot dilute the resolution."""
    lo, hi = points_sim.min(axis=0), points_sim.max(axis=0)
    low, high = _margins(float(max(hi - lo)), ground, walls)
    return float(max((hi - lo) + low + high)) / cells


def fit_grid(rest_sim: np.ndarray, dx: float, *, ground_y: float | None, walls: bool,
             centre: np.ndarray | None = None) -> Grid:
    """Grid of `dx` m cells over the rest particles with room for them to deform (`cell_size`).

    Args:
        rest_sim: (P,3) rest positions in the simulation frame, m.
        dx: cell size, m.
        ground_y: height of the ground plane (simulation frame, m; the lowest rest point), or None
            without a ground.
        walls: close the domain tightly around the objects.
        centre: (3,) m, a point the node planes across the ground pass through (the fill lattice's
            centre, fill.fill_object), or None.

    The ground lies exactly on a node plane. Node planes through the fill's centre make the nodes
    under a mirror-symmetric body mirror-symmetric too: its contact with the ground has no lever about
    its centre, and a ball bouncing straight up on slip ground gathers no spin from the grid.
    """
    lo, hi = rest_sim.min(axis=0), rest_sim.max(axis=0)
    margin_lo, margin_hi = _margins(float(max(hi - lo)), ground_y is not None, walls)
    origin = lo - margin_lo - BOUNDARY_NODES * dx
    if centre is not None:
        origin = centre - np.ceil((centre - origin) / dx - 1e-9) * dx
    if ground_y is not None:  # the ground on a node plane, the points below it (its contact patch) on the grid
        origin[1] = ground_y - (BOUNDARY_NODES + math.ceil((ground_y - lo[1]) / dx - 1e-9)) * dx
    shape = np.ceil((hi + margin_hi - origin) / dx - 1e-9).astype(int) + BOUNDARY_NODES + 1
    return Grid(origin=tuple(float(o) for o in origin), dx=dx, shape=tuple(int(n) for n in shape))


def cfl_substep(dx: float, materials: list, max_speed: float, longest: float = math.inf,
                stiffening: float = SNOW_HARDENING_MAX) -> float:
    """Largest stable substep in s: CFL * dx / (fastest elastic wave + fastest particle, m/s), and at most
    `longest` s, which is all that bounds it where nothing can move (rigid bodies, no gravity, no condition:
    no wave and no speed). Snow's wave is that of its moduli times `stiffening` (constitutive.wave_speed)."""
    speed = max(wave_speed(m, stiffening) for m in materials) + max_speed
    return min(longest, CFL * dx / speed) if speed > 0 else longest
