"""pm-render's torn solid: a torn face shows the material's crumb, not a blur of its surface's colours.

A sphere of surfels photographed as a crust: 60 % of its pixels one lit colour, 40 % that colour at half
its brightness (a crust's dark lines, its shaded side), every surfel coloured with the photograph's mean,
as a reconstruction averages them. It is filled as pm-simulate fills it, cut through by a plane turned
towards the camera and its halves moved apart (test_render_interior.torn_in_two), at 8 px a lattice
spacing, as the examples are drawn. The truth is the photograph's: the crumb is the material's lit colour,
the mean of the photograph's brighter half (here exactly the lit colour), with pores in it at the
particles' scale."""
import numpy as np
import pytest
import torch

import splat
from stages.render.interior import CREVICE_SHADE, GRAIN_SIGMA, LUMA, crumb_colours
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


def test_a_torn_face_shows_the_lit_crumb(torn):
    """The torn faces' matrix (their median colour) is the crumb's lit colour within 4 levels, not the
    surface's mean (0.8 of it: 20-50 levels darker)."""
    coarse, opened = torn
    assert opened.sum() > 300
    matrix = np.median(coarse.rgb[-1][opened].astype(float), axis=0)
    assert np.abs(matrix - 255 * LIT).max() <= 4, matrix


def test_a_torn_face_has_sharp_pores(torn):
    """Pores at the particles' scale, sharp: at least 5 % of a torn face is darker than 0.65 of the crumb's
    luma (scikit-image's gravel, a broken material, has 10 % of its pixels there, decision 0037), at most a
    third of it (the matrix holds), the darkest reach CREVICE_SHADE of it; and a pore's edge is a step:
    of the steps between horizontal neighbours on the face, the largest 5 % are at least three times the
    steepest slope (per pixel) of that contrast, 1 - CREVICE_SHADE, blurred by a lattice spacing's
    GRAIN_SIGMA (a soft grain's), erf's 1 / (sigma sqrt(2 pi))."""
    coarse, opened = torn
    luma = (coarse.rgb[-1].astype(float) / 255) @ LUMA / (LIT @ LUMA)
    dark = float((luma[opened] < 0.65).mean())
    assert 0.05 <= dark <= 1 / 3, dark
    assert np.percentile(luma[opened], 1) <= CREVICE_SHADE + 0.05
    sigma_px = GRAIN_SIGMA * FOCAL * LATTICE_SPACING  # the sphere's centre is 1 m away
    blurred_slope = (1 - CREVICE_SHADE) / (sigma_px * np.sqrt(2 * np.pi))
    steps = np.abs(np.diff(luma, axis=1))[opened[:, 1:] & opened[:, :-1]]
    assert np.percentile(steps, 95) >= 3 * blurred_slope, (np.percentile(steps, 95), blurred_slope)
