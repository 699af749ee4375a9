"""pm-render's interior: the fill particles rendered as the body's material.

A sphere of surfels (test_render_flow.surfel_sphere) filled and simulated by pm-simulate's own
Simulation: pulled at both sides (fracture), slumped into a heap (sand), stretched (jelly); and,
independent of the physics, filled and its halves moved apart rigidly (a clean tear). Each frame's
coarse render is measured against an occupancy computed from the particles alone."""
import cv2
import numpy as np
import pytest
import torch
from scipy.spatial import cKDTree

import splat
from schemas import materials as M
from schemas.scene import PhysicsConfig
from stages.enhance.flow import enhance_frames
from stages.render.interior import (GRAIN_ELONGATION, GRAIN_SIGMA, GRAIN_SIZES, grain_shapes, surface_under,
                                    transmittance_layers)
from schemas.artifacts import TrajectoriesArtifact
from stages.render.render import render_video
from stages.simulate.fill import fill_object, lattice_spacing
from stages.simulate.simulation import Simulation

from .test_render_flow import reconstruction_render, surfel_sphere

SIZE, FOCAL = 96, 200.0
PULL = [{"type": "velocity", "region": {"box": [0, 0, 0, 0.3, 1, 1]}, "velocity": [-0.6, 0, 0]},
        {"type": "velocity", "region": {"box": [0.7, 0, 0, 1, 1, 1]}, "velocity": [0.6, 0, 0]}]
SIMULATED = {
    "torn fracture ball": (M.Fracture(youngs_modulus=5e4), dict(gravity=[0, 0, 0], ground={"enabled": False},
                                                                 conditions=PULL)),
    "sand heap": (M.Sand(friction_angle_deg=35), dict(ground={"enabled": True, "type": "friction", "friction": 0.5})),
    "stretched jelly": (M.Jelly(youngs_modulus=5e4), dict(gravity=[0, 0, 0], ground={"enabled": False},
                                                          conditions=[{**c, "velocity": [v / 6 for v in c["velocity"]]}
                                                                      for c in PULL])),
}
TORN_IN_TWO = "ball torn in two"


def torn_in_two(gaussians) -> TrajectoriesArtifact:
    """The sphere filled as pm-simulate fills it, cut through its centre by a plane turned 17 degrees
    towards the camera (so that one torn face is seen), its halves moved apart rigidly sideways: 0,
    2 and 8 cm in all."""
    fill, volumes = fill_object(gaussians.means.astype(np.float64), 0.02, 8)
    rest = np.concatenate([gaussians.means, fill])
    P, G, T = len(rest), len(gaussians.means), 3
    normal = np.array([1.0, 0.0, -0.3]) / np.hypot(1.0, 0.3)
    side = np.where((rest - gaussians.means.mean(0)) @ normal < 0, -1.0, 1.0)
    positions = rest[None] + np.array([0.0, 0.01, 0.04])[:, None, None] * side[None, :, None] * [1, 0, 0]
    zeros = np.zeros(T)
    return TrajectoriesArtifact(
        rest_positions=rest, volumes=volumes, masses=np.ones(P),
        material_id=np.full(P, M.PRESETS.index("fracture")), object_id=np.zeros(P), is_gaussian=np.arange(P) < G,
        positions=positions, F=np.tile(np.eye(3), (T, P, 1, 1)), time_s=np.arange(T) / 10.0, substeps=zeros,
        kinetic_energy=zeros, potential_energy=zeros, momentum=np.zeros((T, 3)), angular_momentum=np.zeros((T, 3)),
        max_speed=zeros, lattice_spacing=lattice_spacing(0.02, 8), fps=10.0, duration_s=0.2)


@pytest.fixture(scope="module", params=sorted(SIMULATED) + [TORN_IN_TWO])
def simulated(request):
    gaussians = surfel_sphere(size=SIZE, focal=FOCAL)
    if request.param == TORN_IN_TWO:
        trajectories = torn_in_two(gaussians)
    else:
        material, physics = SIMULATED[request.param]
        trajectories = Simulation(PhysicsConfig(duration_s=0.3, fps=20, grid=24, **physics), [material],
                                  gaussians.means, gaussians.object_id, device="cpu").run()
    coarse = render_video(gaussians, trajectories, width=SIZE, device="cpu")
    return request.param, gaussians, trajectories, coarse


def lattice_spacing_of(trajectories) -> float:
    fill = trajectories.rest_positions[~trajectories.is_gaussian].astype(np.float64)
    return float(np.median(cKDTree(fill).query(fill, k=2)[0][:, 1]))


def occupancy(positions: np.ndarray, F: np.ndarray, volumes: np.ndarray, K: np.ndarray,
              shape: tuple[int, int]) -> np.ndarray:
    """(rows, cols) = shape, bool, float64 brute force: the pixels whose centre's ray passes through some
    particle's share of the material, the ball of diameter cbrt(volume) about it deformed by its F
    ({x : |F^-1 (x - x_p)| <= cbrt(V_p) / 2}); the camera at the origin looking along +z."""
    x, F = positions.astype(np.float64), F.astype(np.float64)
    radius = np.cbrt(volumes.astype(np.float64)) / 2
    F_inverse = np.linalg.inv(F)
    reach_px = np.linalg.norm(F, ord=2, axis=(1, 2)) * radius * K[0, 0] / x[:, 2]
    half = int(np.ceil(reach_px.max())) + 1
    centre = np.floor(x[:, :2] / x[:, 2:] * K[0, 0] + K[:2, 2]).astype(int)
    offsets = np.stack(np.meshgrid(np.arange(-half, half + 1), np.arange(-half, half + 1)), -1).reshape(-1, 2)
    hit = np.zeros(shape, bool)
    for chunk in np.array_split(np.arange(len(x)), max(1, len(x) // 2000)):
        pixels = centre[chunk, None, :] + offsets[None]  # (n, k, 2) col, row
        inside = (pixels >= 0).all(-1) & (pixels < np.array(shape[::-1])).all(-1)
        rays = np.concatenate([(pixels + 0.5 - K[:2, 2]) / K[0, 0], np.ones(pixels.shape[:2] + (1,))], -1)
        origin = np.einsum("nij,nj->ni", F_inverse[chunk], -x[chunk])[:, None, :]  # the camera, particle frame
        direction = np.einsum("nij,nkj->nki", F_inverse[chunk], rays)
        miss2 = (np.cross(origin, direction) ** 2).sum(-1) / (direction ** 2).sum(-1)
        ahead = (origin * direction).sum(-1) < 0  # the particle lies in front of the camera
        through = inside & ahead & (miss2 <= radius[chunk, None] ** 2)
        hit[pixels[through][:, 1], pixels[through][:, 0]] = True
    return hit


def test_continuous_material_is_opaque_at_every_frame(simulated):
    """Of the pixels inside the particles' occupancy, at most 1 % may show the background through the
    render (alpha < 0.5). The occupancy is eroded by half a spacing (in pixels, rounded up): within
    that of its outline the particles cannot say where the material ends (and the outline's pixels
    are partly covered)."""
    name, gaussians, trajectories, coarse = simulated
    spacing = lattice_spacing_of(trajectories)
    half_px = int(np.ceil(spacing / 2 * FOCAL / trajectories.positions[..., 2].min()))
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * half_px + 1, 2 * half_px + 1))
    for t in range(len(trajectories.time_s)):
        material = occupancy(trajectories.positions[t], trajectories.F[t], trajectories.volumes, gaussians.K,
                             (SIZE, SIZE))
        material = cv2.erode(material.astype(np.uint8), disc) > 0
        assert material.sum() > 200, f"{name}, frame {t}"
        see_through = float((coarse.alpha[t][material] < 0.5).mean())
        assert see_through <= 0.01, f"{name}, frame {t}: {100 * see_through:.1f} % of the material is see-through"


def test_frame0_is_the_surface_render(simulated):
    """At rest the interior is hidden: frame 0 equals the render of the surface Gaussians alone."""
    _, gaussians, _, coarse = simulated
    surface = reconstruction_render(gaussians, SIZE, SIZE)
    assert np.abs(coarse.alpha[0] - surface.alpha.numpy()).max() < 2 / 255
    expected = (surface.features.clamp(0, 1).numpy() * 255 + 0.5).astype(int)
    assert np.abs(coarse.rgb[0].astype(int) - expected).max() <= 2


def bodies(alpha: np.ndarray, min_px: int) -> tuple[int, int]:
    """(pieces of at least min_px pixels, pixels in smaller pieces) of the solid picture (alpha >= 0.5)."""
    _, labels, stats, _ = cv2.connectedComponentsWithStats((alpha >= 0.5).astype(np.uint8), connectivity=8)
    areas = stats[1:, cv2.CC_STAT_AREA]
    return int((areas >= min_px).sum()), int(areas[areas < min_px].sum())


def test_torn_ball_ends_as_solid_pieces_without_dust(simulated):
    """Torn, the ball reads as solid bodies (each at least 5 % of the ball's picture at rest), the gaps
    between them empty; pieces under that hold under 1 % of the solid pixels (no dust). Cut in two
    and moved apart, two bodies; pulled apart by the simulation, at least two."""
    name, _, _, coarse = simulated
    if name not in (TORN_IN_TWO, "torn fracture ball"):
        pytest.skip("the tears only")
    rest_px = int((coarse.alpha[0] >= 0.5).sum())
    assert bodies(coarse.alpha[0], rest_px // 20)[0] == 1
    pieces, dust = bodies(coarse.alpha[-1], rest_px // 20)
    assert (pieces == 2 if name == TORN_IN_TWO else pieces >= 2), f"{name}: {pieces} bodies"
    assert dust < 0.01 * (coarse.alpha[-1] >= 0.5).sum(), f"{name}: {dust} px of dust"


def test_interior_takes_the_colour_of_the_surface_it_lies_under():
    """surface_under against a float64 brute-force nearest search among each object's opaque Gaussians."""
    rng = np.random.default_rng(3)
    means, object_id = rng.uniform(-1, 1, (300, 3)), rng.integers(0, 2, 300)
    opacity = rng.uniform(0, 1, 300)
    points, point_object = rng.uniform(-1, 1, (200, 3)), rng.integers(0, 2, 200)
    under = surface_under(points, point_object, means, object_id, opacity)
    for p, k, u in zip(points, point_object, under):
        candidates = np.flatnonzero((object_id == k) & (opacity >= 0.5))
        assert u == candidates[np.argmin(((means[candidates] - p) ** 2).sum(1))]


def test_flow_shows_the_interior_where_the_surface_opens(simulated):
    """Where the surface has opened and the interior shows in front (the render's distance a lattice
    spacing nearer than that of the Gaussians alone, rendered by splat), the photograph is not trusted:
    the flow backend shows the render's interior colour, never photograph pixels read through it (here
    a white photograph, which would stand out); nor re-lit, with relight on, over the sphere's black
    photograph and over one shaded by a light."""
    name, gaussians, trajectories, coarse = simulated
    if name not in (TORN_IN_TWO, "sand heap", "torn fracture ball"):
        pytest.skip("a surface that opens: the stretched jelly's stays whole")
    G = len(gaussians.means)
    t = lambda a: torch.as_tensor(a, dtype=torch.float32)  # noqa: E731
    F = t(trajectories.F[-1, :G])
    rest = splat.covariances_from_scales_rotations(t(gaussians.scales), t(gaussians.rotations))
    camera = splat.Camera(gaussians.K, gaussians.world_to_camera, SIZE, SIZE)
    surface = splat.rasterize(t(trajectories.positions[-1, :G]), t(gaussians.opacities), t(gaussians.colors),
                              camera, covariances=F @ rest @ F.transpose(1, 2))
    surface_distance = (surface.depth / surface.alpha.clamp_min(1e-6)).numpy()
    distance = coarse.depth[-1] / np.maximum(coarse.alpha[-1], 1e-6)
    opened = (coarse.alpha[-1] > 0.99) & (distance < surface_distance - lattice_spacing_of(trajectories))
    assert opened.sum() > 30, name
    photo = gaussians.photo.copy()
    gaussians.photo[:] = 255
    white = enhance_frames(coarse, gaussians, threshold=0.5, hidden_surfaces="photo", relight=False)
    gaussians.photo[:] = photo
    # the sphere's own photograph is black: no light fits it (fitted, its shading would be 0 everywhere)
    unlit = enhance_frames(coarse, gaussians, threshold=0.5, hidden_surfaces="photo", relight=True)
    # shaded by a light from the upper left, which the backend fits: the interior is not re-lit either
    light = np.array([-0.5, -0.5, -0.7]) / np.linalg.norm([-0.5, -0.5, -0.7])
    facing = np.clip(np.nan_to_num(coarse.normal[0]) @ light, 0, 1)  # camera-facing normals
    gaussians.photo[:] = (255 * (0.2 + 0.8 * facing))[..., None].astype(np.uint8)
    lit = enhance_frames(coarse, gaussians, threshold=0.5, hidden_surfaces="photo", relight=True)
    gaussians.photo[:] = photo
    rendered = coarse.rgb[-1].astype(float) / coarse.alpha[-1][..., None]
    for frames in (white, unlit, lit):
        # within the rgb's rounding (0.5 / alpha) and the at most 1 % of background behind alpha > 0.99 (2.55)
        assert np.abs(frames[-1][opened] - rendered[opened]).max() <= 0.5 / 0.99 + 0.01 * 255



def test_transmittance_layers_are_the_render_of_the_gaussians_in_front():
    """transmittance_layers against its reference: 1 - alpha of splat's render of only the Gaussians
    nearer than each depth, for random Gaussians at random depths."""
    rng = np.random.default_rng(5)
    n = 400
    means = torch.as_tensor(np.c_[rng.uniform(-0.2, 0.2, (n, 2)), rng.uniform(0.8, 1.2, n)], dtype=torch.float32)
    covariances = torch.as_tensor(np.eye(3) * rng.uniform(0.005, 0.02, (n, 1, 1)) ** 2, dtype=torch.float32)
    opacities = torch.as_tensor(rng.uniform(0.2, 0.9, n), dtype=torch.float32)
    K = np.array([[FOCAL, 0, SIZE / 2], [0, FOCAL, SIZE / 2], [0, 0, 1]])
    camera = splat.Camera(K, np.eye(4), SIZE, SIZE)
    depths = torch.linspace(0.85, 1.15, 40)  # more than one render's channels
    layers = transmittance_layers(means, covariances, opacities, depths, camera)
    for l in (0, 17, 39):
        nearer = means[:, 2] < depths[l]
        alone = splat.rasterize(means[nearer], opacities[nearer], torch.ones(int(nearer.sum()), 1), camera,
                                covariances=covariances[nearer])
        np.testing.assert_allclose(layers[l].numpy(), 1 - alone.alpha.numpy(), atol=1e-5)


def test_a_grain_is_a_hard_grain_the_size_of_the_lattice():
    """A grain alone (of sand, or of a torn solid's face), rendered by splat face-on: its alpha >= 1/2
    covers the projection of an ellipsoid of the volume of a ball of radius s GRAIN_SIGMA sqrt(2 ln 2)
    spacings, s its size over GRAIN_SIZES with a mean square of 1 (float64: the picture of the ellipsoid
    x^T C^-1 x <= 2 ln(2 opacity)), elongated GRAIN_ELONGATION; along a row through its centre its alpha
    falls from 0.9 to 0.1 within a quarter of its half-alpha radius there plus a pixel, where a Gaussian of
    opacity 1 and the lattice's standard deviation takes over 1.4 radii. The grains are turned at random:
    their long axes' mean |component| along each axis is that of directions uniform on the sphere, 1/2."""
    spacing = 0.03
    shapes, opacity = grain_shapes(np.full(1000, spacing), np.ones(1000, bool))
    radius = GRAIN_SIGMA * np.sqrt(2 * np.log(2)) * spacing
    level = 2 * np.log(2 * opacity[0])  # alpha 1/2 on x^T C^-1 x = level
    half_axes = np.sqrt(np.linalg.eigvalsh(shapes) * level)
    # sizes uniform over GRAIN_SIZES scaled to a mean square of 1
    sizes = np.cbrt(half_axes.prod(1)) / radius
    low, high = np.array(GRAIN_SIZES) / np.sqrt((GRAIN_SIZES[1] ** 3 - GRAIN_SIZES[0] ** 3) / (3 * np.ptp(GRAIN_SIZES)))
    assert low - 1e-9 <= sizes.min() < low + 0.02 and high - 0.02 < sizes.max() <= high + 1e-9
    assert abs(np.mean(sizes ** 2) - 1) < 0.05
    np.testing.assert_allclose(half_axes[:, 2] / half_axes[:, 0], GRAIN_ELONGATION, rtol=1e-9)
    long_axes = np.linalg.eigh(shapes)[1][:, :, 2]
    assert np.abs(np.abs(long_axes).mean(0) - 0.5).max() < 0.03
    soft = np.eye(3) * (GRAIN_SIGMA * spacing) ** 2
    size, focal = 201, 2000.0
    K = np.array([[focal, 0, size / 2], [0, focal, size / 2], [0, 0, 1]])
    camera = splat.Camera(K, np.eye(4), size, size)
    widths = []
    for C, o in ((shapes[0], opacity[0]), (soft, 1.0)):
        grain = splat.rasterize(torch.tensor([[0.0, 0.0, 1.0]]), torch.tensor([float(o)]), torch.ones(1, 1), camera,
                                covariances=torch.as_tensor(C, dtype=torch.float32)[None])
        alpha = grain.alpha.numpy()
        profile = alpha[size // 2, size // 2:]  # from the centre pixel outwards
        r = np.arange(len(profile))
        half_px = np.interp(0.5, profile[::-1], r[::-1])
        widths.append((np.interp(0.1, profile[::-1], r[::-1]) - np.interp(0.9, profile[::-1], r[::-1]), half_px))
        if o > 1:
            projected = np.linalg.inv(C[:2, :2] * focal ** 2)
            rows, cols = np.mgrid[0:size, 0:size] + 0.5 - size / 2
            pixels = np.stack([cols, rows], -1)
            inside = np.einsum("...i,ij,...j->...", pixels, projected, pixels) <= np.log(2 * o) * 2
            assert abs(int((alpha >= 0.5).sum()) - int(inside.sum())) <= 0.02 * inside.sum() + 2 * np.sqrt(inside.sum())
    (hard, hard_radius), (soft, soft_radius) = widths
    assert hard <= 0.25 * hard_radius + 1 and soft > 1.4 * soft_radius
