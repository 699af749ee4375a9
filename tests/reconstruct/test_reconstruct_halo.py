"""The background fill leaves no outline of an object with a soft edge, against a photograph whose
background is known (reconstruct/background.py: background_hole).

A defocused or motion-blurred object's edge fades into the ground over a few pixels, and a segmentation
ends inside that fade: the fade's outer part, and a dark rim just outside, stayed in the photograph
around the hole and outlined the object's place once it moved away (the clock of a user's scene)."""
import cv2
import numpy as np
import pytest

from stages.reconstruct.background import EDGE_REACH, background_hole, dilation_px, inpaint_background
from stages.reconstruct.geometry import intrinsics_from_fov
from testing.photographs import Capsule, photograph, soft_edged

W, H = 160, 120
ROWS, COLS = np.mgrid[0:H, 0:W].astype(np.float64)


def plaster_wall() -> np.ndarray:
    """(H, W, 3) u8: a lit wall, brighter to the right, with a faint mottling (2/255)."""
    wall = 130 + 0.15 * COLS - 0.1 * ROWS + 2 * np.sin(COLS / 6.0) * np.sin(ROWS / 9.0)
    return np.clip(np.stack([wall, 0.95 * wall, 0.9 * wall], -1) + 0.5, 0, 255).astype(np.uint8)


def capsule_on(backdrop: np.ndarray, blur_px: float, rim_px: float) -> tuple[np.ndarray, np.ndarray]:
    """The tilted capsule photographed over ``backdrop`` with its edge blurred by ``blur_px`` and a dark
    frame ``rim_px`` wide, and the mask a segmentation gives it: where its blurred coverage, the dark
    frame left out, passes 0.6 (inside the edge's fade, as GrabCut's on the clock)."""
    sharp = photograph(Capsule.tilted(distance=0.7), intrinsics_from_fov(40, W, H), np.eye(4), W, H)
    photo, coverage = soft_edged(sharp, backdrop, blur_px, rim_px)
    return photo, coverage > 0.6


@pytest.mark.parametrize("blur_px, rim_px", [(2.5, 0.0), (2.0, 3.0)], ids=["blurred edge", "blurred dark rim"])
def test_the_fill_leaves_no_outline_of_a_soft_edge(blur_px, rim_px):
    """Everywhere the object changed the photograph (by more than 2/255), and so in the ring of its fade
    outside the mask, the fill must be the wall within 8/255, 2.5 on average. With the hole the mask
    dilated by a fixed 3 px the fade stayed: the ring was 4.7 off on average and up to 15 (blurred edge),
    8.0 and up to 46 (dark rim)."""
    wall = plaster_wall()
    photo, mask = capsule_on(wall, blur_px, rim_px)
    background = inpaint_background(photo, mask.astype(np.uint8))
    error = np.abs(background.astype(float) - wall).max(-1)
    changed = np.abs(photo.astype(float) - wall).max(-1) > 2
    ring = changed & ~mask
    assert ring.sum() > 500
    assert error[changed].max() <= 8, f"up to {error[changed].max():.0f}/255 off where the object stood"
    assert error[ring].mean() < 2.5, f"{error[ring].mean():.1f}/255 off on average in the ring"


def test_the_hole_keeps_the_ground_past_a_flat_gap_and_the_reach():
    """A sharp-edged object (no fade) beside a dark bar 8 px from its outline: the hole is the least
    dilation, the bar and everything past it stay as photographed. On the blurred photograph, nothing
    farther than EDGE_REACH of the object's size (and 2 px) from its mask is filled."""
    wall = plaster_wall()
    sharp = photograph(Capsule.tilted(distance=0.7), intrinsics_from_fov(40, W, H), np.eye(4), W, H)
    away = cv2.distanceTransform((~sharp.mask).astype(np.uint8), cv2.DIST_L2, 5)
    bar = (away > 8) & (away < 12) & (ROWS < H / 2)
    ground = np.where(bar[..., None], wall // 3, wall)
    photo = np.where(sharp.mask[..., None], sharp.rgb, ground).astype(np.uint8)
    hole = background_hole(photo, sharp.mask.astype(np.uint8)) > 0
    least = cv2.dilate(sharp.mask.astype(np.uint8), cv2.getStructuringElement(
        cv2.MORPH_ELLIPSE, (2 * dilation_px(H, W) + 1,) * 2)) > 0
    assert (hole == least).all(), f"{(hole & ~least).sum()} pixels past the least dilation"
    background = inpaint_background(photo, sharp.mask.astype(np.uint8))
    assert (background[bar] == photo[bar]).all()

    blurred, mask = capsule_on(wall, 2.5, 3.0)
    reach = EDGE_REACH * np.sqrt(mask.sum())
    hole = background_hole(blurred, mask.astype(np.uint8)) > 0
    from_mask = cv2.distanceTransform((~mask).astype(np.uint8), cv2.DIST_L2, 5)
    assert from_mask[hole].max() <= reach + 2  # the width rounded up, and the margin of a pixel
