"""Depth prior: the inflation against analytic shapes and a ray-cast perspective sphere."""
import numpy as np
import pytest

from stages.reconstruct.depth import depth_prior_image, inflation_half_thickness, object_depths
from stages.reconstruct.geometry import intrinsics_from_fov, pixel_rays


def disc(height, width, centre, radius):
    rows, cols = np.mgrid[:height, :width] + 0.5
    return (cols - centre[0]) ** 2 + (rows - centre[1]) ** 2 < radius ** 2


def test_inflation_of_a_disc_is_a_hemisphere():
    radius = 30.0
    mask = disc(80, 80, (40, 40), radius)
    half = inflation_half_thickness(mask)
    rows, cols = np.mgrid[:80, :80] + 0.5
    r = np.hypot(cols - 40, rows - 40)
    sphere = np.sqrt(np.maximum(radius ** 2 - r ** 2, 0))
    inner = r < radius - 3  # away from the pixelated rim
    assert np.median(np.abs(half[inner] - sphere[inner])) < 1.5
    assert half[~mask].max() == 0


def test_inflation_of_a_bar_has_round_cross_sections_of_its_own_width():
    mask = np.zeros((60, 120), bool)
    mask[20:40, 10:110] = True  # 20 px wide: radius 10
    half = inflation_half_thickness(mask)
    column = half[20:40, 60]
    assert column.max() == pytest.approx(10, abs=1.0)
    offsets = np.arange(20, 40) + 0.5 - 30
    assert np.abs(column - np.sqrt(np.maximum(100 - offsets ** 2, 0))).max() < 1.6


def test_sphere_prior_is_close_to_a_ray_cast_sphere_and_has_size_m():
    height, width, radius_m, distance = 96, 128, 0.15, 1.0
    K = intrinsics_from_fov(40, width, height)
    rays = pixel_rays(K, height, width)
    centre = np.array([0.05, -0.02, distance])
    b = rays @ centre
    disc_term = b ** 2 - (centre @ centre - radius_m ** 2)
    mask = disc_term > 0
    truth = b - np.sqrt(np.where(mask, disc_term, 0))
    depths = object_depths(mask.astype(np.uint8), K, [2 * radius_m])
    thickness = np.nanmax(depths[0].back) - np.nanmin(depths[0].front)
    assert thickness == pytest.approx(2 * radius_m, rel=0.07)  # the silhouette is 40 px: +-1 px each side
    prior = depth_prior_image(depths, K)
    assert np.isnan(prior[~mask]).all() and np.isfinite(prior[mask]).all()
    # the 40-pixel silhouette measures its extent to about a pixel: 2-3 % in distance
    assert np.median(np.abs(prior[mask] - truth[mask]) / truth[mask]) < 0.03
    assert (depths[0].back[mask] >= depths[0].front[mask]).all()
