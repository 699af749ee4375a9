"""The silhouette's signed distance (standing.signed_distance_px), which the standing solids' fits and the flat
objects' prisms (body.Prism) read, against the analytic distance to a square's and a disc's outline."""
import numpy as np

from stages.reconstruct.body import Prism
from stages.reconstruct.standing import signed_distance_px

CORNER_PX = (np.sqrt(2) - 1) / 2
"""Beside a convex corner the distance to the nearest inside pixel centre, less half a pixel, overshoots the
distance to the corner by at most this (one pixel out diagonally: sqrt 2 - 1/2 against sqrt 2 / 2)."""


def pixel_centres(h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    rows, cols = np.mgrid[0:h, 0:w] + 0.5
    return rows, cols


def test_a_squares_distance_is_exact_along_its_sides():
    """The outline of pixels rows 10-24, cols 12-39 is the rectangle [12, 40] x [10, 25] of image points: every
    pixel centre inside, and outside every one whose nearest outline point lies on a side, is exactly its
    distance from that rectangle; beside the corners it is within CORNER_PX."""
    mask = np.zeros((40, 50), bool)
    mask[10:25, 12:40] = True
    rows, cols = pixel_centres(*mask.shape)
    beyond_cols = np.maximum(np.maximum(12 - cols, cols - 40), 0)
    beyond_rows = np.maximum(np.maximum(10 - rows, rows - 25), 0)
    inside = np.minimum.reduce([cols - 12, 40 - cols, rows - 10, 25 - rows])
    exact = np.where(mask, inside, -np.hypot(beyond_cols, beyond_rows))
    error = np.abs(signed_distance_px(mask) - exact)
    on_a_side = mask | (beyond_cols == 0) | (beyond_rows == 0)
    assert error[on_a_side].max() < 1e-12
    assert error[~on_a_side].max() <= CORNER_PX + 1e-12


def test_a_discs_outline_lies_midway_between_pixel_centres():
    """The pixels whose centres lie within R of a point off the grid: within 3 px of the circle the signed
    distance is the circle's, R - |p - c|, within half a pixel (the staircase), with no bias inside or outside
    (a distance measured to the nearest pixel centre across the outline is half a pixel long on either side)."""
    rows, cols = pixel_centres(96, 96)
    for radius, centre_col, centre_row in ((8.2, 40.7, 41.9), (20.0, 47.3, 48.6), (30.5, 45.1, 50.2)):
        from_centre = np.hypot(cols - centre_col, rows - centre_row)
        mask = from_centre <= radius
        error = signed_distance_px(mask) - (radius - from_centre)
        near = np.abs(radius - from_centre) < 3
        assert np.abs(error[near]).max() <= 0.5 + 1e-9
        assert abs(error[near & mask].mean()) < 0.15 and abs(error[near & ~mask].mean()) < 0.15


def test_a_prism_reads_its_face_at_the_outline():
    """A square silhouette's prism, at its slab's middle plane: a point whose image lies half a pixel either side of
    the square's left edge is (nearly) that far from the cone's side face, the plane through the camera and
    that edge; the exact distance to the plane is the reference (the prism's pixels at the point's depth are
    exact to the cosine of the face's slant, here 0.7 %)."""
    f, size = 100.0, 64
    K = np.array([[f, 0, size / 2], [0, f, size / 2], [0, 0, 1]])
    mask = np.zeros((size, size), bool)
    mask[20:44, 20:44] = True
    prism = Prism(mask, K, np.array([0.0, 0.0, 1.0]), middle=1.0, half=0.2)
    u = np.arange(16, 25) + 0.5  # pixel centres 4.5 px outside to 4.5 px inside the edge at u = 20
    z = 1.0
    points = np.stack([(u - size / 2) / f * z, np.zeros_like(u), np.full_like(u, z)], axis=1)
    slope = (20 - size / 2) / f  # the face: x = slope z
    to_face = (slope * points[:, 2] - points[:, 0]) / np.hypot(1.0, slope)  # positive outside (left of the edge)
    np.testing.assert_allclose(prism.distance(points), to_face, rtol=0.01)
