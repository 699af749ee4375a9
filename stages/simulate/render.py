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
import math

import torch

import splat
from splat.project import project_gaussians
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
                    camera: splat.Camera) -> torch.Tensor:
    """(G,) in [0, 1]: the fraction of each Gaussian's footprint that reached the photograph.

    Its blending weight summed over pixels, sum_p T_k(p) alpha_k(p), is the gradient of the
    summed render with respect to its feature; dividing by its unoccluded footprint
    sum_p alpha_k(p) ~ o_k 2 pi sqrt(det Sigma2D_k) leaves how much of it was in front.
    """
    features = torch.ones(means.shape[0], 1, device=means.device, requires_grad=True)
    rendered = splat.rasterize(means, opacities, features, camera, covariances=covariances).features
    (weight_sum,) = torch.autograd.grad(rendered.sum(), features)
    with torch.no_grad():
        conics = project_gaussians(means, covariances, camera).conics  # (a, b, c) of Sigma2D^-1
        det_conic = (conics[:, 0] * conics[:, 2] - conics[:, 1] ** 2).clamp_min(1e-12)
        footprint = opacities * 2 * math.pi / det_conic.sqrt()
        visible = torch.where(conics.abs().sum(1) > 0, weight_sum[:, 0] / footprint.clamp_min(1e-12), 0.0)
    return visible.clamp(0.0, 1.0)


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
    visibility = rest_visibility(rest_means, rest_cov, opacities, full_camera(gaussians))
    features = torch.cat([t(gaussians.colors), project_to_photo(rest_means, gaussians), visibility[:, None]], 1)
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
