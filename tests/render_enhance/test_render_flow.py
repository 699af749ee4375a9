"""pm-render and the flow backend on a scene whose answer is known: a textured disc of Gaussians
(one per pixel, facing the camera) with a hidden layer behind it, translated by whole pixels."""
import cv2
import numpy as np
import pytest
import torch

import splat
from schemas.artifacts import GaussiansArtifact, TrajectoriesArtifact
from schemas.solid import solid_fields
from stages.enhance.flow import band_limited_upsample, enhance_frames, photograph_at, sample_at
from stages.render.render import render_camera, render_video
from stages.render.source_map import map_moments, source_points, source_spread
from testing.particles import sphere_surfels
from testing.photographs import sphere_hits

W, H, FOCAL, DEPTH = 48, 40, 60.0, 1.0


def textured_photo() -> tuple[np.ndarray, np.ndarray]:
    """A high-contrast striped disc (the hardest case for resampling) on a grey background, and its mask."""
    rows, cols = np.mgrid[0:H, 0:W]
    disc = (cols - 20) ** 2 + (rows - 20) ** 2 < 12 ** 2
    photo = np.full((H, W, 3), 128, np.uint8)
    stripes = (cols + rows) % 4 < 2
    photo[disc & stripes] = (240, 30, 30)
    photo[disc & ~stripes] = (20, 40, 220)
    return photo, disc


def disc_gaussians() -> GaussiansArtifact:
    """A front layer of Gaussians, one per disc pixel, on the plane z = DEPTH; a green layer 5 % farther
    on the same rays, so each of its Gaussians projects onto the same pixel centre."""
    photo, disc = textured_photo()
    K = np.array([[FOCAL, 0, W / 2], [0, FOCAL, H / 2], [0, 0, 1]])
    rows, cols = np.nonzero(disc)
    front = np.stack([(cols + 0.5 - W / 2) * DEPTH / FOCAL, (rows + 0.5 - H / 2) * DEPTH / FOCAL,
                      np.full(len(rows), DEPTH)], 1)
    back = front * 1.05
    n = len(rows)
    pixel = DEPTH / FOCAL
    scales = np.tile([0.35 * pixel, 0.35 * pixel, 0.05 * pixel], (n, 1))
    return GaussiansArtifact(
        K=K, world_to_camera=np.eye(4), width=W, height=H, means=np.concatenate([front, back]),
        scales=np.concatenate([scales, scales * 1.05]),
        rotations=np.tile([1.0, 0, 0, 0], (2 * n, 1)), opacities=np.ones(2 * n),
        colors=np.concatenate([photo[rows, cols] / 255.0, np.tile([0.0, 1.0, 0.0], (n, 1))]),
        object_id=np.zeros(2 * n), photo=photo, mask=disc.astype(np.uint8), background=np.full((H, W, 3), 128),
        depth_prior=np.where(disc, DEPTH, np.nan), **solid_fields([None]), loss=np.zeros((0, 1)),
        loss_terms=["none"])


def translated(gaussians: GaussiansArtifact, shifts_px) -> TrajectoriesArtifact:
    """Every frame t moves all Gaussians right by shifts_px[t] pixels; F stays the identity."""
    G, T = len(gaussians.means), len(shifts_px)
    offsets = np.array([[s * DEPTH / FOCAL, 0, 0] for s in shifts_px])
    positions = gaussians.means[None] + offsets[:, None]
    zeros = np.zeros(T)
    return TrajectoriesArtifact(
        rest_positions=gaussians.means, volumes=np.ones(G), masses=np.ones(G), material_id=np.zeros(G),
        object_id=np.zeros(G), is_gaussian=np.ones(G, bool), positions=positions, F=np.tile(np.eye(3), (T, G, 1, 1)),
        time_s=np.arange(T) / 8.0, substeps=zeros, kinetic_energy=zeros, potential_energy=zeros,
        momentum=np.zeros((T, 3)), angular_momentum=np.zeros((T, 3)), max_speed=zeros, lattice_spacing=0.01, fps=8.0,
        duration_s=(T - 1) / 8)


@pytest.fixture(scope="module")
def shifted_run():
    gaussians = disc_gaussians()
    shifts = [0, 3, 7]
    coarse = render_video(gaussians, translated(gaussians, shifts), width=W, device="cpu")
    return gaussians, shifts, coarse, enhance_frames(coarse, gaussians, threshold=0.5)


def reconstruction_render(gaussians, width: int, height: int) -> splat.Render:
    """splat's render of the reconstruction's Gaussians alone, at rest, from the input camera."""
    t = lambda a: torch.as_tensor(a, dtype=torch.float32)  # noqa: E731
    camera = splat.Camera(gaussians.K, gaussians.world_to_camera, width, height)
    return splat.rasterize(t(gaussians.means), t(gaussians.opacities), t(gaussians.colors), camera,
                           scales=t(gaussians.scales), rotations=t(gaussians.rotations))


def test_frame0_is_the_reconstruction_render(shifted_run):
    gaussians, _, coarse, _ = shifted_run
    direct = reconstruction_render(gaussians, W, H)
    assert np.abs(coarse.alpha[0] - direct.alpha.numpy()).max() < 1e-5
    expected_rgb = (direct.features.clamp(0, 1).numpy() * 255 + 0.5).astype(np.uint8)
    assert np.abs(coarse.rgb[0].astype(int) - expected_rgb).max() <= 1


@pytest.mark.parametrize("width, size", [(20, (20, 16)), (31, (30, 26)), (100, (W, H))])
def test_output_size_follows_render_width_up_to_the_photograph_in_even_pixels(width, size):
    camera = render_camera(disc_gaussians(), width)
    assert (camera.width, camera.height) == size  # W x H = 48 x 40, the photograph's own size


def test_source_uv_maps_rest_pixels_onto_themselves(shifted_run):
    _, _, coarse, _ = shifted_run
    _, disc = textured_photo()
    # px; blended projected centres would be 0.25-0.45 px off. Every Gaussian's affine map is
    # the identity at rest, so the blend is exact up to float32 rounding, silhouette included.
    rows, cols = np.nonzero(disc)
    assert np.abs(coarse.source_uv[0][rows, cols] - np.stack([cols + 0.5, rows + 0.5], 1)).max() < 1e-3


def test_hidden_layer_gets_no_confidence_and_front_full(shifted_run):
    _, _, coarse, _ = shifted_run
    _, disc = textured_photo()
    assert coarse.source_confidence[0][disc].min() > 0.95


def test_enhanced_frames_are_the_shifted_photograph(shifted_run):
    gaussians, shifts, coarse, frames = shifted_run
    photo, disc = textured_photo()
    inner = disc & np.roll(disc, 2, 0) & np.roll(disc, -2, 0) & np.roll(disc, 2, 1) & np.roll(disc, -2, 1)
    for t, shift in enumerate(shifts):
        expected = np.roll(photo, shift, axis=1)
        region = np.roll(inner, shift, axis=1)
        mae = np.abs(frames[t][region].astype(float) - expected[region]).mean()
        assert mae < 2.0, f"frame {t}: mean absolute error {mae:.2f}/255 inside the object"


def test_background_where_the_object_left(shifted_run):
    _, shifts, coarse, frames = shifted_run
    _, disc = textured_photo()
    uncovered = disc & ~np.roll(disc, shifts[-1] + 2, axis=1) & (coarse.alpha[-1] < 1e-3)
    assert uncovered.sum() > 20
    assert np.abs(frames[-1][uncovered].astype(int) - 128).max() <= 1


def shuffled_front(gaussians: GaussiansArtifact) -> TrajectoriesArtifact:
    """Two frames: at rest, then the front layer's Gaussians shuffled among each other's places."""
    front = len(gaussians.means) // 2
    order = np.random.default_rng(0).permutation(front)
    shuffled = translated(gaussians, [0, 0])
    shuffled.positions[1, :front] = gaussians.means[order]
    return shuffled


def test_scrambled_surface_falls_back_to_the_render():
    """Gaussians shuffled among each other's places: every pixel now blends sources from all over the
    photograph, so the lookup is incoherent and the enhancement must show the render, not a mix."""
    gaussians = disc_gaussians()
    coarse = render_video(gaussians, shuffled_front(gaussians), width=W, device="cpu")
    _, disc = textured_photo()
    assert coarse.source_confidence[0][disc].mean() > 0.95
    assert coarse.source_confidence[1][disc].mean() < 0.1
    frames = enhance_frames(coarse, gaussians, threshold=0.5)
    rendered = coarse.rgb[1][disc].astype(float) / coarse.alpha[1][disc, None]
    assert np.abs(frames[1][disc] - rendered).mean() < 3.0


def test_mixed_grains_fall_back_to_the_render():
    """As test_scrambled_surface_falls_back_to_the_render, with every Gaussian four times wider and
    translucent (opacity 0.2): each pixel now blends dozens of sources from all over the disc, whose
    mean is near the disc's middle everywhere. That blended map is smooth (its roughness trusted it
    everywhere), but no grain came from there: the sources' spread must withdraw the trust."""
    gaussians = disc_gaussians()
    gaussians.scales[:, :2] *= 4
    gaussians.opacities[:] = 0.2
    coarse = render_video(gaussians, shuffled_front(gaussians), width=W, device="cpu")
    _, disc = textured_photo()
    inner = cv2.erode(disc.astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
    assert coarse.source_coherence[0][inner].min() > 0.95
    assert coarse.source_coherence[1][inner].mean() < 0.1


def test_source_spread_is_the_weighted_spread_of_the_gaussians_sources():
    """source_spread from the blended moments against the float64 spread of each Gaussian's map applied
    to the pixel, for random maps and blending weights."""
    rng = np.random.default_rng(1)
    h, w, G = 3, 4, 5
    maps = torch.as_tensor(np.concatenate([rng.uniform(0, 500, (G, 2)), rng.normal(1, 0.5, (G, 4))], 1))
    weights = torch.as_tensor(rng.uniform(0, 1, (h, w, G)))
    voted_maps, voted_moments = weights @ maps, weights @ map_moments(maps)
    votes = weights.sum(-1)
    spread = source_spread(voted_moments, votes, source_points(voted_maps, votes))
    for i in range(h):
        for j in range(w):
            p = np.array([j + 0.5, i + 0.5])
            sources = np.array([m[:2] + m[2:].reshape(2, 2) @ p for m in maps.numpy()])
            share = weights[i, j].numpy() / weights[i, j].numpy().sum()
            expected = np.sqrt(share @ np.square(sources - share @ sources).sum(1))
            assert abs(float(spread[i, j]) - expected) < 1e-6 * max(1.0, expected)


def test_revealed_hidden_layer_reads_the_photograph_at_its_mirror_image():
    """The front layer leaves the view at frame 1 and reveals the green layer the photograph never
    saw. Nothing else moved, so each pixel's source is its own place in the photograph. The body is
    taken as mirror-symmetric across the vertical plane halfway between the layers, facing the
    camera from the disc's centre: the point M of the front (z = DEPTH) whose mirror image lies on
    a pixel's ray is the colour of the unseen surface there (float64 here). The "photo" setting
    must show the photograph at M's projection, "render" the green layer."""
    gaussians = disc_gaussians()
    front = len(gaussians.means) // 2
    revealed = translated(gaussians, [0, 0])
    revealed.positions[1, :front] += [10.0, 0.0, 0.0]
    coarse = render_video(gaussians, revealed, width=W, device="cpu")
    photo, _ = textured_photo()
    inner = cv2.erode((coarse.alpha[1] > 0.5).astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    assert inner.sum() > 200
    assert coarse.source_confidence[1][inner].max() < 0.1  # hidden at rest
    assert coarse.source_coherence[1][inner].min() > 0.9  # but it maps smoothly
    rows, cols = np.nonzero(inner)
    assert np.abs(coarse.source_uv[1][inner] - np.stack([cols + 0.5, rows + 0.5], 1)).max() < 0.1  # px
    through = enhance_frames(coarse, gaussians, threshold=0.5, hidden_surfaces="photo")[1][inner].astype(float)
    rendered = enhance_frames(coarse, gaussians, threshold=0.5, hidden_surfaces="render")[1][inner].astype(float)
    rays = np.stack([cols + 0.5, rows + 0.5, np.ones(len(rows))], 1) @ np.linalg.inv(gaussians.K).T
    towards = gaussians.means.mean(0) * [1, 0, 1]
    towards /= np.linalg.norm(towards)
    plane = (gaussians.means @ towards).min() / 2 + (gaussians.means @ towards).max() / 2
    # mirror(r t) = r t - 2 (t r.n - plane) n has z = DEPTH
    t = (DEPTH - 2 * plane * towards[2]) / (rays[:, 2] - 2 * (rays @ towards) * towards[2])
    front = rays * t[:, None] - 2 * (t * (rays @ towards) - plane)[:, None] * towards
    image = front @ gaussians.K.T
    mirrored = photograph_at(band_limited_upsample(photo.astype(np.float32)), (image[:, :2] / image[:, 2:])[None])[0]
    assert np.abs(through - mirrored).mean() < 3.0
    assert np.abs(through - photo[inner]).mean() > 3 * np.abs(through - mirrored).mean()  # not the same pixel
    assert np.abs(rendered - [0, 255, 0]).mean() < 3.0


def test_photograph_lookup_shifts_fine_detail_without_softening_it():
    """A band-limited texture (sinusoids up to 0.4 cycles per pixel, float64) read at a sub-pixel
    offset must equal the same sinusoids evaluated there; a plain Lanczos lookup cannot (it
    attenuates detail near the Nyquist limit), and whole-pixel reads must be exact."""
    rows, cols = np.indices((64, 80), dtype=np.float64)
    waves = [(0.40, 0.05, 0.3), (0.11, 0.37, 1.1), (0.27, -0.21, 2.0)]  # cycles/px along x, y; phase

    def texture(x, y):
        return 128 + sum(30 * np.cos(2 * np.pi * (fx * x + fy * y) + phase) for fx, fy, phase in waves)

    image = np.repeat(texture(cols, rows)[..., None], 3, axis=2).astype(np.float32)
    offset = np.array([0.3, -0.45])
    uv = np.stack([cols, rows], -1) + 0.5 + offset
    expected = texture(cols + offset[0], rows + offset[1])
    inner = (slice(10, -10), slice(10, -10))  # away from the border, where the texture is not periodic
    fine = band_limited_upsample(image)
    error = np.abs(photograph_at(fine, uv)[..., 0] - expected)[inner].mean()
    plain = np.abs(sample_at(image, uv, cv2.INTER_LANCZOS4)[..., 0] - expected)[inner].mean()
    # grey levels, of waves 90 peak to peak: the ringing of the reflected border reaches in a little
    assert error < 1.5 and plain > 2.5 * error
    whole = photograph_at(fine, np.stack([cols, rows], -1) + 0.5)
    assert np.abs(whole - image)[inner].max() < 1e-2


def surfel_sphere(n: int = 6000, radius_m: float = 0.1, distance_m: float = 1.0, focal: float = 200.0,
                  size: int = 96) -> GaussiansArtifact:
    """Surfels tangent to a sphere of radius_m, distance_m in front of the camera (they cover its far side
    too), textured; the photograph black, the camera's focal length ``focal`` px, its image size x size."""
    normals, scales, quaternions = sphere_surfels(n, radius_m)
    centre = np.array([0.0, 0.0, distance_m])
    K = np.array([[focal, 0, size / 2], [0, focal, size / 2], [0, 0, 1]])
    colours = 0.5 + 0.4 * np.sin(40 * normals)  # any texture: the test reads source_uv, not colour
    return GaussiansArtifact(
        K=K, world_to_camera=np.eye(4), width=size, height=size, means=centre + radius_m * normals,
        scales=scales, rotations=quaternions,
        opacities=np.full(n, 0.9), colors=colours, object_id=np.zeros(n),
        photo=np.zeros((size, size, 3), np.uint8), mask=np.ones((size, size), np.uint8),
        background=np.zeros((size, size, 3), np.uint8), depth_prior=np.full((size, size), distance_m),
        **solid_fields([None]), loss=np.zeros((0, 1)), loss_terms=["none"])


def turned_sphere(turn_deg: float, radius_m: float = 0.1, distance_m: float = 1.0):
    """surfel_sphere, and trajectories whose frame 1 turns it by ``turn_deg`` about the vertical axis
    through its centre."""
    gaussians = surfel_sphere(radius_m=radius_m, distance_m=distance_m)
    centre = np.array([0.0, 0.0, distance_m])
    angle = np.radians(turn_deg)
    turn = np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]])
    trajectories = translated(gaussians, [0, 0])
    trajectories.positions[1] = (gaussians.means - centre) @ turn.T + centre
    trajectories.F[1] = turn
    return gaussians, trajectories, centre, radius_m, turn


def test_turned_sphere_reads_the_photograph_where_its_surface_was():
    """The analytic answer: a pixel's ray meets the turned sphere at x; the surface there was at
    centre + turn^-1 (x - centre) in the photograph's view, whose projection is its source point.
    The far side shows through the surfels' gaps; it must not pull the map off."""
    gaussians, trajectories, centre, radius, turn = turned_sphere(30.0)
    coarse = render_video(gaussians, trajectories, width=gaussians.width, device="cpu")
    size = gaussians.width
    rows, cols = np.indices((size, size))
    rays = np.stack([(cols + 0.5 - size / 2), (rows + 0.5 - size / 2), np.full((size, size), gaussians.K[0, 0])], -1)
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    distance, met = sphere_hits(rays, centre, radius)
    hit = rays * distance[..., None]
    rest = (hit - centre) @ turn + centre  # turn^-1 = turn^T, applied to row vectors
    expected = rest[..., :2] / rest[..., 2:] * gaussians.K[0, 0] + size / 2
    facing_now = -((hit - centre) / radius * rays).sum(-1)
    facing_at_rest = -((rest - centre) / radius * rest / np.linalg.norm(rest, axis=-1, keepdims=True)).sum(-1)
    # away from the limb now and at rest, where a pixel's footprint spans a strip of the surface
    region = met & (facing_now > 0.5) & (facing_at_rest > 0.5) & (coarse.alpha[1] > 0.99)
    assert region.sum() > 300
    error = np.linalg.norm(coarse.source_uv[1][region] - expected[region], axis=-1)
    assert np.median(error) < 0.05 and error.max() < 0.2, f"median {np.median(error):.2f} px, max {error.max():.2f} px"
    assert coarse.source_coherence[1][region].min() > 0.9
    # and the surface's normals, carried by the turn, against the sphere's own. Each surfel's normal
    # is within 0.7 degrees; a pixel blends surfels whose footprints span 6 mm of this 10 cm sphere,
    # and compositing favours the nearer ones, which face the camera more (measured 2.2-2.7 median).
    normals = (hit - centre) / radius
    for frame in (0, 1):
        cosine = np.sum(coarse.normal[frame][region] * normals[region], -1)
        degrees = np.degrees(np.arccos(np.clip(cosine, -1, 1)))
        assert np.median(degrees) < 3.0 and degrees.max() < 5.0


def test_ring_around_the_object_shows_the_photograph_until_the_object_moves():
    """The background is filled over the mask and a ring around it (here 60 grey, where the photograph
    shows 128): at rest the ring must show the photograph, as it did; once the object has moved away
    from it, the fill (no outline of the object left behind)."""
    gaussians = disc_gaussians()
    photo, disc = textured_photo()
    ring = (cv2.dilate(disc.astype(np.uint8), np.ones((7, 7), np.uint8)) > 0) & ~disc
    gaussians.background = np.where((disc | ring)[..., None], 60, photo).astype(np.uint8)
    shifts = [0, 7]
    coarse = render_video(gaussians, translated(gaussians, shifts), width=W, device="cpu")
    frames = enhance_frames(coarse, gaussians, threshold=0.5)
    at_rest = ring & (coarse.alpha[0] < 0.05)
    assert at_rest.sum() > 20
    assert np.abs(frames[0][at_rest].astype(int) - 128).max() <= 2
    left_behind = ring & (coarse.alpha[1] < 0.05) & (np.arange(W) < 20)  # the side the disc moved away from
    assert left_behind.sum() > 10
    assert np.abs(frames[1][left_behind].astype(int) - 60).max() <= 2
