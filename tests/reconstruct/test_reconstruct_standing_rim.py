"""A photographed rim is a flat top; a large ball's or capsule's top stays round.

References: the coffee example's silhouette (scenes/coffee/mask.png, a photograph of an espresso cup, whose
rim is a flat circle), told the pitch its rim's ellipse gives (63 degrees: axis ratio 0.80 about 10 degrees
above the optical axis); and ray-cast capsules and balls of known round tops (testing/photographs.py),
photographed 100-150 px across, where a rim's allowance (standing.RIM_SHARE of its radius in pixels) is
twice the pixels' own.
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from stages.reconstruct.closure import down_direction
from stages.reconstruct.geometry import intrinsics_from_fov
from stages.reconstruct.standing import Revolution, standing_solid
from testing.photographs import Capsule, photograph, standing_axes

COFFEE = Path(__file__).resolve().parents[2] / "scenes" / "coffee" / "mask.png"
CENTRE = np.array([0.0, 0.0, 0.45])
WIDTH, HEIGHT = 384, 288


def test_a_photographed_cup_s_rim_is_a_flat_top():
    """The cup is a body of revolution whose top is a face, full width (0.8 of its widest, as the rim's
    ellipse against the widest outline shows) at its top, not a dome (0.03 of its widest radius)."""
    mask = cv2.imread(str(COFFEE), cv2.IMREAD_GRAYSCALE) > 127
    K = intrinsics_from_fov(45, mask.shape[1], mask.shape[0])
    solid = standing_solid(mask, K, down_direction(63.0))
    assert solid is not None and isinstance(solid.solid, Revolution)
    assert solid.solid.top_face
    assert solid.solid.radii[0] >= 0.75 * solid.solid.radii.max()


@pytest.mark.parametrize("pitch", [45.0, 55.0])
@pytest.mark.parametrize("half_axis", [0.03, 1e-5])
def test_a_large_capsule_or_ball_keeps_its_round_top(pitch, half_axis):
    """A capsule (40 mm radius, 60 mm between its caps' centres) and a ball (40 mm), 45 cm away in a 384 px
    picture: no face is taken at the top, whose radius is under 0.5 of the widest there."""
    shape = Capsule(CENTRE, standing_axes(pitch)[1] * half_axis, 0.04)
    K = intrinsics_from_fov(40, WIDTH, HEIGHT)
    mask = photograph(shape, K, np.eye(4), WIDTH, HEIGHT).mask
    solid = standing_solid(mask, K, down_direction(pitch))
    assert solid is not None and isinstance(solid.solid, Revolution)
    assert not solid.solid.top_face
    assert solid.solid.radii[0] < 0.5 * solid.solid.radii.max()
