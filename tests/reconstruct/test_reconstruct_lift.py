"""Initial Gaussians: a closed surface around the true shape, seen without holes from every side."""
import numpy as np
import pytest
import torch

import splat
from stages.reconstruct.closure import object_depths
from stages.reconstruct.geometry import intrinsics_from_fov
from stages.reconstruct.lift import lift_object
from stages.reconstruct.metrics import iou
from testing.photographs import Capsule, photograph, side_view


@pytest.fixture(scope="module")
def lifted():
    capsule = Capsule.tilted()
    K = intrinsics_from_fov(40, 128, 96)
    photo = photograph(capsule, K, np.eye(4), 128, 96)
    depth = object_depths(photo.mask.astype(np.uint8), K, [capsule.size_m], 0.0)[0]
    return capsule, K, lift_object(depth, K, photo.rgb, 0)[0]


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
