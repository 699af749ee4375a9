"""Where each pixel of a coarse frame was in the photograph at rest, and how far to trust it.

Each Gaussian carries, per frame, an affine map from the frame's image points to
the photograph's (:func:`affine_source_maps`). Blended by the rasterizer like any
feature, the maps give every pixel its source point; at rest they are the
identity for every Gaussian, so the source map is exact there without any fit,
and under motion each Gaussian carries its own patch of the photograph with it.
"""
from __future__ import annotations

import numpy as np
import torch
from scipy.spatial import cKDTree

import splat
from schemas.artifacts import GaussiansArtifact
from schemas.camera import project_points

MIN_ALPHA = 1.0 / 255
"""Below this accumulated alpha a pixel shows no surface: source_uv is NaN there."""
SMOOTH_SOURCE_PX = (2.0, 5.0)
"""Roughness of the source map (output pixels, see source_roughness) up to which the photograph
is fully trusted, and from which it is not trusted at all. Where a surface tumbles or flows
neighbouring pixels read places of the photograph tens or hundreds of pixels apart."""
SOURCE_SPREAD_PX = (4.0, 8.0)
"""Spread of the sources that the surface in front gives a pixel (output pixels, see source_spread)
up to which the photograph is fully trusted, and from which it is not trusted at all. Where material
mixes (sand, debris) grains from far-apart places of the photograph overlap, and their blended map
can be smooth and still read a place that is none of theirs. Measured on the examples' last frames:
the sand logo over 4 px on 46 % of its surface (median 3.5 px, 90th percentile 40 px); the bouncing
ball on 4 % (its rim and folds), the swaying cup on 1 %."""
INTERIOR_SHARE = (0.05, 0.3)
"""Share of a pixel's colour from the interior (the fill particles, which the photograph never saw) up
to which the photograph is fully trusted there, and from which it is not trusted at all: a tenth of
torn face under a photograph read through it would already be a visible ghost of the surface."""
MIN_GRAZING_COS = 0.1
"""Cosine between the normal of a Gaussian's plane and the view ray below which its lift is clamped: a plane
seen edge-on would map one pixel of the frame onto an unbounded stretch of the photograph."""
MIN_VOTE = 0.01
"""Vote on a pixel's source of a Gaussian that is not on the surface in front, so that a pixel
showing only such Gaussians still gets a source."""
SURFACE_NEIGHBOURS = 16
"""Nearest Gaussian centres whose plane of least spread is taken as the surface at a Gaussian."""
AFFINE_CHANNELS = 6
"""Feature channels of an affine source map: the offset b (2) and the Jacobian J row-major (4)."""
MOMENT_CHANNELS = 6
"""Feature channels of an affine map's second moments (:func:`map_moments`)."""


def full_camera(gaussians: GaussiansArtifact) -> splat.Camera:
    """The photograph's camera, at its full resolution."""
    return splat.Camera(torch.as_tensor(gaussians.K), torch.as_tensor(gaussians.world_to_camera),
                        gaussians.width, gaussians.height)


def to_camera(points, world_to_camera):
    """(..., 3) world points (m) -> (..., 3) camera-frame points, of the type of ``points`` (a torch tensor
    or a numpy array); world_to_camera (4, 4), torch or numpy."""
    if isinstance(points, torch.Tensor):
        w2c = torch.as_tensor(world_to_camera, dtype=points.dtype, device=points.device)
    else:
        w2c = np.asarray(world_to_camera, dtype=points.dtype)
    return points @ w2c[:3, :3].T + w2c[:3, 3]


def visibility(surface: splat.Render, means: torch.Tensor, covariances: torch.Tensor,
               camera: splat.Camera) -> torch.Tensor:
    """(G,) in [0, 1]: how visible each Gaussian is in a render of them, by a soft depth test.

    A Gaussian is seen when it lies on the surface the render shows at its pixel: its distance
    to the camera at most a tolerance (twice its own largest standard deviation plus 1 % of the
    distance) behind the rendered distance there (depth / alpha, Eq. 2). Gaussians of the back or
    the interior fall far behind and get ~0. (A ratio of blending weight to footprint cannot tell
    these apart: on a dense surface neighbours occlude each other too.) What leaks through a
    surface only pulls the rendered distance deeper, towards calling more of that surface seen.

    Args:
        surface: the render of these Gaussians from ``camera``.
        means: (G, 3) world positions; covariances: (G, 3, 3), as rendered.
    """
    K = torch.as_tensor(camera.K, dtype=means.dtype, device=means.device)
    in_camera = to_camera(means, camera.world_to_camera)
    uv = project_points(in_camera, K)
    col = uv[:, 0].floor().long().clamp(0, camera.width - 1)
    row = uv[:, 1].floor().long().clamp(0, camera.height - 1)
    distance = in_camera.norm(dim=1)
    tolerance = 2 * torch.linalg.eigvalsh(covariances)[:, -1].clamp_min(0).sqrt() + 0.01 * distance
    rendered = surface.depth / surface.alpha.clamp_min(MIN_ALPHA)
    behind = (distance - rendered[row, col]).clamp_min(0)
    in_view = (uv[:, 0] >= 0) & (uv[:, 0] < camera.width) & (uv[:, 1] >= 0) & (uv[:, 1] < camera.height)
    shown = in_view & (in_camera[:, 2] > 0) & (surface.alpha[row, col] >= MIN_ALPHA)
    return torch.where(shown, torch.exp(-(behind / tolerance) ** 2), 0.0)


def rest_visibility(means: torch.Tensor, covariances: torch.Tensor, opacities: torch.Tensor,
                    gaussians: GaussiansArtifact) -> torch.Tensor:
    """(G,) in [0, 1]: how visible each Gaussian was in the photograph (:func:`visibility`)."""
    camera = full_camera(gaussians)
    with torch.no_grad():
        rest = splat.rasterize(means, opacities, torch.zeros_like(means[:, :1]), camera, covariances=covariances)
        return visibility(rest, means, covariances, camera)


def surface_normals(rest_means: torch.Tensor, neighbours: int = SURFACE_NEIGHBOURS) -> torch.Tensor:
    """(G, 3) unit normal of the surface at each Gaussian at rest (sign arbitrary): the direction
    of least spread of its nearest centres. The Gaussians' own shapes do not say it: fitted from
    one view they lie flat towards the camera, and the ones behind are round."""
    points = rest_means.detach().cpu().double().numpy()
    _, nearest = cKDTree(points).query(points, k=min(neighbours, len(points)))
    patches = points[nearest] - points[nearest].mean(1, keepdims=True)
    _, vectors = np.linalg.eigh(np.einsum("gki,gkj->gij", patches, patches))
    return torch.as_tensor(vectors[:, :, 0], device=rest_means.device)


def affine_source_maps(rest_means: torch.Tensor, means: torch.Tensor, normals: torch.Tensor, F_inverse: torch.Tensor,
                       gaussians: GaussiansArtifact, K_frame: torch.Tensor) -> torch.Tensor:
    """(G, 6) per Gaussian, the affine map  uv = b + J p  from image points p of the frame
    (intrinsics K_frame, the photograph's pose) to image points uv of the full-resolution photograph.

    Each Gaussian stands for a patch of surface: at rest the plane through X_k with normal N_k,
    now, carried by its motion and deformation, the plane through x_k with normal F^-T N_k
    (:func:`facing_normals`). A pixel is lifted onto that plane, taken back to rest
    (X = X_k + F^-1 (x - x_k)) and projected into the photograph; J is that chain's derivative at
    the Gaussian's centre, b makes the centre land on X_k's projection. At rest (F = I) every map
    is exactly the change of resolution, so their blend is too. A surface the photograph never saw
    (the back) maps onto the point of the photograph in front of it.

    Args:
        rest_means, means: (G, 3) centres at rest and now, metres, world frame.
        normals: (G, 3) surface normals now, camera frame (:func:`facing_normals`).
        F_inverse: (G, 3, 3) inverses of the deformation gradients (:func:`inverse_deformation`).
        K_frame: (3, 3) intrinsics of the frame.
    Returns:
        (G, 6) float64: b (2) and J (2 x 2, row-major) in photograph pixels per frame pixel.
    """
    f64 = lambda a: torch.as_tensor(a, dtype=torch.float64, device=means.device)  # noqa: E731
    R = f64(gaussians.world_to_camera)[:3, :3]
    K_photo, K_frame = f64(gaussians.K), f64(K_frame)
    F_inverse = f64(F_inverse)
    centre, normal = to_camera(f64(means), gaussians.world_to_camera), f64(normals)
    facing = (normal * centre).sum(-1)
    limit = MIN_GRAZING_COS * normal.norm(dim=-1) * centre.norm(dim=-1)
    facing = torch.where(facing < 0, -1.0, 1.0) * torch.maximum(facing.abs(), limit)
    # d x / d p on the plane at the centre's pixel: z (I - c n^T / n.c) K^-1 restricted to (u, v)
    eye = torch.eye(3, dtype=torch.float64, device=means.device)
    lift = centre[:, 2, None, None] * (eye - centre[:, :, None] * normal[:, None, :] / facing[:, None, None]) \
        @ torch.linalg.inv(K_frame)[:, :2]
    to_rest = F_inverse @ R.T @ lift  # (G, 3, 2) world displacement at rest per pixel
    rest_cam = to_camera(f64(rest_means), gaussians.world_to_camera)
    z = rest_cam[:, 2].clamp_min(1e-9)
    zero = torch.zeros_like(z)
    d_project = torch.stack([torch.stack([K_photo[0, 0] / z, zero, -K_photo[0, 0] * rest_cam[:, 0] / z ** 2], -1),
                             torch.stack([zero, K_photo[1, 1] / z, -K_photo[1, 1] * rest_cam[:, 1] / z ** 2], -1)], 1)
    J = d_project @ R @ to_rest
    b = project_points(rest_cam, K_photo) - (J @ project_points(centre, K_frame)[..., None])[..., 0]
    return torch.cat([b, J.reshape(-1, 4)], 1)


CRUSHED_DET = 1e-9
"""det F below which (relative to |F|^3, Frobenius) a deformation counts as crushed flat."""


def inverse_deformation(F: torch.Tensor) -> torch.Tensor:
    """(G, 3, 3) float64 F^-1 of each particle's deformation gradient, as a pseudo-inverse for a
    particle crushed flat (rank-deficient F), which so keeps a finite normal and source map. The
    others take the plain inverse (equal to the pseudo-inverse, at a fifth of the SVD's time)."""
    F = F.to(torch.float64)
    crushed = torch.linalg.det(F).abs() <= CRUSHED_DET * F.flatten(1).norm(dim=1) ** 3
    inverse = torch.linalg.inv_ex(F)[0]
    if crushed.any():
        inverse[crushed] = torch.linalg.pinv(F[crushed])
    return inverse


def facing_normals(rest_normals: torch.Tensor, means: torch.Tensor, F_inverse: torch.Tensor,
                   world_to_camera: torch.Tensor) -> torch.Tensor:
    """(G, 3) unit normals of the surface at each Gaussian now, camera frame, turned towards the
    camera: the rest normals carried by the deformation (F^-T N). Any surface the camera sees
    faces it, so the side the normal points to needs no bookkeeping from rest.

    Args:
        rest_normals: (G, 3) world frame (:func:`surface_normals`); means: (G, 3) centres now;
        F_inverse: (G, 3, 3) (:func:`inverse_deformation`); world_to_camera: (4, 4).
    """
    R = torch.as_tensor(world_to_camera, dtype=means.dtype, device=means.device)[:3, :3]
    normals = (rest_normals.to(means.dtype)[:, None, :] @ F_inverse.to(means.dtype))[:, 0] @ R.T
    normals = normals / normals.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    towards_camera = (to_camera(means, world_to_camera) * normals).sum(-1) < 0
    return torch.where(towards_camera[:, None], normals, -normals)


def pixel_centres(h: int, w: int, like: torch.Tensor) -> torch.Tensor:
    """(h, w, 2) image points (x, y) of the pixel centres, in ``like``'s dtype and device."""
    rows, cols = torch.meshgrid(torch.arange(h, device=like.device), torch.arange(w, device=like.device),
                                indexing="ij")
    return torch.stack([cols, rows], -1).to(like.dtype) + 0.5


def source_points(voted_maps: torch.Tensor, votes: torch.Tensor) -> torch.Tensor:
    """(h, w, 2) each pixel's source point: the vote-weighted blend of the Gaussians' affine maps
    applied to it.

    Args:
        voted_maps: (h, w, 6) sum_k w_k v_k [b_k, J_k] as rendered (w blending weights, v votes).
        votes: (h, w) sum_k w_k v_k.
    Returns:
        Photograph image points; NaN where nothing voted (below MIN_ALPHA).
    """
    h, w = votes.shape
    p = pixel_centres(h, w, voted_maps)
    J = voted_maps[..., 2:].reshape(h, w, 2, 2)
    uv = (voted_maps[..., :2] + (J @ p[..., None])[..., 0]) / votes.clamp_min(MIN_ALPHA)[..., None]
    return torch.where((votes >= MIN_ALPHA)[..., None], uv, float("nan"))


def map_moments(maps: torch.Tensor) -> torch.Tensor:
    """(G, 6) the second moments of each Gaussian's affine map uv = b + J p, as constants that blend like
    features: |b + J p|^2 = b.b + 2 (J^T b).p + p^T (J^T J) p. Columns: b.b, J^T b (2), and
    (J^T J)_00, _01, _11.

    Args:
        maps: (G, 6) from :func:`affine_source_maps`.
    """
    b, J = maps[:, :2], maps[:, 2:].reshape(-1, 2, 2)
    JtJ = J.transpose(1, 2) @ J
    return torch.cat([(b * b).sum(-1, keepdim=True), (J.transpose(1, 2) @ b[..., None])[..., 0],
                      JtJ[:, 0, :], JtJ[:, 1, 1:]], 1)


def source_spread(voted_moments: torch.Tensor, votes: torch.Tensor, source_uv: torch.Tensor) -> torch.Tensor:
    """(h, w) how far apart the sources are that the Gaussians covering a pixel give it: the
    vote-weighted standard deviation of their maps applied to the pixel, in photograph pixels;
    0 where nothing voted.

    Args:
        voted_moments: (h, w, 6) sum_k w_k v_k moments_k as rendered (:func:`map_moments`).
        votes: (h, w) sum_k w_k v_k.
        source_uv: (h, w, 2) their mean (:func:`source_points`).
    """
    p = pixel_centres(*votes.shape, voted_moments)
    square, linear, quadratic = voted_moments.split([1, 2, 3], -1)
    x, y = p[..., 0], p[..., 1]
    mean_square = (square[..., 0] + 2 * (linear * p).sum(-1) + quadratic[..., 0] * x * x
                   + 2 * quadratic[..., 1] * x * y + quadratic[..., 2] * y * y) / votes.clamp_min(MIN_ALPHA)
    variance = (mean_square - source_uv.square().sum(-1)).clamp_min(0)
    return torch.nan_to_num(variance.sqrt(), nan=0.0)


def source_roughness(source_uv: torch.Tensor) -> torch.Tensor:
    """(h, w) how far the source map departs from an affine one at each pixel, in its own units.

    Second differences along x and y, where both neighbours have a source: exactly 0 for any
    affine motion of the surface (translation, rotation, stretch), about a pixel for a smooth
    bend, and large where the surface tumbled, tore or flowed, so that neighbouring pixels
    read far-apart places of the photograph.
    """
    rough = torch.zeros(source_uv.shape[:2], dtype=source_uv.dtype, device=source_uv.device)
    for axis in (0, 1):
        before, after = source_uv.roll(1, axis), source_uv.roll(-1, axis)
        second = (before + after - 2 * source_uv).square().sum(-1)
        inside = torch.ones_like(rough, dtype=torch.bool)
        inside.narrow(axis, 0, 1).fill_(False)
        inside.narrow(axis, source_uv.shape[axis] - 1, 1).fill_(False)
        rough += torch.where(inside & second.isfinite(), second, 0.0)
    return rough.sqrt()


def falling_ramp(x: torch.Tensor, bounds: tuple[float, float]) -> torch.Tensor:
    """1 up to bounds[0], 0 from bounds[1], linear between."""
    return ((bounds[1] - x) / (bounds[1] - bounds[0])).clamp(0, 1)


def coherence(roughness_px: torch.Tensor, spread_px: torch.Tensor, surface_share: torch.Tensor) -> torch.Tensor:
    """1 where the photograph maps smoothly onto the frame, the Gaussians covering each pixel
    agree on where it came from and what the pixel shows in front is the object's surface, falling
    to 0 where any fails (roughness and spread in output pixels; surface_share in [0, 1], the
    surface's share of the front, the rest being interior): sampling a jumbled source map would
    scatter the photograph's pixels into noise, a blend of disagreeing sources reads a place that
    none of them came from, and the interior (a torn face, grains) was never in the photograph,
    whose surface in front of it would be scattered over it; the render is trusted there instead."""
    trusted = (falling_ramp(roughness_px, SMOOTH_SOURCE_PX) * falling_ramp(spread_px, SOURCE_SPREAD_PX)
               * falling_ramp(1 - surface_share, INTERIOR_SHARE))
    trusted = trusted[None, None]
    # Trust changes over regions, not from pixel to pixel (which would speckle the frame with
    # alternating photo and render): a 3x3 minimum, then a 3x3 mean.
    regional = torch.nn.functional.avg_pool2d(-torch.nn.functional.max_pool2d(-trusted, 3, 1, 1), 3, 1, 1,
                                              count_include_pad=False)
    return regional[0, 0]
