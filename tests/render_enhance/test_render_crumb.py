"""pm-render's torn solid: a torn face shows the material's crumb, not a blur of its surface's colours.

A sphere of surfels photographed as a crust: 60 % of its pixels one lit colour, 40 % that colour at half
its brightness (a crust's dark lines, its shaded side), every surfel coloured with the photograph's mean,
as a reconstruction averages them. It is filled as pm-simulate fills it, cut through by a plane turned
towards the camera and its halves moved apart (test_render_interior.torn_in_two), at 8 px a lattice
spacing, as the examples are drawn. The truth is the photograph's: the crumb is the material's lit colour,
the mean of the photograph's brighter half (here exactly the lit colour), with pores in it at bread's scale,
finer than the particles, as light as the light their cavities gather (interior.pore_shades)."""
import cv2
import numpy as np
import pytest
import torch

import splat
from stages.render.interior import GRAIN_SIGMA, LUMA, PORE_OPENINGS, crumb_colours, pore_shades
from stages.render.render import render_video

from .test_render_flow import surfel_sphere
from .test_render_interior import torn_in_two

SIZE, FOCAL = 256, 800.0
LIT = np.array([0.85, 0.6, 0.3])
LATTICE_SPACING = 0.01  # torn_in_two's fill, m


@pytest.fixture(scope="module")
def torn():
    gaussians = surfel_sphere(size=SIZE, focal=FOCAL)
    dark = np.random.default_rng(4).uniform(size=(SIZE, SIZE)) < 0.4
    gaussians.photo[:] = np.round(255 * np.where(dark[..., None], 0.5 * LIT, LIT)).astype(np.uint8)
    gaussians.colors[:] = 0.8 * LIT  # the photograph's mean: 0.6 + 0.4 / 2
    trajectories = torn_in_two(gaussians)
    assert trajectories.lattice_spacing == pytest.approx(LATTICE_SPACING)
    coarse = render_video(gaussians, trajectories, width=SIZE, device="cpu")
    # the torn faces: the render a lattice spacing nearer than the surface Gaussians alone
    G = len(gaussians.means)
    t = lambda a: torch.as_tensor(a, dtype=torch.float32)  # noqa: E731
    camera = splat.Camera(gaussians.K, gaussians.world_to_camera, SIZE, SIZE)
    surface = splat.rasterize(t(trajectories.positions[-1, :G]), t(gaussians.opacities), t(gaussians.colors), camera,
                              scales=t(gaussians.scales), rotations=t(gaussians.rotations))
    surface_distance = (surface.depth / surface.alpha.clamp_min(1e-6)).numpy()
    distance = coarse.depth[-1] / np.maximum(coarse.alpha[-1], 1e-6)
    opened = (coarse.alpha[-1] > 0.99) & (distance < surface_distance - trajectories.lattice_spacing)
    return coarse, opened


def test_crumb_colour_is_the_photograph_s_lit_half():
    """crumb_colours against the mean of each object's pixels at or above its median luma, brute force over
    a random two-object photograph (the silhouette's EDGE_PX pixels left out: a disc's erosion by a ball
    of radius 2 px, computed directly)."""
    rng = np.random.default_rng(0)
    photo = rng.integers(0, 256, (40, 60, 3)).astype(np.uint8)
    labels = np.zeros((40, 60), np.uint8)
    labels[5:35, 5:28], labels[5:35, 32:55] = 1, 2
    colours = crumb_colours(np.array([0, 1, 1]), photo, labels)
    for k, colour in ((1, colours[0]), (2, colours[1])):
        rows, cols = np.nonzero(labels == k)
        inner = [(r, c) for r, c in zip(rows, cols)
                 if all(labels[r + dr, c + dc] == k for dr in range(-2, 3) for dc in range(-2, 3)
                        if dr * dr + dc * dc <= 4)]
        pixels = np.array([photo[r, c] for r, c in inner], float) / 255
        luma = pixels @ [0.299, 0.587, 0.114]
        np.testing.assert_allclose(colour, pixels[luma >= np.median(luma)].mean(0), atol=1e-12)
    np.testing.assert_array_equal(colours[1], colours[2])


def luma_over_crumb(rgb: np.ndarray) -> np.ndarray:
    """(H, W) each pixel's luma over the lit crumb's."""
    return (rgb.astype(float) / 255) @ LUMA / (LIT @ LUMA)


def matrix_colour(rgb: np.ndarray, opened: np.ndarray) -> np.ndarray:
    """(3,) the torn faces' matrix: the median colour of their pixels at or above their median luma (the pores,
    a third of a face with their soft edges, lie in the darker half)."""
    luma = luma_over_crumb(rgb)
    return np.median(rgb[opened & (luma >= np.median(luma[opened]))].astype(float), axis=0)


def test_a_torn_face_shows_the_lit_crumb(torn):
    """The torn faces' matrix is the crumb's lit colour within 4 levels, not the surface's mean (0.8 of it: 20-50
    levels darker)."""
    coarse, opened = torn
    assert opened.sum() > 300
    matrix = matrix_colour(coarse.rgb[-1], opened)
    assert np.abs(matrix - 255 * LIT).max() <= 4, matrix


def test_a_torn_face_has_bread_s_pores(torn):
    """Bread's crumb, not a cookie's chips: the pores (4-connected spots under 0.9 of the crumb's luma) outnumber
    the particles on the face (its area over a lattice spacing's square) and the median one is under a quarter
    of a particle's picture (its grain's alpha-1/2 disc, radius 0.59 spacings); they take 5 % to a third of the
    face at under 0.85 of its luma (the matrix holds); they are no darker than the deepest cavity of the lit
    crumb (pore_shades at the least opening of PORE_OPENINGS; 95 % of the face above its luma, 0.05 spared
    for the soft edges), and warmer than the matrix as light bouncing in a cavity of its colour is: over the
    matrix, red keeps most, blue least (the pores' mean colour)."""
    coarse, opened = torn
    rgb = coarse.rgb[-1]
    luma = luma_over_crumb(rgb)
    spacing_px = FOCAL * LATTICE_SPACING  # the sphere's centre is 1 m away
    count, labels, stats, _ = cv2.connectedComponentsWithStats((opened & (luma < 0.9)).astype(np.uint8),
                                                               connectivity=4)
    assert count - 1 > opened.sum() / spacing_px ** 2, (count - 1, opened.sum() / spacing_px ** 2)
    particle_px = np.pi * (GRAIN_SIGMA * np.sqrt(2 * np.log(2)) * spacing_px) ** 2
    assert np.median(stats[1:, cv2.CC_STAT_AREA]) < particle_px / 4
    dark = float((luma[opened] < 0.85).mean())
    assert 0.05 <= dark <= 1 / 3, dark
    deepest = pore_shades(LIT[None], np.array([PORE_OPENINGS[0]]))[0] * LIT @ LUMA / (LIT @ LUMA)
    assert np.percentile(luma[opened], 5) >= deepest - 0.05, (np.percentile(luma[opened], 5), deepest)
    kept = rgb[opened & (luma < 0.85)].astype(float).mean(0) / matrix_colour(rgb, opened)
    assert kept[0] > kept[1] > kept[2], kept
