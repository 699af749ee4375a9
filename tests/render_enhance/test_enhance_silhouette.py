"""pm-enhance draws no halo around an object at rest: a ray-cast capsule whose Gaussians reach two pixels
past its mask, as a reconstruction's silhouette Gaussians do, shows the photograph beside it, not the fringe."""
import cv2
import numpy as np
import pytest
from scipy import ndimage

from schemas.artifacts import GaussiansArtifact, TrajectoriesArtifact
from schemas.camera import pixel_rays
from schemas.solid import solid_fields
from stages.enhance.flow import enhance_frames
from stages.reconstruct.geometry import intrinsics_from_fov
from stages.render.render import render_video
from testing.photographs import Capsule, photograph

W, H, FRINGE_PX = 64, 48, 2
BACKDROP = 115  # testing.photographs' grey


def fringed_gaussians() -> tuple[GaussiansArtifact, np.ndarray]:
    """One Gaussian per pixel of the capsule's mask and of a FRINGE_PX ring beyond it, on the pixel's ray
    at the nearest mask pixel's distance and with its colour; and the photograph's mask (H, W) bool."""
    K = intrinsics_from_fov(40.0, W, H)
    shot = photograph(Capsule.tilted(distance=0.5), K, np.eye(4), W, H)
    ring = outside_band(shot.mask, 0.0, FRINGE_PX) | shot.mask
    _, (near_rows, near_cols) = ndimage.distance_transform_edt(~shot.mask, return_indices=True)
    rows, cols = np.nonzero(ring)
    src = near_rows[rows, cols], near_cols[rows, cols]
    distance = shot.distance[src]
    means = pixel_rays(K, H, W)[rows, cols] * distance[:, None]  # unit rays
    pixel = means[:, 2] / K[0, 0]
    n = len(rows)
    gaussians = GaussiansArtifact(
        K=K, world_to_camera=np.eye(4), width=W, height=H, means=means,
        scales=np.stack([0.5 * pixel, 0.5 * pixel, 0.05 * pixel], 1), rotations=np.tile([1.0, 0, 0, 0], (n, 1)),
        opacities=np.ones(n), colors=shot.rgb[src] / 255.0, object_id=np.zeros(n), photo=shot.rgb,
        mask=shot.mask.astype(np.uint8), background=np.full((H, W, 3), BACKDROP, np.uint8),
        depth_prior=np.where(shot.mask, shot.distance, np.nan), **solid_fields([None]), loss=np.zeros((0, 1)),
        loss_terms=["none"])
    return gaussians, shot.mask


def at_rest(gaussians: GaussiansArtifact) -> TrajectoriesArtifact:
    """One frame: every Gaussian where it is, F the identity."""
    G, zeros = len(gaussians.means), np.zeros(1)
    return TrajectoriesArtifact(
        rest_positions=gaussians.means, volumes=np.ones(G), masses=np.ones(G), material_id=np.zeros(G),
        object_id=np.zeros(G), is_gaussian=np.ones(G, bool), positions=gaussians.means[None],
        F=np.tile(np.eye(3), (1, G, 1, 1)), time_s=zeros, substeps=zeros, kinetic_energy=zeros,
        potential_energy=zeros, momentum=np.zeros((1, 3)), angular_momentum=np.zeros((1, 3)), max_speed=zeros,
        lattice_spacing=0.01, fps=8.0, duration_s=0.0)


@pytest.fixture(scope="module")
def run():
    gaussians, mask = fringed_gaussians()
    coarse = render_video(gaussians, at_rest(gaussians), width=W, device="cpu")
    return gaussians, mask, coarse, enhance_frames(coarse, gaussians, threshold=0.5)


def outside_band(mask: np.ndarray, nearest_px: float = 0.0, farthest_px: float = 3.0) -> np.ndarray:
    """(H, W) bool: the pixels outside the mask more than nearest_px and at most farthest_px from it."""
    distance = cv2.distanceTransform((~mask).astype(np.uint8), cv2.DIST_L2, 5)
    return ~mask & (distance > nearest_px) & (distance <= farthest_px)


def test_frame0_beside_the_silhouette_is_the_photograph(run):
    """Within 3 px outside the silhouette frame 0 is the photograph within 3 levels, although the render
    covers most of that band with the fringe's object colours."""
    gaussians, mask, coarse, frames = run
    band = outside_band(mask)
    assert (coarse.alpha[0][band] > 0.5).sum() > 0.5 * band.sum()  # the fringe is there to be shown
    error = np.abs(frames[0][band].astype(int) - gaussians.photo[band].astype(int)).max(-1)
    assert error.max() <= 3, f"{(error > 3).sum()} of {band.sum()} pixels off by up to {error.max()} levels"


def test_the_diffusion_backends_frame0_beside_the_silhouette_is_the_photograph(run):
    """The diffusion backend's blended frames, which it inverts and reads its Canny control from, composite the
    render over the same backdrop: within 3 px outside the silhouette frame 0 is the photograph within 3 levels."""
    from stages.enhance.diffusion.pipeline import blended_frames

    gaussians, mask, coarse, _ = run
    band = outside_band(mask)
    blended = blended_frames(coarse, gaussians)
    error = np.abs(blended[0][band].astype(int) - gaussians.photo[band].astype(int)).max(-1)
    assert error.max() <= 3, f"{(error > 3).sum()} of {band.sum()} pixels off by up to {error.max()} levels"
