"""Initial Gaussians: a closed surface around the true shape, seen without holes from every side."""
import numpy as np
import pytest
import torch
from scipy.spatial import ConvexHull

import splat
from stages.reconstruct.depth import object_depths
from stages.reconstruct.geometry import down_direction, intrinsics_from_fov
from stages.reconstruct.lift import lift_object
from stages.reconstruct.metrics import iou
from stages.reconstruct.synthetic import Capsule, photograph, side_view


@pytest.fixture(scope="module")
def lifted():
    capsule = Capsule.tilted()
    K = intrinsics_from_fov(40, 128, 96)
    photo = photograph(capsule, K, np.eye(4), 128, 96)
    depth = object_depths(photo.mask.astype(np.uint8), K, [capsule.size_m])[0]
    return capsule, K, lift_object(depth, K, photo.rgb, 0, down_direction(0.0))


def test_gaussians_are_valid_and_near_the_true_surface(lifted):
    capsule, K, g = lifted
    assert np.allclose(np.linalg.norm(g.rotations, axis=1), 1)
    assert (g.scales > 0).all() and ((g.opacities > 0) & (g.opacities <= 1)).all()
    assert (g.colors >= 0).all() and (g.colors <= 1).all() and (g.object_id == 0).all()
    distance = np.abs(capsule.signed_distance(g.means))
    pixel_m = 0.6 / K[1, 1]  # one pixel's footprint at the capsule (0.6 m away): 4.5 mm at this size
    assert np.median(distance) < 1.5 * pixel_m


@pytest.mark.parametrize("azimuth", [90, 180, 270])
def test_every_side_is_covered(lifted, azimuth):
    capsule, K, g = lifted
    camera = splat.Camera(K, side_view(capsule, azimuth), 128, 96)
    t = lambda a: torch.tensor(a, dtype=torch.float32)  # noqa: E731
    alpha = splat.rasterize(t(g.means), t(g.opacities), t(g.colors), camera, scales=t(g.scales),
                            rotations=t(g.rotations)).alpha.numpy()
    truth = photograph(capsule, K, camera.world_to_camera, 128, 96).mask
    # No holes: the back and the rim are closed. The side silhouette is only ~22 px wide at this size,
    # so a one-pixel error of the inflated rim costs several percent (benchmarks/quality.py checks the
    # optimised result at 256 px against the 0.8 target).
    assert (alpha[truth] > 0.5).mean() > 0.85
    assert iou(alpha > 0.5, truth) > 0.7


@pytest.mark.parametrize("pitch", [10.0, 30.0, 50.0])
def test_a_pitched_cameras_ball_stands_on_a_base_under_its_centre(pitch):
    """Seen from a camera pitched down, a ball's unseen back is its bottom. Closed along the rays or straight
    behind the front, its lowest points form a keel behind its centre of mass (at 10 degrees the centroid
    lies 9 mm outside their hull, seen from above); lifted, the back goes no lower than the front's lowest
    point, and the points within a pixel of that level hold the centroid a tenth of the radius inside.
    Above the base the surface is the sphere's."""
    ball = Capsule(np.array([0.0, 0.0, 0.6]), np.array([1e-6, 0.0, 0.0]), 0.06)
    K = intrinsics_from_fov(40, 128, 96)
    photo = photograph(ball, K, np.eye(4), 128, 96)
    depth = object_depths(photo.mask.astype(np.uint8), K, [ball.size_m])[0]
    down = down_direction(pitch)
    g = lift_object(depth, K, photo.rgb, 0, down)
    pixel_m = 0.6 / K[1, 1]
    across = np.linalg.svd(np.eye(3) - np.outer(down, down))[0][:, :2]  # two horizontal axes
    heights, flat = g.means @ down, g.means @ across
    base = ConvexHull(flat[heights >= heights.max() - pixel_m])
    inside = -(base.equations[:, :2] @ flat.mean(0) + base.equations[:, 2])  # distances to the hull's edges
    assert inside.min() > 0.1 * ball.radius
    assert np.median(np.abs(ball.signed_distance(g.means))) < 1.5 * pixel_m
