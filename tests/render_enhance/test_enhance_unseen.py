"""Unseen surfaces continue the seen ones: a lit ball whose colour depends only on height, spun about
the vertical axis through pm-render and the flow backend, must look like its photograph from every
side (it is the same picture: the light stays, the ball is round and its bands are horizontal)."""
import cv2
import numpy as np
import pytest

from schemas.artifacts import GaussiansArtifact, TrajectoriesArtifact
from schemas.camera import pixel_rays
from schemas.solid import solid_fields
from stages.enhance.flow import enhance_frames
from stages.enhance.relight import to_srgb
from stages.enhance.unseen import mirrored_source
from stages.render.render import render_video
from testing.particles import sphere_surfels
from testing.photographs import sphere_hits

SIZE, FOCAL, RADIUS, DISTANCE = 128, 300.0, 0.1, 1.0
CENTRE = np.array([0.0, 0.0, DISTANCE])
K = np.array([[FOCAL, 0, SIZE / 2], [0, FOCAL, SIZE / 2], [0, 0, 1]])
AMBIENT, LIGHT = 0.4, 0.55 * np.array([-0.45, -0.65, -0.6]) / np.linalg.norm([-0.45, -0.65, -0.6])
TURNS_DEG = [0, 45, 90, 135, 180, 225, 270, 315]


def albedo(height: np.ndarray) -> np.ndarray:
    """Linear albedo (..., 3) of bands from red to yellow along height (unit sphere's y, down)."""
    s = (0.5 + 0.5 * np.sin(7 * height))[..., None]
    return (1 - s) * np.array([0.75, 0.08, 0.05]) + s * np.array([0.85, 0.7, 0.12])


def shaded(normals: np.ndarray) -> np.ndarray:
    """sRGB in [0, 255] of the lit ball where its unit normals are ``normals`` (..., 3)."""
    return to_srgb(albedo(normals[..., 1]) * np.maximum(AMBIENT + normals @ LIGHT, 0.05)[..., None])


def photograph(supersampling: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """The ball ray-cast in float64 over a striped grey background, anti-aliased; and its pixel coverage."""
    n = SIZE * supersampling
    rows, cols = np.indices((n, n), dtype=np.float64)
    rays = np.stack([(cols + 0.5) / supersampling - SIZE / 2, (rows + 0.5) / supersampling - SIZE / 2,
                     np.full(cols.shape, FOCAL)], -1)
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    distance, on = sphere_hits(rays, CENTRE, RADIUS)
    normals = (rays * distance[..., None] - CENTRE) / RADIUS
    background = 100 + 20 * np.sin(cols / supersampling / 3.0)[..., None] * np.ones(3)
    image = np.where(on[..., None], shaded(normals), background)
    image = image.reshape(SIZE, supersampling, SIZE, supersampling, 3).mean((1, 3))
    return (image + 0.5).astype(np.uint8), on.reshape(SIZE, supersampling, SIZE, supersampling).mean((1, 3))


def closed_ball(photo: np.ndarray, coverage: np.ndarray, n: int = 8000) -> GaussiansArtifact:
    """Surfels all around the ball, coloured as the reconstruction colours them: the front by the
    photograph, the back by the front it mirrors (across the plane z = DISTANCE)."""
    normals, scales, quaternions = sphere_surfels(n, RADIUS)
    front = normals * [1, 1, -1]
    front[:, 2] = -np.abs(normals[:, 2])
    return GaussiansArtifact(
        K=K, world_to_camera=np.eye(4), width=SIZE, height=SIZE, means=CENTRE + RADIUS * normals,
        scales=scales, rotations=quaternions,
        opacities=np.full(n, 0.95), colors=shaded(front) / 255.0, object_id=np.zeros(n), photo=photo,
        mask=(coverage > 0.5).astype(np.uint8), background=np.full((SIZE, SIZE, 3), 100, np.uint8),
        depth_prior=np.where(coverage > 0.5, DISTANCE - RADIUS, np.nan), **solid_fields([None]),
        loss=np.zeros((0, 1)), loss_terms=["none"])


def spun(gaussians: GaussiansArtifact, turns_deg) -> TrajectoriesArtifact:
    """Frame t turns the ball by turns_deg[t] about the vertical axis through its centre."""
    G, T = len(gaussians.means), len(turns_deg)
    angles = np.radians(turns_deg)
    turns = np.array([[[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]] for a in angles])
    positions = np.einsum("tij,gj->tgi", turns, gaussians.means - CENTRE) + CENTRE
    zeros = np.zeros(T)
    return TrajectoriesArtifact(
        rest_positions=gaussians.means, volumes=np.ones(G), masses=np.ones(G), material_id=np.zeros(G),
        object_id=np.zeros(G), is_gaussian=np.ones(G, bool), positions=positions,
        F=np.broadcast_to(turns[:, None], (T, G, 3, 3)), time_s=np.arange(T) / 8.0, substeps=zeros,
        kinetic_energy=zeros, potential_energy=zeros, momentum=np.zeros((T, 3)), angular_momentum=np.zeros((T, 3)),
        max_speed=zeros, lattice_spacing=0.01, fps=8.0, duration_s=(T - 1) / 8)


def luma(rgb: np.ndarray) -> np.ndarray:
    return rgb.astype(np.float64) @ [0.299, 0.587, 0.114]


@pytest.fixture(scope="module")
def spun_ball():
    photo, coverage = photograph()
    gaussians = closed_ball(photo, coverage)
    coarse = render_video(gaussians, spun(gaussians, TURNS_DEG), width=SIZE, device="cpu")
    return photo, coverage, coarse, enhance_frames(coarse, gaussians, threshold=0.5)


def test_spun_ball_looks_like_its_photograph_from_every_side(spun_ball):
    """PSNR-Y inside the ball (its silhouette's mixed pixels left out) against the photograph, at
    every turn past 30 degrees: at least 25 dB (measured 30.8 at 90 and 270 degrees, where half the
    visible side was seen and half not, 33-48 elsewhere; reading the photograph at the sources alone
    gave 21.7 at 90 and 22.7 at 135)."""
    photo, coverage, coarse, frames = spun_ball
    inside = cv2.erode((coverage > 0.99).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    unseen = [float((coarse.source_confidence[t] < 0.5)[inside].mean()) for t in range(len(TURNS_DEG))]
    assert max(unseen) > 0.9  # the far side does come into view
    for t, turn in enumerate(TURNS_DEG):
        mse = np.mean((luma(frames[t])[inside] - luma(photo)[inside]) ** 2)
        psnr = 10 * np.log10(255.0 ** 2 / mse)
        assert turn <= 30 or psnr >= 25.0, f"turned {turn} degrees: PSNR-Y {psnr:.1f} dB inside the ball"
    assert 10 * np.log10(255.0 ** 2 / np.mean((luma(frames[0]) - luma(photo))[inside] ** 2)) > 45.0


def test_mirrored_source_is_where_the_photograph_saw_the_mirror_image():
    """For a sphere whose plane of symmetry is z = DISTANCE: the source of a back point B (the
    projection of B) must lead to the projection of B mirrored across the plane, in float64."""
    rng = np.random.default_rng(3)
    back = rng.normal(size=(200, 3))
    back /= np.linalg.norm(back, axis=1, keepdims=True)
    back[:, 2] = np.abs(back[:, 2])
    back = back[back[:, 2] > 0.4]  # away from the limb, where the front is steep between pixels
    B = CENTRE + RADIUS * back
    mirror = B * [1, 1, -1] + [0, 0, 2 * DISTANCE]
    project = lambda x: x[:, :2] / x[:, 2:] * FOCAL + SIZE / 2  # noqa: E731
    rays = pixel_rays(K, SIZE, SIZE)
    along = rays @ CENTRE
    reach = along ** 2 - (CENTRE @ CENTRE - RADIUS ** 2)
    front = np.where(reach > 0, along - np.sqrt(np.maximum(reach, 0)), np.nan)
    found = mirrored_source(project(B)[None].astype(np.float32), front.astype(np.float32), rays.astype(np.float32),
                            np.tile([0.0, 0.0, 1.0], (1, len(B), 1)), np.full((1, len(B)), DISTANCE), K)[0]
    error = np.linalg.norm(found - project(mirror), axis=1)
    # the front is known per pixel and read bilinearly: a fraction of a pixel; the sources themselves
    # are up to 3 px from their mirror images here
    assert np.linalg.norm(project(B) - project(mirror), axis=1).max() > 2.5
    assert np.median(error) < 0.1 and error.max() < 0.3, f"median {np.median(error):.3f}, max {error.max():.3f} px"
