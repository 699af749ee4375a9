"""EWA projection of 3D Gaussians to image-space 2D Gaussians (Warp), with its backward pass.

One thread per Gaussian. The forward kernel is straight-line code, so its
backward is the adjoint Warp generates for it (``wp.launch(adjoint=True)``):
that is exactly the chain rule one would write by hand, without the chance of
a slip in it.
"""
from __future__ import annotations

from dataclasses import dataclass

import torch
import warp as wp

from .camera import Camera
from .launch import launch

NEAR_PLANE = wp.constant(0.01)
"""Gaussians whose mean has camera-space z below this are culled (metres)."""
DILATION = wp.constant(0.3)
"""Added to the 2D covariance diagonal (px^2): anti-aliasing as in 3DGS."""
FOV_CLAMP = 1.3
"""The Jacobian is evaluated at the mean clamped to this many times the field of view."""

mat23 = wp.types.matrix(shape=(2, 3), dtype=float)


@wp.kernel
def project_gaussians_kernel(
    means: wp.array(dtype=wp.vec3),
    covariances: wp.array(dtype=wp.mat33),
    rotation: wp.mat33,
    translation: wp.vec3,
    focal: wp.vec2,
    principal: wp.vec2,
    tan_lim_low: wp.vec2,
    tan_lim_high: wp.vec2,
    means2d: wp.array(dtype=wp.vec2),
    conics: wp.array(dtype=wp.vec3),
    distances: wp.array(dtype=float),
    depths: wp.array(dtype=float),
):
    """Project Gaussian i; culled ones get a zero conic, which binning skips."""
    i = wp.tid()
    p = rotation * means[i] + translation
    depths[i] = p[2]
    conic = wp.vec3(0.0)
    if p[2] >= NEAR_PLANE:
        rz = 1.0 / p[2]
        # Evaluate J at the mean clamped to 1.3x the field of view, so Gaussians far
        # outside the image do not blow up into huge, misleading 2D footprints.
        tx = p[2] * wp.clamp(p[0] * rz, tan_lim_low[0], tan_lim_high[0])
        ty = p[2] * wp.clamp(p[1] * rz, tan_lim_low[1], tan_lim_high[1])
        J = mat23(focal[0] * rz, 0.0, -focal[0] * tx * rz * rz,
                  0.0, focal[1] * rz, -focal[1] * ty * rz * rz)
        cov_camera = rotation * covariances[i] * wp.transpose(rotation)
        cov2d = J * cov_camera * wp.transpose(J)
        a = cov2d[0, 0] + DILATION
        b = 0.5 * (cov2d[0, 1] + cov2d[1, 0])  # symmetric in both, so the covariance gradient is symmetric
        c = cov2d[1, 1] + DILATION
        det = a * c - b * b
        if det > 0.0:
            conic = wp.vec3(c / det, -b / det, a / det)
        means2d[i] = wp.vec2(focal[0] * p[0] * rz + principal[0], focal[1] * p[1] * rz + principal[1])
        distances[i] = wp.length(p)
    conics[i] = conic


@dataclass
class _CameraArgs:
    """The camera as the kernel's constant arguments."""

    rotation: wp.mat33
    translation: wp.vec3
    focal: wp.vec2
    principal: wp.vec2
    tan_lim_low: wp.vec2
    tan_lim_high: wp.vec2

    @classmethod
    def of(cls, camera: Camera) -> "_CameraArgs":
        (fx, fy), (cx, cy) = camera.focal, camera.principal_point
        # gsplat's limits: the image's own half-extents plus (FOV_CLAMP - 1) of the half field of view.
        margin_x = (FOV_CLAMP - 1.0) * 0.5 * camera.width / fx
        margin_y = (FOV_CLAMP - 1.0) * 0.5 * camera.height / fy
        W = camera.world_to_camera
        return cls(
            rotation=wp.mat33(*W[:3, :3].reshape(-1).tolist()),
            translation=wp.vec3(*W[:3, 3].tolist()),
            focal=wp.vec2(fx, fy),
            principal=wp.vec2(cx, cy),
            tan_lim_low=wp.vec2(-cx / fx - margin_x, -cy / fy - margin_y),
            tan_lim_high=wp.vec2((camera.width - cx) / fx + margin_x, (camera.height - cy) / fy + margin_y),
        )

    def as_list(self) -> list:
        return [self.rotation, self.translation, self.focal, self.principal, self.tan_lim_low, self.tan_lim_high]

    @staticmethod
    def zeros() -> list:
        """Adjoint placeholders: the camera is never differentiated."""
        return [wp.mat33(), wp.vec3(), wp.vec2(), wp.vec2(), wp.vec2(), wp.vec2()]


def _kernel_inputs(means: torch.Tensor, covariances: torch.Tensor, camera_args: _CameraArgs) -> list:
    return [wp.from_torch(means.detach(), dtype=wp.vec3), wp.from_torch(covariances.detach(), dtype=wp.mat33),
            *camera_args.as_list()]


class _ProjectGaussians(torch.autograd.Function):
    @staticmethod
    def forward(ctx, means: torch.Tensor, covariances: torch.Tensor, camera: Camera):
        G, device = means.shape[0], means.device
        means2d = torch.zeros(G, 2, device=device)
        conics = torch.zeros(G, 3, device=device)
        distances = torch.zeros(G, device=device)
        depths = torch.zeros(G, device=device)
        camera_args = _CameraArgs.of(camera)
        inputs = _kernel_inputs(means, covariances, camera_args)
        outputs = [wp.from_torch(means2d, dtype=wp.vec2), wp.from_torch(conics, dtype=wp.vec3),
                   wp.from_torch(distances), wp.from_torch(depths)]
        launch(project_gaussians_kernel, G, inputs=inputs, outputs=outputs, device=device)
        ctx.save_for_backward(means, covariances)
        ctx.camera_args = camera_args
        ctx.mark_non_differentiable(depths)
        return means2d, conics, distances, depths

    @staticmethod
    def backward(ctx, grad_means2d, grad_conics, grad_distances, _grad_depths):
        means, covariances = ctx.saved_tensors
        G, device = means.shape[0], means.device
        grad_means = torch.zeros_like(means)
        grad_covariances = torch.zeros_like(covariances)
        # The adjoint replays the forward pass; its outputs go to scratch arrays.
        scratch = [wp.from_torch(torch.empty(G, 2, device=device), dtype=wp.vec2),
                   wp.from_torch(torch.empty(G, 3, device=device), dtype=wp.vec3),
                   wp.from_torch(torch.empty(G, device=device)), wp.from_torch(torch.empty(G, device=device))]
        launch(
            project_gaussians_kernel, G,
            inputs=_kernel_inputs(means, covariances, ctx.camera_args),
            outputs=scratch,
            adj_inputs=[wp.from_torch(grad_means, dtype=wp.vec3), wp.from_torch(grad_covariances, dtype=wp.mat33),
                        *_CameraArgs.zeros()],
            adj_outputs=[wp.from_torch(grad_means2d.contiguous(), dtype=wp.vec2),
                         wp.from_torch(grad_conics.contiguous(), dtype=wp.vec3),
                         wp.from_torch(grad_distances.contiguous()), None],
            adjoint=True, device=device,
        )
        return grad_means, grad_covariances, None


@dataclass
class Projection:
    """Image-space Gaussians, one row per input Gaussian.

    means2d (G, 2) px; conics (G, 3) the inverse 2D covariance (a, b, c) of
    [[a, b], [b, c]] in 1/px^2, all zero for culled Gaussians; distances (G,)
    from the camera centre in metres; depths (G,) camera-space z in metres
    (the sort key, not differentiable).
    """

    means2d: torch.Tensor
    conics: torch.Tensor
    distances: torch.Tensor
    depths: torch.Tensor


def project_gaussians(means: torch.Tensor, covariances: torch.Tensor, camera: Camera) -> Projection:
    """EWA-project Gaussians (differentiable with respect to means and covariances).

    Args:
        means: (G, 3) float32 world positions, metres.
        covariances: (G, 3, 3) float32 world covariances, metres^2.
        camera: the view.
    """
    return Projection(*_ProjectGaussians.apply(means.contiguous(), covariances.contiguous(), camera))
