"""A handle beside a standing solid hangs from it, never below its base.

Reference: a ray-cast upright cylinder (testing/photographs.UprightCylinder) photographed from 55 degrees
above, a disc drawn onto its silhouette below its front rim's lowest point: a handle pointing at the camera,
as the coffee example's cup shows. The cylinder's base height is known from the shape itself; a handle
whose balls stood on the vertical plane through the cylinder's middle would hang below it (what a camera
looking down shows below the base is nearer, not lower).
"""
from __future__ import annotations

import numpy as np

from stages.reconstruct.body import Balls
from stages.reconstruct.closure import down_direction, object_depths
from stages.reconstruct.geometry import intrinsics_from_fov
from testing.photographs import UprightCylinder, photograph, standing_axes

WIDTH, HEIGHT, FOV, PITCH = 256, 192, 40.0, 55.0
HANDLE_PX = 9
"""The handle's radius in pixels: a fifth of the cylinder's width in the picture."""


def test_a_handle_below_a_standing_solid_in_the_picture_does_not_hang_below_its_base():
    """The handle's balls reach no lower than the cylinder's true base (within a pixel's footprint), and the
    body's lowest depth sample is no lower either: it stands on the cylinder's base, not on the handle."""
    cylinder = UprightCylinder(np.array([0.0, 0.0, 0.45]), standing_axes(PITCH), 0.045, 0.06)
    K = intrinsics_from_fov(FOV, WIDTH, HEIGHT)
    mask = photograph(cylinder, K, np.eye(4), WIDTH, HEIGHT).mask
    rows, cols = np.nonzero(mask)
    bottom, middle = rows.max(), 0.5 * (cols.min() + cols.max())
    grid_rows, grid_cols = np.mgrid[0:HEIGHT, 0:WIDTH]
    handle = np.hypot(grid_rows - (bottom + 2), grid_cols - (middle - 12)) < HANDLE_PX
    assert (handle & ~mask).sum() > 100, "the handle must stand out of the cylinder's silhouette"
    down = down_direction(PITCH)
    depth = object_depths((mask | handle).astype(np.uint8), K, [2 * cylinder.radius], PITCH)[0]

    base = float((cylinder.centre - 0.5 * cylinder.height * cylinder.axes[1]) @ down)  # camera frame, downwards
    footprint = 0.45 / K[0, 0]
    balls = [part for part in depth.body.parts if isinstance(part, Balls)]
    assert len(balls) == 1, "the handle keeps balls of its own"
    lowest_ball = float(np.max(balls[0].centres @ down + balls[0].radii))
    assert lowest_ball <= base + footprint, f"the handle hangs {1e3 * (lowest_ball - base):.1f} mm below the base"

    pixels = depth.pixels
    rays = np.stack([grid_cols + 0.5, grid_rows + 0.5, np.ones(mask.shape)], -1)[pixels] @ np.linalg.inv(K).T
    lowest = max(float(np.max(rays @ down * depth.front[pixels])), float(np.max(rays @ down * depth.back[pixels])))
    assert lowest <= base + footprint, f"the body reaches {1e3 * (lowest - base):.1f} mm below the base"
