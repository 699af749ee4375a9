"""Coarse frames: the simulated Gaussians through splat, from the input camera (paper Sec. 3.2).

Each Gaussian k at frame t sits at x_k(t) with covariance F_k H_k F_k^T (H_k its
rest covariance, F_k the deformation gradient from the simulation). Beside the
colour we render, as extra feature channels in the same pass, where each
surface was in the photograph at rest (``source_uv``) and how far the
photograph can be trusted there (``source_confidence``: how visible the surface
was at rest, times how smoothly the photograph maps onto the frame there, see
:func:`source_roughness`): the flow
enhancement reads the photograph through them.
"""
from __future__ import annotations

import logging

import torch

import splat
from schemas.artifacts import CoarseArtifact, GaussiansArtifact, TrajectoriesArtifact
from schemas.video import even_size

log = logging.getLogger("physmotion.render")

MIN_ALPHA = 1.0 / 255
"""Below this accumulated alpha a pixel shows no surface: source_uv is NaN there."""
SMOOTH_SOURCE_PX = (2.0, 5.0)
"""Roughness of the source map (output pixels, see source_roughness) up to which the photograph
is fully trusted, and from which it is not trusted at all. Measured on the example scenes: at
rest 99 % of object pixels are below 2 px (the Gaussians' own lattice); where a surface tumbles
or flows the roughness jumps to tens or hundreds of pixels."""


def render_camera(gaussians: GaussiansArtifact, width: int) -> splat.Camera:
    """The input camera at ``width`` pixels (capped at the photograph's, rounded to even sizes for H.264)."""
    w, h = even_size(min(width, gaussians.width), round(gaussians.height * min(width, gaussians.width) / gaussians.width))
    K = gaussians.K.copy()
    K[:2] *= w / gaussians.width
    return splat.Camera(torch.as_tensor(K), torch.as_tensor(gaussians.world_to_camera), w, h)


def full_camera(gaussians: GaussiansArtifact) -> splat.Camera:
    return splat.Camera(torch.as_tensor(gaussians.K), torch.as_tensor(gaussians.world_to_camera),
                        gaussians.width, gaussians.height)


def project_to_photo(points: torch.Tensor, gaussians: GaussiansArtifact) -> torch.Tensor:
    """(N, 3) world points -> (N, 2) image points of the full-resolution photograph (pixel centres at +0.5)."""
    w2c = torch.as_tensor(gaussians.world_to_camera, dtype=points.dtype, device=points.device)
    K = torch.as_tensor(gaussians.K, dtype=points.dtype, device=points.device)
    cam = points @ w2c[:3, :3].T + w2c[:3, 3]
    z = cam[:, 2:3].clamp_min(1e-6)
    return (cam[:, :2] / z) * torch.stack([K[0, 0], K[1, 1]]) + K[:2, 2]


def rest_visibility(means: torch.Tensor, covariances: torch.Tensor, opacities: torch.Tensor,
                    gaussians: GaussiansArtifact) -> torch.Tensor:
    """(G,) in [0, 1]: how visible each Gaussian was in the photograph, by a soft depth test.

    A Gaussian was seen when it lies on the surface the photograph shows at its pixel: its
    distance to the camera at most a tolerance (twice its own largest standard deviation plus
    1 % of the distance) behind the rendered distance there (depth / alpha, Eq. 2). Gaussians
    of the back or the interior fall far behind and get ~0. (A ratio of blending weight to
    footprint cannot tell these apart: on a dense surface neighbours occlude each other too.)
    """
    camera = full_camera(gaussians)
    with torch.no_grad():
        rest = splat.rasterize(means, opacities, torch.zeros_like(means[:, :1]), camera, covariances=covariances)
        surface = rest.depth / rest.alpha.clamp_min(MIN_ALPHA)
        uv = project_to_photo(means, gaussians)
        col = uv[:, 0].floor().long().clamp(0, camera.width - 1)
        row = uv[:, 1].floor().long().clamp(0, camera.height - 1)
        w2c = torch.as_tensor(gaussians.world_to_camera, dtype=means.dtype, device=means.device)
        distance = (means @ w2c[:3, :3].T + w2c[:3, 3]).norm(dim=1)
        tolerance = 2 * torch.linalg.eigvalsh(covariances)[:, -1].clamp_min(0).sqrt() + 0.01 * distance
        behind = (distance - surface[row, col]).clamp_min(0)
        in_view = (uv[:, 0] >= 0) & (uv[:, 0] < camera.width) & (uv[:, 1] >= 0) & (uv[:, 1] < camera.height)
        seen = in_view & (rest.alpha[row, col] >= MIN_ALPHA)
        return torch.where(seen, torch.exp(-(behind / tolerance) ** 2), 0.0)


def fit_source_uv(means: torch.Tensor, covariances: torch.Tensor, opacities: torch.Tensor,
                  visibility: torch.Tensor, gaussians: GaussiansArtifact, iterations: int = 40) -> torch.Tensor:
    """(G, 2) per-Gaussian photo coordinates whose rest render maps every pixel onto itself.

    Pixels read the visibility-weighted blend  uv(p) = sum_k w_k c_k f_k / sum_k w_k c_k
    (w blending weights, c visibility). Blending the projected centres would shift it by a
    fraction of a pixel towards the Gaussians earlier in depth order and blur the photograph
    sampled there. The blend is linear in f, so we solve the least-squares problem
    min_f sum_p || sum_k w_k c_k f_k - (sum_k w_k c_k) p ||^2  (L-BFGS through the
    rasterizer's feature gradient) from the projected centres. Gaussians no pixel sees keep
    their projected centre.
    """
    camera = full_camera(gaussians)
    rows, cols = torch.meshgrid(torch.arange(camera.height, device=means.device),
                                torch.arange(camera.width, device=means.device), indexing="ij")
    centres = torch.stack([cols, rows], -1).to(means.dtype) + 0.5
    weight = visibility[:, None]
    with torch.no_grad():
        seen = splat.rasterize(means, opacities, weight, camera, covariances=covariances).features
    target = seen * centres
    uv = project_to_photo(means, gaussians).clone().requires_grad_(True)
    optimizer = torch.optim.LBFGS([uv], max_iter=iterations, history_size=10, line_search_fn="strong_wolfe",
                                  tolerance_grad=1e-10, tolerance_change=1e-14)

    def residual_loss():
        optimizer.zero_grad()
        blended = splat.rasterize(means, opacities, weight * uv, camera, covariances=covariances).features
        loss = (blended - target).square().sum()
        loss.backward()
        return loss

    before = float(residual_loss().detach())
    optimizer.step(residual_loss)
    total_weight = float(seen.square().sum().clamp_min(1e-12))
    log.info("source_uv fitted: rms error %.3f px -> %.3f px", (before / total_weight) ** 0.5,
             (float(residual_loss().detach()) / total_weight) ** 0.5)
    return uv.detach()


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


def coherence(roughness_px: torch.Tensor) -> torch.Tensor:
    """1 where the photograph maps smoothly onto the frame, falling to 0 where it does not
    (roughness in output pixels): sampling a jumbled source map would scatter the photograph's
    pixels into noise, so the render is trusted there instead."""
    low, high = SMOOTH_SOURCE_PX
    trusted = ((high - roughness_px) / (high - low)).clamp(0, 1)[None, None]
    # Trust changes over regions, not from pixel to pixel (which would speckle the frame with
    # alternating photo and render): a 3x3 minimum, then a 3x3 mean.
    regional = torch.nn.functional.avg_pool2d(-torch.nn.functional.max_pool2d(-trusted, 3, 1, 1), 3, 1, 1,
                                              count_include_pad=False)
    return regional[0, 0]


def render_video(gaussians: GaussiansArtifact, trajectories: TrajectoriesArtifact, width: int,
                 device: str) -> CoarseArtifact:
    """Render every frame of the trajectories; see the module docstring for the channels."""
    G = gaussians.means.shape[0]
    if trajectories.F.shape[1] != G:
        raise ValueError(f"trajectories hold {trajectories.F.shape[1]} Gaussians, gaussians.h5 {G}")
    t = lambda a: torch.as_tensor(a, device=device)  # noqa: E731
    camera = render_camera(gaussians, width)
    scale = camera.width / gaussians.width  # photo pixels -> output pixels
    rest_means, opacities = t(gaussians.means), t(gaussians.opacities)
    rest_cov = splat.covariances_from_scales_rotations(t(gaussians.scales), t(gaussians.rotations))
    visibility = rest_visibility(rest_means, rest_cov, opacities, gaussians)
    uv = fit_source_uv(rest_means, rest_cov, opacities, visibility, gaussians)
    # Only Gaussians the photograph saw vote on where a pixel reads it: channels c (u, v) and c.
    features = torch.cat([t(gaussians.colors), visibility[:, None] * uv, visibility[:, None]], 1)
    log.info("%d Gaussians, %.0f%% visible in the photograph; rendering %d frames at %dx%d",
             G, 100 * float((visibility > 0.5).float().mean()), trajectories.positions.shape[0],
             camera.width, camera.height)

    T = trajectories.positions.shape[0]
    out = {k: [] for k in ("rgb", "alpha", "depth", "source_uv", "source_confidence")}
    with torch.no_grad():
        for frame in range(T):
            F = t(trajectories.F[frame])
            render = splat.rasterize(t(trajectories.positions[frame, :G]), opacities, features, camera,
                                     covariances=F @ rest_cov @ F.transpose(1, 2))
            alpha, blended = render.alpha, render.features
            covered = alpha >= MIN_ALPHA
            seen = blended[..., 5]  # sum_k w_k c_k
            source_uv = torch.where(covered[..., None], blended[..., 3:5] / seen.clamp_min(1e-6)[..., None],
                                    float("nan"))
            smooth = coherence(source_roughness(source_uv) * scale)
            confidence = (seen / alpha.clamp_min(MIN_ALPHA)).clamp(0, 1) * smooth
            out["rgb"].append((blended[..., :3].clamp(0, 1) * 255 + 0.5).to(torch.uint8))
            out["alpha"].append(alpha)
            out["depth"].append(render.depth)
            out["source_uv"].append(source_uv)
            out["source_confidence"].append(torch.where(covered, confidence, 0.0))
            surface = covered & (seen > 0.5 * alpha)
            log.info("frame %d/%d rendered; %.0f%% of the seen surface maps smoothly from the photograph", frame + 1,
                     T, 100 * float(smooth[surface].gt(0.5).float().mean()) if surface.any() else 0.0)
    arrays = {k: torch.stack(v).cpu().numpy() for k, v in out.items()}
    return CoarseArtifact(**arrays, K=camera.K, width=camera.width,
                          height=camera.height, fps=float(trajectories.fps))
