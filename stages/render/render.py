"""Coarse frames: the simulated Gaussians through splat, from the input camera (paper Sec. 3.2).

Each Gaussian k at frame t sits at x_k(t) with covariance F_k H_k F_k^T (H_k its
rest covariance, F_k the deformation gradient from the simulation). Beside the
colour we render, in a second pass voted by what the frame itself shows, each
Gaussian's affine map back into the photograph at rest, its surface normal now
and its visibility at rest (source_map.py). Their blend gives ``source_uv``
(where each pixel's surface was in the photograph; for a surface the photograph
never saw, the point of the photograph in front of it, whose colour the
reconstruction gave it), ``source_coherence`` (how smoothly the photograph maps
onto the frame there, and how well the surface in front agrees on where each
pixel came from), ``source_confidence`` (how visible the surface was at
rest, times the coherence) and ``normal``: the flow enhancement reads the
photograph through them and re-shades it.
"""
from __future__ import annotations

import logging

import torch

import splat
from schemas.artifacts import CoarseArtifact, GaussiansArtifact, TrajectoriesArtifact
from schemas.video import even_size

from .source_map import (AFFINE_CHANNELS, MIN_ALPHA, MIN_VOTE, MOMENT_CHANNELS, affine_source_maps, coherence,
                         facing_normals, inverse_deformation, map_moments, rest_visibility, source_points,
                         source_roughness, source_spread, surface_normals, visibility)

log = logging.getLogger("physmotion.render")


def render_camera(gaussians: GaussiansArtifact, width: int) -> splat.Camera:
    """The input camera at ``width`` pixels (capped at the photograph's, rounded to even sizes for H.264)."""
    w, h = even_size(min(width, gaussians.width), round(gaussians.height * min(width, gaussians.width) / gaussians.width))
    K = gaussians.K.copy()
    K[:2] *= w / gaussians.width
    return splat.Camera(torch.as_tensor(K), torch.as_tensor(gaussians.world_to_camera), w, h)


def render_video(gaussians: GaussiansArtifact, trajectories: TrajectoriesArtifact, width: int,
                 device: str) -> CoarseArtifact:
    """Render every frame of the trajectories; see the module docstring for the channels."""
    G = gaussians.means.shape[0]
    if trajectories.F.shape[1] != G:
        raise ValueError(f"trajectories hold {trajectories.F.shape[1]} Gaussians, gaussians.h5 {G}")
    t = lambda a: torch.as_tensor(a, device=device)  # noqa: E731
    camera = render_camera(gaussians, width)
    scale = camera.width / gaussians.width  # photo pixels -> output pixels
    rest_means, opacities, colors = t(gaussians.means), t(gaussians.opacities), t(gaussians.colors)
    rest_cov = splat.covariances_from_scales_rotations(t(gaussians.scales), t(gaussians.rotations))
    rest_seen = rest_visibility(rest_means, rest_cov, opacities, gaussians)
    rest_normals = surface_normals(rest_means)
    log.info("%d Gaussians, %.0f%% visible in the photograph; rendering %d frames at %dx%d",
             G, 100 * float((rest_seen > 0.5).float().mean()), trajectories.positions.shape[0],
             camera.width, camera.height)

    T = trajectories.positions.shape[0]
    out = {k: [] for k in ("rgb", "alpha", "depth", "source_uv", "source_coherence", "source_confidence", "normal")}
    with torch.no_grad():
        for frame in range(T):
            F, means = t(trajectories.F[frame]), t(trajectories.positions[frame, :G])
            covariances = F @ rest_cov @ F.transpose(1, 2)
            render = splat.rasterize(means, opacities, colors, camera, covariances=covariances)
            alpha = render.alpha
            covered = alpha >= MIN_ALPHA
            # Only the surface in front decides a pixel's source: what leaks through it from behind
            # (the far side, which maps to elsewhere in the photograph) would scatter the map.
            seen_now = visibility(render, means, covariances, camera)[:, None]
            votes = seen_now.clamp_min(MIN_VOTE)
            F_inverse = inverse_deformation(F)
            normals = facing_normals(rest_normals, means, F_inverse, gaussians.world_to_camera)
            maps = affine_source_maps(rest_means, means, normals, F_inverse, gaussians, camera.K)
            moments = map_moments(maps).to(votes.dtype)
            maps = maps.to(votes.dtype)
            # The spread of sources is taken over the surface in front alone (unfloored votes): a
            # per cent of the far side, leaking through from a source across the object, would
            # otherwise read as disagreement.
            voting = torch.cat([votes * torch.cat([maps, normals, rest_seen[:, None], torch.ones_like(votes)], 1),
                                seen_now * torch.cat([maps, moments, torch.ones_like(votes)], 1)], 1)
            channels = splat.rasterize(means, opacities, voting, camera, covariances=covariances).features
            voted_maps, normal, seen, voted, front_maps, front_moments, front_votes = channels.split(
                [AFFINE_CHANNELS, 3, 1, 1, AFFINE_CHANNELS, MOMENT_CHANNELS, 1], -1)
            voted = voted[..., 0].clamp_min(MIN_ALPHA)
            source_uv = torch.where(covered[..., None], source_points(voted_maps, voted), torch.nan)
            normal = normal / normal.norm(dim=-1, keepdim=True).clamp_min(1e-12)
            seen_fraction = (seen[..., 0] / voted).clamp(0, 1)
            front_votes = front_votes[..., 0]
            spread = source_spread(front_moments, front_votes, source_points(front_maps, front_votes))
            smooth = torch.where(covered, coherence(source_roughness(source_uv) * scale, spread * scale), 0.0)
            out["rgb"].append((render.features.clamp(0, 1) * 255 + 0.5).to(torch.uint8))
            out["alpha"].append(alpha)
            out["depth"].append(render.depth)
            out["source_uv"].append(source_uv)
            out["source_coherence"].append(smooth)
            out["source_confidence"].append(torch.where(covered, seen_fraction * smooth, 0.0))
            out["normal"].append(torch.where(covered[..., None], normal, torch.nan))
            surface = alpha > 0.5
            share = lambda x: 100 * float(x[surface].gt(0.5).float().mean()) if surface.any() else 0.0  # noqa: E731
            log.info("frame %d/%d rendered; of the surface %.0f%% maps smoothly from the photograph, %.0f%% was "
                     "seen in it", frame + 1, T, share(smooth), share(seen_fraction))
    arrays = {k: torch.stack(v).cpu().numpy() for k, v in out.items()}
    return CoarseArtifact(**arrays, K=camera.K, width=camera.width,
                          height=camera.height, fps=float(trajectories.fps))
