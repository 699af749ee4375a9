"""Coarse frames: the simulated Gaussians through splat, from the input camera (paper Sec. 3.2).

Each Gaussian k at frame t sits at x_k(t) with covariance F_k H_k F_k^T (H_k its
rest covariance, F_k the deformation gradient from the simulation). Beside the
colour we render, as extra feature channels in the same pass, where each
surface was in the photograph at rest (``source_uv``) and how visible it was
there (``source_confidence``): the flow enhancement reads the photograph
through them.
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
                  gaussians: GaussiansArtifact, iterations: int = 40) -> torch.Tensor:
    """(G, 2) per-Gaussian photo coordinates whose rest render maps every pixel onto itself.

    Blending the projected centres would not: at a pixel, Gaussians earlier in depth order
    weigh more, which shifts the blended coordinate by a fraction of a pixel and blurs the
    photograph when it is sampled there. The blend is linear in the features, so we solve
    the least-squares problem  min_f  sum_p || sum_k w_k(p) f_k - alpha(p) p ||^2  (L-BFGS
    through the rasterizer's feature gradient), starting from the projected centres.
    Gaussians no pixel sees keep their projected centre.
    """
    camera = full_camera(gaussians)
    rows, cols = torch.meshgrid(torch.arange(camera.height, device=means.device),
                                torch.arange(camera.width, device=means.device), indexing="ij")
    centres = torch.stack([cols, rows], -1).to(means.dtype) + 0.5
    with torch.no_grad():
        alpha = splat.rasterize(means, opacities, torch.zeros_like(means[:, :1]), camera,
                                covariances=covariances).alpha
    target = alpha[..., None] * centres
    uv = project_to_photo(means, gaussians).clone().requires_grad_(True)
    optimizer = torch.optim.LBFGS([uv], max_iter=iterations, history_size=10, line_search_fn="strong_wolfe",
                                  tolerance_grad=1e-10, tolerance_change=1e-14)

    def residual_loss():
        optimizer.zero_grad()
        loss = (splat.rasterize(means, opacities, uv, camera, covariances=covariances).features - target).square().sum()
        loss.backward()
        return loss

    before = float(residual_loss().detach())
    optimizer.step(residual_loss)
    covered = float((alpha >= MIN_ALPHA).sum().clamp_min(1))
    log.info("source_uv fitted: rms error %.3f px -> %.3f px", (before / covered) ** 0.5,
             (float(residual_loss().detach()) / covered) ** 0.5)
    return uv.detach()


def render_video(gaussians: GaussiansArtifact, trajectories: TrajectoriesArtifact, width: int,
                 device: str) -> CoarseArtifact:
    """Render every frame of the trajectories; see the module docstring for the channels."""
    G = gaussians.means.shape[0]
    if trajectories.F.shape[1] != G:
        raise ValueError(f"trajectories hold {trajectories.F.shape[1]} Gaussians, gaussians.h5 {G}")
    t = lambda a: torch.as_tensor(a, device=device)  # noqa: E731
    camera = render_camera(gaussians, width)
    rest_means, opacities = t(gaussians.means), t(gaussians.opacities)
    rest_cov = splat.covariances_from_scales_rotations(t(gaussians.scales), t(gaussians.rotations))
    visibility = rest_visibility(rest_means, rest_cov, opacities, gaussians)
    source_uv = fit_source_uv(rest_means, rest_cov, opacities, gaussians)
    features = torch.cat([t(gaussians.colors), source_uv, visibility[:, None]], 1)
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
            alpha = render.alpha
            covered = (alpha >= MIN_ALPHA)[..., None]
            per_surface = render.features[..., 3:] / alpha.clamp_min(MIN_ALPHA)[..., None]  # un-blend uv, confidence
            out["rgb"].append((render.features[..., :3].clamp(0, 1) * 255 + 0.5).to(torch.uint8))
            out["alpha"].append(alpha)
            out["depth"].append(render.depth)
            out["source_uv"].append(torch.where(covered, per_surface[..., :2], float("nan")))
            out["source_confidence"].append(torch.where(covered[..., 0], per_surface[..., 2].clamp(0, 1), 0.0))
            log.info("frame %d/%d rendered", frame + 1, T)
    arrays = {k: torch.stack(v).cpu().numpy() for k, v in out.items()}
    return CoarseArtifact(**arrays, K=camera.K, width=camera.width,
                          height=camera.height, fps=float(trajectories.fps))
