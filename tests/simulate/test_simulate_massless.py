"""Massless particles (the Gaussians riding on a body's solid) move with the material they belong to, also
where no node of their stencil carries mass: a piece torn or flung from its body carries its Gaussians along.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from schemas import materials as M
from schemas.scene import PhysicsConfig
from schemas.solid import SolidGrid, gravity_axes
from stages.simulate.mpm import GROUND_NONE, Grid, Ground, MPMSolver, anchors
from stages.simulate.simulation import Simulation
from testing.particles import box_surface

G = 9.81


def lattice(lo, hi, spacing: float) -> np.ndarray:
    """Points (N,3) of the cubic lattice of `spacing` m in the box [lo, hi] m, half a spacing inside its faces."""
    axes = [np.arange(a + 0.5 * spacing, b, spacing) for a, b in zip(lo, hi)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)


def box_solid(centre: np.ndarray, half: np.ndarray, nodes: int = 40) -> SolidGrid:
    """The signed distance of the box centre +- half (m) on a grid aligned with default gravity, as
    pm-reconstruct passes a solid on."""
    spacing = 2.4 * half.max() / (nodes - 1)
    ijk = np.stack(np.meshgrid(*[np.arange(nodes)] * 3, indexing="ij"), axis=-1) - 0.5 * (nodes - 1)
    q = np.abs(ijk * spacing) - half
    distance = np.linalg.norm(np.maximum(q, 0.0), axis=-1) + np.minimum(q.max(axis=-1), 0.0)
    return SolidGrid(distance, np.asarray(centre, float), gravity_axes(np.array([0.0, 1.0, 0.0])), spacing)


def pieces(points: np.ndarray, link: float) -> np.ndarray:
    """(N,) label of the connected piece of each point, linking points closer than `link` m."""
    pairs = cKDTree(points).query_pairs(link, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(points),) * 2)
    return connected_components(graph, directed=False)[1]


def test_anchors_are_the_nearest_particle_with_mass_of_the_same_object():
    """Brute force: each massless particle's anchor is its nearest massive particle of its object, ties aside;
    massive particles and an object with no mass get none (-1)."""
    rng = np.random.default_rng(0)
    x = rng.uniform(0, 1, (300, 3))
    masses = np.where(rng.uniform(size=300) < 0.5, 0.0, 1.0)
    objects = rng.integers(0, 3, 300)
    masses[objects == 2] = 0.0
    got = anchors(x, masses, objects)
    for p in range(300):
        own = np.flatnonzero((objects == objects[p]) & (masses > 0))
        if masses[p] > 0 or objects[p] == 2:
            assert got[p] == -1
        else:
            assert got[p] == own[np.argmin(np.linalg.norm(x[own] - x[p], axis=1))]


@pytest.mark.parametrize("material", [M.Jelly(youngs_modulus=5e4), M.Sand(), M.Fracture(youngs_modulus=5e4)],
                         ids=lambda m: m.preset)
def test_massless_particles_beyond_every_stencil_fall_with_their_body(device, material):
    """A 6 cm cube of massive particles falls freely (no ground) for 0.1 s; massless particles 3.5 cells off
    three of its faces, so that no node of their stencils ever carries mass, fall with it: each moves
    g t^2 / 2 down (MPM's free fall is exact for a uniform field) within 2 % of the drop, a tenth of a cell,
    and keeps its distance to its nearest massive particle within 2 % of a cell. Without the anchor they keep
    their own velocity, 0 at the start, and hang where they were."""
    dx, dt, steps = 0.01, 2e-4, 500
    spacing = 0.5 * dx
    body = lattice((0.2, 0.4, 0.2), (0.26, 0.46, 0.26), spacing)
    off = 3.5 * dx  # beyond the 1.5 cells a stencil reaches on either side of a node
    a, b = np.meshgrid(np.linspace(0.2, 0.26, 7), np.linspace(0.4, 0.46, 7), indexing="ij")
    a, b = a.ravel(), b.ravel()
    riders = np.concatenate([np.stack([np.full_like(a, 0.26 + off), b, a], 1),  # +x face
                             np.stack([np.full_like(a, 0.2 - off), b, a], 1),  # -x face
                             np.stack([a, b, np.full_like(a, 0.26 + off)], 1)])  # +z face
    x = np.concatenate([body, riders])
    volumes = np.concatenate([np.full(len(body), spacing ** 3), np.zeros(len(riders))])
    solver = MPMSolver(Grid((0.0, 0.0, 0.0), dx, (48, 64, 48)), x, material.density * volumes, volumes,
                       np.zeros(len(x), int), [material], np.array([0.0, -G, 0.0]), Ground(GROUND_NONE),
                       device=device)
    try:
        for _ in range(steps):
            solver.substep(dt)
        now = solver.x.numpy().astype(np.float64)
    finally:
        solver.close()
    drop = 0.5 * G * (steps * dt) ** 2
    moved = now - x
    body_moved = moved[:len(body)].mean(0)
    np.testing.assert_allclose(body_moved, [0.0, -drop, 0.0], atol=0.02 * drop)  # the body itself falls freely
    np.testing.assert_allclose(moved[len(body):], np.tile([0.0, -drop, 0.0], (len(riders), 1)), atol=0.02 * drop)
    gap = lambda points, solid: np.min(np.linalg.norm(points[:, None] - solid[None], axis=-1), axis=1)
    np.testing.assert_allclose(gap(now[len(body):], now[:len(body)]), gap(riders, body), atol=0.02 * dx)


def test_the_gaussians_of_a_torn_loaf_stay_on_its_pieces(device):
    """A 20 x 6 x 6 cm fracture bar on the ground, its Gaussians massless on its surface (1 mm either side),
    its outer quarters pulled apart at 0.15 m/s for 0.4 s (the loaf example), tears into three pieces; every
    Gaussian keeps its distance to the nearest particle with mass within half a cell of what it was at rest,
    including those whose stencils hold no mass once the pieces part."""
    centre, half = np.array([0.0, 0.0, 0.5]), np.array([0.1, 0.03, 0.03])
    means = box_surface(centre - half, centre + half, 0.004)
    means += np.random.default_rng(1).uniform(-0.001, 0.001, means.shape)
    pull = [{"type": "velocity", "region": {"box": box}, "velocity": [speed, 0, 0], "end_s": 0.4}
            for box, speed in (([0, 0, 0, 0.25, 1, 1], -0.15), ([0.75, 0, 0, 1, 1, 1], 0.15))]
    physics = PhysicsConfig(duration_s=0.5, fps=24, grid=24, ground={"type": "friction", "friction": 0.5},
                            conditions=pull)
    sim = Simulation(physics, [M.Fracture(youngs_modulus=2.5e4, density=300)], means, np.zeros(len(means), int),
                     solids=[box_solid(centre, half)], device=device)
    tr = sim.run()
    massless = tr.masses <= 0
    assert massless.sum() == len(means)
    solid = tr.positions[-1][~massless]
    assert np.bincount(pieces(solid, 1.5 * sim.spacing)).size == 3  # the bar tore where the loaf tears
    gap = [cKDTree(x[~massless]).query(x[massless])[0] for x in tr.positions]
    assert np.max(np.array(gap) - gap[0]) < 0.5 * sim.grid.dx
