"""A body of revolution's top: flat at a rim the outline traces, round over a cap.

References: ray-cast shapes of known top (testing/photographs.py): a cup-like cylinder (45 mm radius, 60 mm
tall, red side, white top) whose top is flat, and a capsule (40 mm radius, 140 mm tall) whose top is a
hemisphere, its radius 0.95 of the widest 27.5 mm (0.196 of its height) below its tip. Each is photographed
and read under the same camera, pitched 35 and 55 degrees.
"""
from __future__ import annotations

import numpy as np
import pytest

from stages.reconstruct.closure import down_direction
from stages.reconstruct.geometry import intrinsics_from_fov
from stages.reconstruct.standing import Revolution, standing_solid
from testing.photographs import Capsule, PaintedCylinder, photograph, standing_axes

CENTRE = np.array([0.0, 0.0, 0.45])
WIDTH, HEIGHT = 192, 144


def top_depth(shape, pitch: float) -> tuple[Revolution, float]:
    """The body of revolution the closure fits to ``shape`` photographed by a 40-degree camera pitched
    ``pitch`` degrees, and the share of its height below its top where its radius first reaches 0.95 of its
    widest (0 for a flat top)."""
    K = intrinsics_from_fov(40, WIDTH, HEIGHT)
    mask = photograph(shape, K, np.eye(4), WIDTH, HEIGHT).mask
    solid = standing_solid(mask, K, down_direction(pitch))
    assert solid is not None and isinstance(solid.solid, Revolution)
    radii = solid.solid.radii
    return solid.solid, float(np.argmax(radii >= 0.95 * radii.max()) / len(radii))


@pytest.mark.parametrize("pitch", [35.0, 55.0])
def test_a_cup_seen_from_above_has_a_flat_top_at_its_rim(pitch):
    """The cylinder's top is a face (its rim traced along the outline), full width within 2 % of its height
    of the top (a dome fitted to its outline would reach 0.95 of the radius 0.2 of the height down)."""
    cup = PaintedCylinder(CENTRE, standing_axes(pitch), 0.045, 0.06)
    solid, depth = top_depth(cup, pitch)
    assert solid.top_face
    assert depth <= 0.02


@pytest.mark.parametrize("pitch", [35.0, 55.0])
def test_a_capsule_keeps_its_round_top(pitch):
    """The capsule's top is a dome: its radius reaches 0.95 of the widest no sooner than 0.15 of the height
    below its tip (truth 0.196), and no face is taken."""
    capsule = Capsule(CENTRE, standing_axes(pitch)[1] * 0.03, 0.04)
    solid, depth = top_depth(capsule, pitch)
    assert not solid.top_face
    assert depth >= 0.15
