"""pm-render's grains and pores: sized from the material and the camera, not from the simulation's lattice.

The truth on sand's texture is a photograph of a granular material, scikit-image's gravel (grains about
16 px): area-averaged so that a pixel spans k grains, its brightness spreads about its local mean as a flat
layer of flowing sand drawn where a pixel spans k grains of GRAIN_DIAMETER should. The truth on a pore's
shade is light bouncing in a sphere cut open by the face, traced path by path."""
import numpy as np
import pytest
import torch

import splat
from stages.render.interior import (FINE_PER_PARTICLE, GRAIN_DIAMETER, LUMA, FineStructure, fine_features,
                                    fine_structure, grain_offsets, grain_shapes, pore_shades, undilated)
from testing.granular import gravel_texture, texture

FOCAL, SIZE, SPACING = 500.0, 96, 0.005
"""The layer's camera (px) and lattice spacing (m)."""


def sand_layer(grains_a_pixel: float) -> tuple[np.ndarray, FineStructure]:
    """(SIZE, SIZE) luma of three layers of flowing grey sand on a lattice of SPACING facing the camera, at the
    distance where a pixel spans ``grains_a_pixel`` grains of GRAIN_DIAMETER, drawn as pm-render draws them (the
    particles' hard grains, their fine grains over them); and its fine structure."""
    z = FOCAL * GRAIN_DIAMETER * grains_a_pixel
    half = SIZE / 2 * z / FOCAL + 2 * SPACING
    across = np.arange(-half, half, SPACING)
    x, y, depth = np.meshgrid(across, across, z + SPACING * np.arange(3), indexing="ij")
    points = np.stack([x.ravel(), y.ravel(), depth.ravel()], 1)
    P = len(points)
    spacing, granular = np.full(P, SPACING), np.ones(P, bool)
    shape, opacity = grain_shapes(spacing, granular)
    colours = np.full((P, 3), 0.5)
    fine = fine_structure(granular, ~granular, shape, points[:, 2], FOCAL, colours)
    camera = splat.Camera(np.array([[FOCAL, 0, SIZE / 2], [0, FOCAL, SIZE / 2], [0, 0, 1]]), np.eye(4), SIZE, SIZE)
    t = torch.as_tensor
    means = t(points + grain_offsets(spacing))
    covariances = undilated(means, t(shape), torch.ones(P, dtype=torch.float64), camera)
    bodies = splat.rasterize(means, t(opacity), means[:, 2:], camera, covariances=covariances)
    front = torch.where(bodies.alpha > 0.5, bodies.features[..., 0] / bodies.alpha, torch.nan)
    grains = fine_features(means, covariances, t(colours), torch.ones(P, dtype=torch.float64),
                           FineStructure(*(t(a) for a in fine)), front, camera)
    drawn = splat.rasterize(torch.cat([means, grains[0]]), torch.cat([t(opacity), grains[2]]),
                            torch.cat([t(colours), grains[3]]), camera, covariances=torch.cat([covariances, grains[1]]))
    return drawn.features.numpy() @ LUMA, fine


@pytest.mark.parametrize("grains_a_pixel", [1, 2, 3])
def test_sand_spreads_as_gravel_at_as_many_grains_a_pixel(grains_a_pixel):
    """At 1, 2 and 3 grains a pixel (the lattice 10, 5 and 3.3 px), the layer's texture is the gravel's within
    30 %: the grains follow the material's size and the camera, not the lattice."""
    luma, fine = sand_layer(grains_a_pixel)
    drawn, truth = texture(luma, 8), gravel_texture(grains_a_pixel)
    assert abs(drawn / truth - 1) < 0.3, (drawn, truth)
    assert np.bincount(fine.owner).max() <= FINE_PER_PARTICLE


def test_only_sand_snow_and_crumb_carry_fine_structure():
    """A particle of neither granular nor porous material (a ductile solid's) carries no grains or pores; a
    crumb's pores are no larger, at their smallest, than PORE_DIAMETERS or FINE_PX allow."""
    shape, _ = grain_shapes(np.full(3, SPACING), np.zeros(3, bool))
    fine = fine_structure(np.array([True, False, False]), np.array([False, True, False]), shape,
                          np.full(3, 0.5), FOCAL, np.full((3, 3), 0.6))
    assert set(np.unique(fine.owner)) == {0, 1}
    assert (fine.factor[fine.owner == 1] < 1).all()


def cavity_brightness(opening: float, albedo: float, paths: int = 40000, seed: int = 0) -> float:
    """Brightness of the wall of a unit sphere cut open by a plane (the cap above it, ``opening`` of the sphere's
    area, removed) under a sky of radiance 1 over the opening, against a flat face's of the same ``albedo``:
    cosine-weighted paths from points of the wall (at several heights), each bounce weighted by the albedo,
    until they leave through the opening (a chord ends in the removed cap)."""
    rng = np.random.default_rng(seed)
    top = 1 - 2 * opening  # the plane's height: the cap above it is (1 - top) / 2 of the area
    height = rng.uniform(-1, top, paths)
    angle = rng.uniform(0, 2 * np.pi, paths)
    ring = np.sqrt(1 - height ** 2)
    p = np.stack([ring * np.cos(angle), ring * np.sin(angle), height], 1)
    weight, total = np.ones(paths), np.zeros(paths)
    alive = np.ones(paths, bool)
    for _ in range(60):
        n = -p / np.linalg.norm(p, axis=1, keepdims=True)  # inward normal
        u, v = rng.uniform(size=(2, paths))
        local = np.stack([np.sqrt(u) * np.cos(2 * np.pi * v), np.sqrt(u) * np.sin(2 * np.pi * v), np.sqrt(1 - u)], 1)
        helper = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
        e1 = np.cross(n, helper)
        e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
        e2 = np.cross(n, e1)
        d = local[:, :1] * e1 + local[:, 1:2] * e2 + local[:, 2:] * n
        q = p - 2 * (p * d).sum(1, keepdims=True) * d  # the chord's far end
        leaves = alive & (q[:, 2] > top)
        total[leaves] += weight[leaves]
        alive &= ~leaves
        weight *= albedo
        p = q
    return float(total.mean())


@pytest.mark.parametrize("opening, albedo", [(0.25, 0.8), (0.5, 0.3), (0.75, 0.6)])
def test_a_pore_is_lit_as_light_bouncing_in_its_cavity(opening, albedo):
    """pore_shades against the traced cavity, within 2 %, for channels of a light and of a dark crumb."""
    shade = pore_shades(np.array([[albedo] * 3]), np.array([opening]))[0, 0]
    assert shade == pytest.approx(cavity_brightness(opening, albedo), rel=0.02)
