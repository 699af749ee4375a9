"""Slow float64 oracle for splat: every Gaussian against every pixel, pure torch.

Written from DESIGN.md's rules, independently of the Warp path (no shared code,
other formulas where there is a choice): quaternions through the Rodrigues
form, the 2D covariance inverted by torch.linalg, the front-to-back order by a
stable sort of z, transmittance by a cumulative product.

Besides the render, it returns a mask of the pixels whose value or gradient
float32 rounding cannot change discontinuously: no Gaussian's alpha within 1e-3
relative of 1/255 or of the 0.99 clamp, no transmittance within 1e-3 relative of the 1e-4 stop, no
two Gaussians reaching the pixel at depths that differ by float32 rounding
only (1e-6 relative, unless exactly equal), no Gaussian within rounding of the
near plane.
"""
from __future__ import annotations

from typing import NamedTuple

import torch

NEAR = 0.01
ALPHA_MIN = 1.0 / 255.0
ALPHA_MAX = 0.99
T_MIN = 1e-4
DILATION = 0.3
FOV_CLAMP = 1.3
THRESHOLD_RTOL = 1e-3
DEPTH_TIE_RTOL = 1e-6
MAX_PAIRS_PER_CHUNK = 2_000_000


class ReferenceRender(NamedTuple):
    features: torch.Tensor  # (H, W, C)
    alpha: torch.Tensor  # (H, W)
    depth: torch.Tensor  # (H, W)
    reliable: torch.Tensor  # (H, W) bool


def reference_covariances(scales: torch.Tensor, rotations: torch.Tensor) -> torch.Tensor:
    """R diag(s^2) R^T with R = (w^2 - v.v) I + 2 v v^T + 2 w [v]x (Rodrigues form)."""
    q = rotations / rotations.norm(dim=-1, keepdim=True)
    w, v = q[:, 0], q[:, 1:]
    cross = torch.zeros(q.shape[0], 3, 3, dtype=q.dtype)
    cross[:, 0, 1], cross[:, 0, 2], cross[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    cross = cross - cross.transpose(1, 2)
    eye = torch.eye(3, dtype=q.dtype).expand(q.shape[0], 3, 3)
    R = (w * w - (v * v).sum(-1))[:, None, None] * eye + 2 * v[:, :, None] * v[:, None, :] + 2 * w[:, None, None] * cross
    return R @ torch.diag_embed(scales * scales) @ R.transpose(1, 2)


def _project(means, covariances, K, world_to_camera, width, height):
    W, t = world_to_camera[:3, :3], world_to_camera[:3, 3]
    p = means @ W.T + t
    z = p[:, 2]
    visible = z >= NEAR
    zs = torch.where(visible, z, torch.ones_like(z))
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    lim_x = (-cx / fx - 0.3 * 0.5 * width / fx, (width - cx) / fx + 0.3 * 0.5 * width / fx)
    lim_y = (-cy / fy - 0.3 * 0.5 * height / fy, (height - cy) / fy + 0.3 * 0.5 * height / fy)
    tx = zs * torch.clamp(p[:, 0] / zs, float(lim_x[0]), float(lim_x[1]))
    ty = zs * torch.clamp(p[:, 1] / zs, float(lim_y[0]), float(lim_y[1]))
    J = torch.zeros(means.shape[0], 2, 3, dtype=means.dtype)
    J[:, 0, 0], J[:, 0, 2] = fx / zs, -fx * tx / zs**2
    J[:, 1, 1], J[:, 1, 2] = fy / zs, -fy * ty / zs**2
    cov2d = J @ W @ covariances @ W.T @ J.transpose(1, 2) + DILATION * torch.eye(2, dtype=means.dtype)
    means2d = torch.stack([fx * p[:, 0] / zs + cx, fy * p[:, 1] / zs + cy], dim=-1)
    distance = p.norm(dim=-1)  # the camera centre is the origin of the camera frame
    return means2d, cov2d, distance, z, visible


def render_reference(means, opacities, features, K, world_to_camera, width, height, *, covariances,
                     background=None, hard_depth=False, delta=0.95) -> ReferenceRender:
    """Render in float64 (inputs are cast); differentiable by autograd in every tensor input."""
    f64 = torch.float64
    means, opacities, features, covariances = (x.to(f64) for x in (means, opacities, features, covariances))
    K, world_to_camera = torch.as_tensor(K, dtype=f64), torch.as_tensor(world_to_camera, dtype=f64)
    C = features.shape[1]
    background = torch.zeros(C, dtype=f64) if background is None else background.to(f64)
    if hard_depth:
        opacities = torch.full_like(opacities, delta)
        covariances, features, background = covariances.detach(), features.detach(), background.detach()

    means2d, cov2d, distance, z, visible = _project(means, covariances, K, world_to_camera, width, height)
    order = torch.sort(z.detach(), stable=True).indices
    means2d, cov2d, distance, z, visible = means2d[order], cov2d[order], distance[order], z[order], visible[order]
    opacities, features = opacities[order], features[order]
    inv_cov = torch.linalg.inv(torch.where(visible[:, None, None], cov2d, torch.eye(2, dtype=f64)))

    # Gaussians whose order or culling float32 rounding could change.
    zd = z.detach()
    gap = zd[1:] - zd[:-1]
    tie = (gap > 0) & (gap <= DEPTH_TIE_RTOL * torch.maximum(zd[1:].abs(), zd[:-1].abs()))
    group = torch.cat([torch.zeros(1, dtype=torch.long), torch.cumsum(~tie, 0)])  # runs of near-ties
    sizes = torch.bincount(group)
    tie_groups = torch.nonzero(sizes >= 2).flatten()
    tie_membership = (group[:, None] == tie_groups[None]).to(f64)  # (G, groups of near-equal depth)
    near_cull = (zd - NEAR).abs() <= THRESHOLD_RTOL * NEAR

    rows, cols = torch.meshgrid(torch.arange(height, dtype=f64), torch.arange(width, dtype=f64), indexing="ij")
    pixels = torch.stack([cols.reshape(-1) + 0.5, rows.reshape(-1) + 0.5], dim=-1)
    chunk = max(1, MAX_PAIRS_PER_CHUNK // max(1, means.shape[0]))
    out_f, out_a, out_d, out_r = [], [], [], []
    for start in range(0, pixels.shape[0], chunk):
        d = pixels[start:start + chunk, None, :] - means2d[None]  # (P, G, 2)
        power = -0.5 * torch.einsum("pgi,gij,pgj->pg", d, inv_cov, d)
        raw = opacities[None] * torch.exp(power)
        reaches = visible[None] & (raw >= ALPHA_MIN)
        alpha = torch.where(reaches, torch.clamp(raw, max=ALPHA_MAX), torch.zeros_like(raw))
        after = torch.cumprod(1 - alpha, dim=1)
        before = torch.cat([torch.ones_like(after[:, :1]), after[:, :-1]], dim=1)
        included = (after >= T_MIN).detach()
        weight = alpha * before * included
        final_t = 1 - weight.sum(1)
        out_f.append(weight @ features + final_t[:, None] * background)
        out_a.append(1 - final_t)
        out_d.append(weight @ distance)

        with torch.no_grad():
            # Only Gaussians the compositing can still reach matter (transmittance before them above the stop).
            in_play = visible[None] & (before.detach() >= T_MIN * (1 - THRESHOLD_RTOL))
            near_alpha = in_play & ((raw.detach() - ALPHA_MIN).abs() <= THRESHOLD_RTOL * ALPHA_MIN)
            # The 0.99 clamp is continuous in value but not in gradient.
            near_alpha |= in_play & ((raw.detach() - ALPHA_MAX).abs() <= THRESHOLD_RTOL * ALPHA_MAX)
            near_stop = (after.detach() - T_MIN).abs() <= THRESHOLD_RTOL * T_MIN
            counted = reaches & in_play
            ambiguous = near_alpha.any(1) | near_stop.any(1)
            ambiguous |= ((counted | near_alpha) & near_cull[None]).any(1)
            ambiguous |= (((counted | near_alpha).to(f64) @ tie_membership) >= 2).any(1)
            out_r.append(~ambiguous)
    return ReferenceRender(torch.cat(out_f).reshape(height, width, C), torch.cat(out_a).reshape(height, width),
                           torch.cat(out_d).reshape(height, width), torch.cat(out_r).reshape(height, width))
