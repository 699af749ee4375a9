"""The shadow moves with the object: a ball on a textured floor, lit from the upper left and
ray-traced with its soft shadow, slides sideways. Against the floor ray-traced without any shadow,
the old place must lose its shadow and the new one gain the ray-traced ball's."""
import cv2
import numpy as np
import pytest

from schemas.artifacts import GaussiansArtifact, TrajectoriesArtifact
from schemas.solid import solid_fields
from stages.enhance.flow import enhance_frames
from stages.enhance.shadow import Ground
from stages.reconstruct.background import inpaint_background
from testing.particles import sphere_surfels

W, H, FOCAL, PITCH_DEG = 160, 120, 200.0, 20.0
RADIUS, FLOOR_Y = 0.08, 0.33  # world frame: y down along gravity, z away from the camera, horizontal
CENTRE = np.array([0.05, FLOOR_Y - RADIUS, 1.0])
MOVE = np.array([-0.2, 0.0, 0.0])
LIGHT = np.array([-0.5, -1.0, 0.4]) / np.linalg.norm([-0.5, -1.0, 0.4])  # towards the light, world frame
AMBIENT, DIRECT, LIGHT_RADIUS_DEG = 0.35, 0.65, 4.0
p = np.radians(PITCH_DEG)
R = np.array([[1.0, 0, 0], [0, np.cos(p), -np.sin(p)], [0, np.sin(p), np.cos(p)]])  # world -> camera
K = np.array([[FOCAL, 0, W / 2], [0, FOCAL, H / 2], [0, 0, 1]])


def sphere_hit(origins, directions, centre):
    """Distance along unit directions (N, 3) from origins (N, 3) to the sphere, inf where missed."""
    rel = origins - centre
    b = np.sum(rel * directions, -1)
    reach = b * b - (np.sum(rel * rel, -1) - RADIUS ** 2)
    t = -b - np.sqrt(np.maximum(reach, 0))
    return np.where((reach > 0) & (t > 1e-9), t, np.inf)


def light_samples(n: int = 32) -> np.ndarray:
    """(n, 3) unit directions over the light's disc (radius LIGHT_RADIUS_DEG), for a soft shadow."""
    rng = np.random.default_rng(0)
    side = np.cross(LIGHT, [0, 0, 1.0])
    side /= np.linalg.norm(side)
    other = np.cross(LIGHT, side)
    radius, angle = np.sqrt(rng.uniform(0, 1, n)) * np.tan(np.radians(LIGHT_RADIUS_DEG)), rng.uniform(0, 2 * np.pi, n)
    d = LIGHT + radius[:, None] * (np.cos(angle)[:, None] * side + np.sin(angle)[:, None] * other)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def scene_image(centre, shadowed: bool = True, supersampling: int = 3):
    """sRGB (H, W, 3) u8 of the ball at ``centre`` on the floor, and its coverage (H, W)."""
    n = supersampling
    rows, cols = np.indices((H * n, W * n), dtype=np.float64)
    rays = np.stack([(cols + 0.5) / n - W / 2, (rows + 0.5) / n - H / 2, np.full(cols.shape, FOCAL)], -1).reshape(-1, 3)
    rays = rays / np.linalg.norm(rays, axis=1, keepdims=True) @ R  # camera -> world (R^T applied to rows)
    origin = np.zeros_like(rays)
    to_ball = sphere_hit(origin, rays, centre)
    to_floor = np.where(rays[:, 1] > 1e-9, FLOOR_Y / np.maximum(rays[:, 1], 1e-9), np.inf)
    colour = np.tile([0.55, 0.6, 0.7], (len(rays), 1))  # the wall beyond the floor
    floor = np.isfinite(to_floor) & (to_floor < to_ball)
    point = rays[floor] * to_floor[floor, None]
    grain = 0.5 + 0.08 * np.sin(point[:, 2] * 140) + 0.05 * np.sin(point[:, 0] * 60 + point[:, 2] * 30)
    seen = np.ones(len(point))
    if shadowed:
        seen = np.mean([~np.isfinite(sphere_hit(point, np.broadcast_to(d, point.shape), centre)) for d in light_samples()], 0)
    lit = AMBIENT + DIRECT * seen * (-LIGHT[1])
    colour[floor] = grain[:, None] * np.array([1.0, 0.75, 0.5]) * lit[:, None]
    ball = np.isfinite(to_ball) & ~floor
    normal = (rays[ball] * to_ball[ball, None] - centre) / RADIUS
    bands = 0.5 + 0.5 * np.sin(9 * normal[:, 1])
    albedo = (1 - bands)[:, None] * [0.8, 0.15, 0.1] + bands[:, None] * [0.85, 0.75, 0.2]
    colour[ball] = albedo * (AMBIENT + DIRECT * np.maximum(normal @ LIGHT, 0))[:, None]
    srgb = np.where(colour <= 0.0031308, 12.92 * colour, 1.055 * np.clip(colour, 0, 1) ** (1 / 2.4) - 0.055)
    image = srgb.reshape(H, n, W, n, 3).mean((1, 3)) * 255
    return (image + 0.5).astype(np.uint8), ball.reshape(H, n, W, n).mean((1, 3))


def surfel_ball(photo, coverage, n: int = 5000) -> GaussiansArtifact:
    normals, scales, quaternions = sphere_surfels(n, RADIUS)
    means = CENTRE + RADIUS * normals
    image = (means @ R.T) @ K.T
    uv = image[:, :2] / image[:, 2:]
    colours = photo[np.clip(uv[:, 1].astype(int), 0, H - 1), np.clip(uv[:, 0].astype(int), 0, W - 1)] / 255.0
    world_to_camera = np.eye(4)
    world_to_camera[:3, :3] = R
    labels = (coverage > 0.5).astype(np.uint8)
    return GaussiansArtifact(
        K=K, world_to_camera=world_to_camera, width=W, height=H, means=means,
        scales=scales, rotations=quaternions,
        opacities=np.full(n, 0.95), colors=colours, object_id=np.zeros(n), photo=photo, mask=labels,
        background=inpaint_background(photo, labels), depth_prior=np.where(labels > 0, 1.0, np.nan),
        **solid_fields([None]), loss=np.zeros((0, 1)), loss_terms=["none"])


def slid(gaussians: GaussiansArtifact) -> TrajectoriesArtifact:
    G = len(gaussians.means)
    zeros = np.zeros(2)
    return TrajectoriesArtifact(
        rest_positions=gaussians.means, volumes=np.ones(G), masses=np.ones(G), material_id=np.zeros(G),
        object_id=np.zeros(G), is_gaussian=np.ones(G, bool), positions=np.stack([gaussians.means, gaussians.means + MOVE]),
        F=np.tile(np.eye(3), (2, G, 1, 1)), time_s=np.arange(2) / 8.0, substeps=zeros, kinetic_energy=zeros,
        potential_energy=zeros, momentum=np.zeros((2, 3)), angular_momentum=np.zeros((2, 3)), max_speed=zeros,
        lattice_spacing=0.01, fps=8.0, duration_s=1 / 8)


def darkening(image: np.ndarray, unshadowed: np.ndarray) -> np.ndarray:
    """(H, W) 1 - brightness / unshadowed brightness, on the sRGB values' mean, smoothed past the grain."""
    blur = lambda a: cv2.GaussianBlur(a.astype(np.float32).mean(-1), (0, 0), 1.5)  # noqa: E731
    return 1 - blur(image) / np.maximum(blur(unshadowed), 1.0)


@pytest.fixture(scope="module")
def slide():
    from stages.render.render import render_video

    photo, coverage = scene_image(CENTRE)
    gaussians = surfel_ball(photo, coverage)
    coarse = render_video(gaussians, slid(gaussians), width=W, device="cpu")
    frames = enhance_frames(coarse, gaussians, threshold=0.5, ground=True)
    unshadowed, _ = scene_image(CENTRE + MOVE, shadowed=False)
    truth, _ = scene_image(CENTRE + MOVE)
    return photo, coverage, gaussians, coarse, frames, unshadowed, truth


def test_ground_is_under_the_ball(slide):
    _, _, gaussians, _, _, _, _ = slide
    ground = Ground.of(gaussians)
    assert np.allclose(ground.down, R[:, 1])
    # the lowest surfel (4 mm apart) is within 8 mm of the floor under the ball, in the pitched camera frame
    floor_point = R @ np.array([CENTRE[0], FLOOR_Y, CENTRE[2]])
    assert abs(ground.height - floor_point @ ground.down) < 0.008


def test_shadow_leaves_with_the_ball_and_is_drawn_under_it(slide):
    """At the old place (where the photograph's shadow was, the moved ball's not, and no ball now)
    the frame's darkening must fall to at most a fifth of the photograph's; under the moved ball
    (where the ray-traced shadow darkens the floor by more than 15 %) the drawn darkening must
    be 60-140 % of the ray-traced one (measured: 99 % removed, 85 % drawn); and frame 0 is the
    photograph."""
    photo, coverage, gaussians, coarse, frames, unshadowed, truth = slide
    before = darkening(photo, unshadowed)
    expected = darkening(truth, unshadowed)
    now = darkening(frames[1], unshadowed)
    free = cv2.dilate((coarse.alpha[1] > 0.01).astype(np.uint8) | (coverage > 0).astype(np.uint8),
                      np.ones((5, 5), np.uint8)) == 0  # neither ball covers it
    old = free & (before > 0.15) & (expected < 0.02)
    new = free & (expected > 0.15)
    assert old.sum() > 30 and new.sum() > 30, (old.sum(), new.sum())
    removed = 1 - now[old].mean() / before[old].mean()
    drawn = now[new].mean() / expected[new].mean()
    assert removed > 0.8, f"{100 * removed:.0f}% of the old shadow removed"
    assert 0.6 < drawn < 1.4, f"{100 * drawn:.0f}% of the ray-traced shadow drawn under the moved ball"
    rest = np.abs(frames[0].astype(float) - photo)[(coverage == 0)].mean()
    assert rest < 1.0, f"frame 0 off the photograph by {rest:.2f}/255 beside the ball"
