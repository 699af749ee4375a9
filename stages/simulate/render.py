"""Coarse frames: the simulated Gaussians through splat, from the input camera (paper Sec. 3.2).

Each Gaussian k at frame t sits at x_k(t) with covariance F_k H_k F_k^T (H_k its
rest covariance, F_k the deformation gradient from the simulation). Beside the
colour we render, as extra feature channels in the same pass, where each
surface was in the photograph at rest (``source_uv``; for a surface the
photograph never saw, the point of the photograph in front of it, whose colour
the reconstruction gave it), how smoothly the photograph maps onto the frame
there (``source_coherence``, see :func:`source_roughness`) and how far the
photograph can be trusted there (``source_confidence``: how visible the surface
was at rest, times the coherence): the flow enhancement reads the photograph
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
SMOOTH_SOURCE_PX = (2.0, 5.0)
"""Roughness of the source map (output pixels, see source_roughness) up to which the photograph
is fully trusted, and from which it is not trusted at all. Measured on the example scenes: at
rest 99 % of object pixels are below 2 px (the Gaussians' own lattice); where a surface tumbles
or flows the roughness jumps to tens or hundreds of pixels."""


ANCHOR = 1e-3
"""Weight of the pull of each Gaussian's source point towards its projected centre in the fit
(fit_source_uv), per px^2; a Gaussian that alone covers a pixel weighs ~1 there."""


HIDDEN_VOTE = 0.05
"""Weight of a hidden surface's vote on a pixel's source point relative to a seen one's (see
prefer_seen). Measured on the coffee scene mid-sway (frame 4): the mean source_coherence inside
the cup is 0.55 when every surface votes by its blending weight, 0.86 with this weight."""


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
                  votes: torch.Tensor, gaussians: GaussiansArtifact, iterations: int = 40) -> torch.Tensor:
    """(G, 2) per-Gaussian photo coordinates whose rest render maps every pixel onto itself.

    Only the voting Gaussians (votes (G,) in [0, 1]) say where a pixel reads the photograph:
    the blend  uv(p) = sum_k w_k v_k f_k / sum_k w_k v_k  (w blending weights). Blending the
    projected centres g_k would shift it by a fraction of a pixel towards the Gaussians
    earlier in depth order and blur the photograph sampled there. The blend is linear in f,
    so we solve the least-squares problem
        min_f sum_p || sum_k w_k v_k f_k - (sum_k w_k v_k) p ||^2 + ANCHOR sum_k || f_k - g_k ||^2
    (L-BFGS through the rasterizer's feature gradient) from the projected centres. Gaussians
    that barely vote or are barely seen hardly enter the first term, so without the anchor
    L-BFGS would carry them anywhere; with it they keep their projected centre.
    """
    camera = full_camera(gaussians)
    rows, cols = torch.meshgrid(torch.arange(camera.height, device=means.device),
                                torch.arange(camera.width, device=means.device), indexing="ij")
    centres = torch.stack([cols, rows], -1).to(means.dtype) + 0.5
    weight = votes[:, None]
    with torch.no_grad():
        seen = splat.rasterize(means, opacities, weight, camera, covariances=covariances).features
    target = seen * centres
    projected = project_to_photo(means, gaussians)
    uv = projected.clone().requires_grad_(True)
    optimizer = torch.optim.LBFGS([uv], max_iter=iterations, history_size=10, line_search_fn="strong_wolfe",
                                  tolerance_grad=1e-10, tolerance_change=1e-14)

    def residual_loss():
        optimizer.zero_grad()
        blended = splat.rasterize(means, opacities, weight * uv, camera, covariances=covariances).features
        loss = (blended - target).square().sum() + ANCHOR * (uv - projected).square().sum()
        loss.backward()
        return loss

    before = float(residual_loss().detach())
    optimizer.step(residual_loss)
    total_weight = float(seen.square().sum().clamp_min(1e-12))
    log.info("source_uv fitted: rms error %.3f px -> %.3f px", (before / total_weight) ** 0.5,
             (float(residual_loss().detach()) / total_weight) ** 0.5)
    return uv.detach()


def source_points(means: torch.Tensor, covariances: torch.Tensor, opacities: torch.Tensor,
                  visibility: torch.Tensor, gaussians: GaussiansArtifact) -> torch.Tensor:
    """(G, 2) where each Gaussian's surface was in the photograph at rest (full-resolution image points).

    Seen Gaussians are fitted in the photograph's view; hidden ones (the back, the interior) in
    the view of the hidden Gaussians alone, which is what shows once the seen surface moves
    away: their source is the point of the photograph in front of them, whose colour the
    reconstruction gave them too. Partly seen Gaussians mix the two by their visibility.
    """
    seen = fit_source_uv(means, covariances, opacities, visibility, gaussians)
    hidden = fit_source_uv(means, covariances, opacities * (1 - visibility), 1 - visibility, gaussians)
    return visibility[:, None] * seen + (1 - visibility[:, None]) * hidden


def prefer_seen(seen_sum: torch.Tensor, seen: torch.Tensor, hidden_sum: torch.Tensor,
                hidden: torch.Tensor) -> torch.Tensor:
    """(h, w, 2) a pixel's source point: the seen surfaces' blend wherever they show at all.

    Hidden surfaces poke through the seen ones unevenly once the object deforms, and their
    source points need not agree with those in front; letting them vote by their blending
    weight would scatter the map. They are down-weighted by HIDDEN_VOTE instead, so they only
    decide where hardly any seen surface covers the pixel (the back, once turned to the camera).

    Args:
        seen_sum, hidden_sum: (h, w, 2) sum_k w_k c_k f_k and sum_k w_k (1 - c_k) f_k.
        seen, hidden: (h, w) sum_k w_k c_k and sum_k w_k (1 - c_k).
    """
    weight = (seen + HIDDEN_VOTE * hidden).clamp_min(1e-6)
    return (seen_sum + HIDDEN_VOTE * hidden_sum) / weight[..., None]


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
    uv = source_points(rest_means, rest_cov, opacities, visibility, gaussians)
    c = visibility[:, None]
    features = torch.cat([t(gaussians.colors), c * uv, c, (1 - c) * uv], 1)
    log.info("%d Gaussians, %.0f%% visible in the photograph; rendering %d frames at %dx%d",
             G, 100 * float((visibility > 0.5).float().mean()), trajectories.positions.shape[0],
             camera.width, camera.height)

    T = trajectories.positions.shape[0]
    out = {k: [] for k in ("rgb", "alpha", "depth", "source_uv", "source_coherence", "source_confidence")}
    with torch.no_grad():
        for frame in range(T):
            F = t(trajectories.F[frame])
            render = splat.rasterize(t(trajectories.positions[frame, :G]), opacities, features, camera,
                                     covariances=F @ rest_cov @ F.transpose(1, 2))
            alpha, blended = render.alpha, render.features
            covered = alpha >= MIN_ALPHA
            seen = blended[..., 5]  # sum_k w_k c_k, c the visibility at rest
            source_uv = torch.where(covered[..., None], prefer_seen(blended[..., 3:5], seen, blended[..., 6:8],
                                                                    alpha - seen), float("nan"))
            smooth = torch.where(covered, coherence(source_roughness(source_uv) * scale), 0.0)
            seen_fraction = (seen / alpha.clamp_min(MIN_ALPHA)).clamp(0, 1)
            out["rgb"].append((blended[..., :3].clamp(0, 1) * 255 + 0.5).to(torch.uint8))
            out["alpha"].append(alpha)
            out["depth"].append(render.depth)
            out["source_uv"].append(source_uv)
            out["source_coherence"].append(smooth)
            out["source_confidence"].append(torch.where(covered, seen_fraction * smooth, 0.0))
            surface = alpha > 0.5
            share = lambda x: 100 * float(x[surface].gt(0.5).float().mean()) if surface.any() else 0.0  # noqa: E731
            log.info("frame %d/%d rendered; of the surface %.0f%% maps smoothly from the photograph, %.0f%% was "
                     "seen in it", frame + 1, T, share(smooth), share(seen_fraction))
    arrays = {k: torch.stack(v).cpu().numpy() for k, v in out.items()}
    return CoarseArtifact(**arrays, K=camera.K, width=camera.width,
                          height=camera.height, fps=float(trajectories.fps))
