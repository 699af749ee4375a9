"""Re-shading against an analytic reference: a textured Lambertian sphere that turns under a fixed light."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from schemas.artifacts import CoarseArtifact, GaussiansArtifact
from schemas.solid import solid_fields
from stages.enhance.flow import enhance_frames
from stages.enhance.relight import Relighting, fit_shading, to_linear, to_srgb
from testing.photographs import sphere_hits

SIZE, FOCAL = 96, 120.0
CENTRE, RADIUS = np.array([0.0, 0.0, 3.0]), 0.8
AMBIENT, LIGHT = 0.45, 0.4 * np.array([-0.5, -0.6, -0.62]) / np.linalg.norm([-0.5, -0.6, -0.62])
K = np.array([[FOCAL, 0, SIZE / 2], [0, FOCAL, SIZE / 2], [0, 0, 1]])
TURN = Rotation.from_euler("y", 40, degrees=True).as_matrix()


def sphere():
    """Per pixel: distance along the unit ray to the sphere (NaN off it) and the unit normal there."""
    rows, cols = np.indices((SIZE, SIZE), dtype=np.float64)
    rays = np.stack([(cols + 0.5 - SIZE / 2) / FOCAL, (rows + 0.5 - SIZE / 2) / FOCAL, np.ones_like(cols)], -1)
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    distance, met = sphere_hits(rays, CENTRE, RADIUS)
    distance = np.where(met, distance, np.nan)
    normals = (rays * distance[..., None] - CENTRE) / RADIUS
    return distance, normals


def albedo(q: np.ndarray) -> np.ndarray:
    """Linear albedo of the sphere's material point q (unit vector in the sphere's own frame): smooth red
    to yellow stripes, all with the same largest channel, so brightness is the shading alone."""
    s = 0.5 + 0.5 * np.sin(5 * q[..., 1] + 3 * q[..., 0])[..., None]
    return (1 - s) * np.array([0.9, 0.2, 0.2]) + s * np.array([0.9, 0.75, 0.15])


def shade(n: np.ndarray) -> np.ndarray:
    return AMBIENT + n @ LIGHT


def project(points: np.ndarray) -> np.ndarray:
    return np.stack([FOCAL * points[..., 0] / points[..., 2] + SIZE / 2,
                     FOCAL * points[..., 1] / points[..., 2] + SIZE / 2], -1)


@pytest.fixture(scope="module")
def turned_sphere():
    """The photograph at rest, the coarse video (rest, then turned by TURN about the sphere's vertical
    axis), the reconstruction artifact, and frame 1 as the fixed light would show it."""
    distance, normals = sphere()
    on = np.isfinite(distance)
    photo = np.where(on[..., None], to_srgb(albedo(normals) * shade(normals)[..., None]), 128.0)
    rest = TURN.T @ np.moveaxis(np.nan_to_num(normals), -1, -2)  # where frame 1's material points were
    rest = np.moveaxis(rest, -2, -1)
    uv1 = np.where(on[..., None], project(CENTRE + RADIUS * rest), np.nan)
    rows, cols = np.indices((SIZE, SIZE))
    uv0 = np.where(on[..., None], np.stack([cols + 0.5, rows + 0.5], -1), np.nan)
    expected = np.where(on[..., None], to_srgb(albedo(rest) * shade(np.nan_to_num(normals))[..., None]), 128.0)
    alpha = on.astype(np.float32)
    two = lambda a, b: np.stack([a, b]).astype(np.float32)  # noqa: E731
    seen = np.where(on, (rest[..., 2] < 0).astype(np.float32), 0.0)
    coarse = CoarseArtifact(
        rgb=two(photo, expected).astype(np.uint8), alpha=two(alpha, alpha), depth=two(*[np.nan_to_num(distance)] * 2),
        source_uv=two(uv0, uv1), source_coherence=two(alpha, alpha), source_confidence=two(alpha, seen),
        normal=two(normals, normals), K=K, width=SIZE, height=SIZE, fps=8.0)
    gaussians = GaussiansArtifact(
        K=K, world_to_camera=np.eye(4), width=SIZE, height=SIZE, means=CENTRE[None], scales=np.full((1, 3), RADIUS),
        rotations=np.array([[1.0, 0, 0, 0]]), opacities=np.ones(1), colors=np.full((1, 3), 0.5),
        object_id=np.zeros(1), photo=(photo + 0.5).astype(np.uint8), mask=on.astype(np.uint8),
        background=np.full((SIZE, SIZE, 3), 128), depth_prior=np.where(on, distance, np.nan).astype(np.float32),
        **solid_fields([None]), loss=np.zeros((0, 1)), loss_terms=["none"])
    # compared away from both silhouettes (the rest one in the photograph, the current one in the frame),
    # where the normals' blur mixes in the rim
    compare = on & (rest[..., 2] < -0.5) & (normals[..., 2] < -0.5)
    return coarse, gaussians, expected, compare


def test_fit_recovers_the_light_of_a_striped_sphere():
    distance, normals = sphere()
    on = np.isfinite(distance) & (normals[..., 2] < -0.3)
    value = to_linear(to_srgb(albedo(normals) * shade(normals)[..., None])).max(-1)
    shading, explained = fit_shading(value, np.nan_to_num(normals), on)
    assert explained > 0.99
    cosine = shading.light @ LIGHT / np.linalg.norm(shading.light) / np.linalg.norm(LIGHT)
    angle = np.degrees(np.arccos(min(cosine, 1.0)))
    assert angle < 2.0
    assert shading.ambient / 0.9 == pytest.approx(AMBIENT, rel=0.05)  # albedo's largest channel is 0.9


def test_no_relighting_when_texture_explains_the_brightness(turned_sphere):
    coarse, gaussians, _, _ = turned_sphere
    rng = np.random.default_rng(0)
    flat = (rng.integers(0, 8, (SIZE // 8, SIZE // 8, 1)) * 30 + 20).repeat(8, 0).repeat(8, 1).repeat(3, 2)
    assert Relighting.fit(coarse, flat.astype(np.float64)) is None
    assert Relighting.fit(coarse, gaussians.photo.astype(np.float64)) is not None


def test_turned_sphere_is_reshaded_under_the_fixed_light(turned_sphere):
    """Frame 1 must show the turned texture lit from where the light is, not the photograph's shading
    carried along with the texture."""
    coarse, gaussians, expected, compare = turned_sphere
    relit = enhance_frames(coarse, gaussians, threshold=0.5, relight=True)[1]
    carried = enhance_frames(coarse, gaussians, threshold=0.5, relight=False)[1]
    error = np.abs(relit[compare] - expected[compare]).mean()
    baked = np.abs(carried[compare] - expected[compare]).mean()
    assert error < 2.0, f"re-shaded frame off by {error:.2f}/255"  # measured 1.30
    assert baked > 5 * error, f"the carried shading ({baked:.2f}/255) should be far off"  # measured 14.1
