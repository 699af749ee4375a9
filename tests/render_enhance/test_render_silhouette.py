"""pm-render draws an object no further than its photograph's mask: the Gaussians a reconstruction fits to
the silhouette's mixed pixels, which reach past it, are narrowed to a pixel beyond it, so that a moving
object carries no fringe."""
import cv2
import numpy as np
import torch

import splat
from schemas.artifacts import TrajectoriesArtifact
from stages.render.render import render_video
from stages.render.silhouette import SILHOUETTE_TOLERANCE_PX, TENTH_SIGMAS, narrowed_to_mask

from .test_enhance_silhouette import H, W, fringed_gaussians
from .test_render_flow import turned_sphere


def test_a_narrowed_gaussian_stays_within_a_pixel_of_the_mask():
    """Random anisotropic Gaussians about a disc's edge, against a float64 brute force over the picture: after
    narrowing, each one's alpha over its opacity as splat draws it, o' exp(-d^T (f^2 S + 0.3 I)^-1 d / 2) (S its
    projected covariance, from its own pinhole derivative, o' its opacity factor), at every pixel centre more
    than SILHOUETTE_TOLERANCE_PX past the disc's edge (half a pixel more from its pixels' centres) is at most a
    tenth (TENTH_SIGMAS), and within 2 % of a tenth where it was narrowed (no narrower than needed), unless its
    centre's own pixel lies beyond (then its opacity is 0); many keep their size exactly, many are narrowed,
    none grows."""
    size, focal = 80, 100.0
    K = np.array([[focal, 0, size / 2], [0, focal, size / 2], [0, 0, 1]])
    camera = splat.Camera(K, np.eye(4), size, size)
    rows, cols = np.mgrid[0:size, 0:size] + 0.5
    disc = (cols - 40) ** 2 + (rows - 40) ** 2 < 25 ** 2
    rng = np.random.default_rng(7)
    n = 300
    angle, radius = rng.uniform(0, 2 * np.pi, n), rng.uniform(15, 30, n)
    px = np.stack([40 + radius * np.cos(angle), 40 + radius * np.sin(angle)], 1)
    depth = rng.uniform(0.9, 1.1, n)
    means = np.c_[(px - size / 2) / focal * depth[:, None], depth]
    axes = rng.normal(size=(n, 3, 3))
    covariances = np.einsum("nij,nkj->nik", axes, axes) * (rng.uniform(0.5, 4.0, (n, 1, 1)) * depth[:, None, None]
                                                           / focal) ** 2 / 3
    factor, fade = (f.numpy() for f in narrowed_to_mask(torch.as_tensor(means), torch.as_tensor(covariances),
                                                        np.zeros(n, int), disc.astype(np.uint8), camera))
    assert (factor <= 1).all() and (factor >= 0).all() and (fade <= 1).all() and (fade >= 0).all()
    beyond = cv2.distanceTransform((~disc).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE) > (
        SILHOUETTE_TOLERANCE_PX + 0.5)
    tenth = np.exp(-TENTH_SIGMAS ** 2 / 2)
    points = np.stack([cols, rows], -1)
    for m, C, f, o in zip(means, covariances, factor, fade):
        x, y, z = m
        J = np.array([[focal / z, 0, -focal * x / z ** 2], [0, focal / z, -focal * y / z ** 2]])
        d = points - (focal * m[:2] / z + size / 2)
        drawn_covariance = f * f * J @ C @ J.T + 0.3 * np.eye(2)
        drawn = o * np.exp(-0.5 * np.einsum("...i,ij,...j->...", d, np.linalg.inv(drawn_covariance), d))
        assert drawn[beyond].max() <= tenth * (1 + 1e-6)
        centre_pixel = (int(np.floor(focal * x / z + size / 2)), int(np.floor(focal * y / z + size / 2)))
        if beyond[centre_pixel[1], centre_pixel[0]]:
            assert o == 0  # none of the object
        elif f < 1:
            assert drawn[beyond].max() >= 0.98 * tenth
    assert (factor == 1).sum() > 50 and (factor < 1).sum() > 50


def shifted_right(gaussians, shift_px: float) -> TrajectoriesArtifact:
    """Two frames: at rest, then every Gaussian moved right by shift_px pixels at its own depth; F the identity."""
    G = len(gaussians.means)
    per_pixel = gaussians.means[:, 2] / gaussians.K[0, 0]
    positions = np.stack([gaussians.means, gaussians.means + np.outer(shift_px * per_pixel, [1.0, 0, 0])])
    zeros = np.zeros(2)
    return TrajectoriesArtifact(
        rest_positions=gaussians.means, volumes=np.ones(G), masses=np.ones(G), material_id=np.zeros(G),
        object_id=np.zeros(G), is_gaussian=np.ones(G, bool), positions=positions,
        F=np.tile(np.eye(3), (2, G, 1, 1)), time_s=np.array([0.0, 0.125]), substeps=zeros, kinetic_energy=zeros,
        potential_energy=zeros, momentum=np.zeros((2, 3)), angular_momentum=np.zeros((2, 3)), max_speed=zeros,
        lattice_spacing=0.01, fps=8.0, duration_s=0.125)


def test_a_moved_object_carries_no_fringe():
    """A ray-cast capsule whose Gaussians reach 2 px past its mask (test_enhance_silhouette), moved 5 px
    right: more than SILHOUETTE_TOLERANCE_PX + 1 px beyond the moved mask the render's alpha is under 1/2, and
    from half a pixel further under a tenth (the Gaussians' tenths at the tolerance, stacked and antialiased),
    where an unnarrowed fringe draws it at 0.77 and 0.62; the moved mask itself stays covered (alpha above 0.99 on all but
    its outline's pixels). At rest (frame 0) the Gaussians are drawn as fitted, the fringe included: pm-enhance
    shows the photograph there."""
    gaussians, mask = fringed_gaussians()
    shift = 5
    coarse = render_video(gaussians, shifted_right(gaussians, shift), width=W, device="cpu")
    assert coarse.alpha.shape[1:] == (H, W)
    at_rest = cv2.distanceTransform((~mask).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    assert coarse.alpha[0][at_rest > SILHOUETTE_TOLERANCE_PX + 1.5].max() > 0.5
    moved = np.zeros_like(mask)
    moved[:, shift:] = mask[:, :-shift]
    distance = cv2.distanceTransform((~moved).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    assert coarse.alpha[1][distance > SILHOUETTE_TOLERANCE_PX + 1].max() < 0.5
    assert coarse.alpha[1][distance > SILHOUETTE_TOLERANCE_PX + 1.5].max() < 0.1
    inner = cv2.erode(moved.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    assert coarse.alpha[1][inner].min() > 0.99


def test_a_turned_limb_is_drawn_as_fitted():
    """surfel_sphere (test_render_flow) under a mask 3 px inside its picture, so that its limb reaches past
    it, turned 60 degrees about the vertical (turned_sphere): the limb, turned towards the camera, lies over
    the body and is drawn as fitted. The turned frame's alpha is splat's render of the turned Gaussians as
    they are, within 0.05, over the mask (the limb near the axis, at the top and bottom, stays at the
    silhouette, and narrowed); moved sideways instead (no turn), the same sphere is narrowed (its alpha 3 px
    past the moved mask falls under a tenth, from above 1/2)."""
    gaussians, trajectories, centre, radius, turn = turned_sphere(60.0)
    size = gaussians.width
    rows, cols = np.mgrid[0:size, 0:size] + 0.5 - size / 2
    picture_px = radius * gaussians.K[0, 0] / np.sqrt(centre[2] ** 2 - radius ** 2)
    gaussians.mask = (np.hypot(rows, cols) < picture_px - 3).astype(np.uint8)
    coarse = render_video(gaussians, trajectories, width=size, device="cpu")
    t = lambda a: torch.as_tensor(a, dtype=torch.float32)  # noqa: E731
    rest = splat.covariances_from_scales_rotations(t(gaussians.scales), t(gaussians.rotations))
    R = t(turn)
    camera = splat.Camera(gaussians.K, gaussians.world_to_camera, size, size)
    as_fitted = splat.rasterize(t(trajectories.positions[1]), t(gaussians.opacities), torch.ones(len(rest), 1), camera,
                                covariances=R @ rest @ R.T).alpha.numpy()
    on = gaussians.mask > 0  # the limb at the top and bottom, near the axis, stays at the silhouette: narrowed
    assert np.abs(coarse.alpha[1][on] - as_fitted[on]).max() < 0.05
    shifted = render_video(gaussians, shifted_right(gaussians, 6), width=size, device="cpu")
    moved = np.hypot(rows, cols - 6) < picture_px - 3
    beyond = cv2.distanceTransform((~moved).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE) > 3
    rest_beyond = cv2.distanceTransform((gaussians.mask == 0).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE) > 3
    assert coarse.alpha[0][rest_beyond].max() > 0.5
    assert shifted.alpha[1][beyond].max() < 0.1
