"""Camera helpers: intrinsics from the vertical fov, pixel centres, orbit cameras."""
import math

import numpy as np
import pytest

from schemas.camera import pixel_rays
from stages.reconstruct.geometry import intrinsics_from_fov, orbit_world_to_camera, working_size


def test_vertical_fov_spans_the_image_height():
    K = intrinsics_from_fov(60, 200, 100)
    top = np.linalg.inv(K) @ [100, 0, 1]
    assert math.degrees(2 * math.atan(-top[1])) == pytest.approx(60)
    assert K[0, 2] == 100 and K[1, 2] == 50


def test_pixel_ray_passes_through_the_pixel_centre():
    K = intrinsics_from_fov(40, 8, 6)
    ray = pixel_rays(K, 6, 8)[2, 5]
    uv = K @ ray
    assert uv[:2] / uv[2] == pytest.approx([5.5, 2.5])


def test_orbit_by_90_degrees_looks_at_the_centre_from_the_right():
    centre = np.array([0.1, 0.0, 2.0])
    w2c = orbit_world_to_camera(centre, 90)
    position = -w2c[:3, :3].T @ w2c[:3, 3]
    # the camera's offset from the centre, (-0.1, 0, -2), turned by 90 degrees about y towards +x
    assert position == pytest.approx([2.1, 0.0, 1.9])
    # the orbit keeps the centre where the input camera saw it
    assert (w2c[:3, :3] @ centre + w2c[:3, 3]) == pytest.approx(centre)
    assert np.linalg.det(w2c[:3, :3]) == pytest.approx(1)
    assert orbit_world_to_camera(centre, 0) == pytest.approx(np.eye(4))


def test_working_size_keeps_the_longest_side_and_never_upsamples():
    assert working_size(640, 480, 256) == (256, 192)
    assert working_size(100, 50, 256) == (100, 50)
