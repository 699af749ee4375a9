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
from .launch import launch, torch_single_threaded

NEAR_PLANE = wp.constant(0.01)
"""Gaussians whose mean has camera-space z below this are culled (metres)."""
DILATION_PX2 = 0.3
"""Added to the 2D covariance diagonal (px^2): anti-aliasing as in 3DGS."""
DILATION = wp.constant(DILATION_PX2)
"""DILATION_PX2 as the kernel's constant."""
FOV_CLAMP = 1.3
"""The Jacobian is evaluated at the mean clamped to this many times the field of view."""

mat23 = wp.types.matrix(shape=(2, 3), dtype=float)


@wp.func
def covariance_from_scale_rotation(scale: wp.vec3, quaternion: wp.vec4) -> wp.mat33:
    """R S S^T R^T for a quaternion (w, x, y, z), normalised here (as splat.covariance does in torch)."""
    q = wp.normalize(quaternion)
    w, x, y, z = q[0], q[1], q[2], q[3]
    R = wp.mat33(1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y),
                 2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x),
                 2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y))
    M = R * wp.diag(scale)
    return M * wp.transpose(M)


@wp.kernel
def project_gaussians_kernel(
    means: wp.array(dtype=wp.vec3),
    covariances: wp.array(dtype=wp.mat33),
    scales: wp.array(dtype=wp.vec3),
    rotations: wp.array(dtype=wp.vec4),
    from_scales: int,
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
    """Project Gaussian i, its covariance given or (from_scales) built from scale and rotation;
    culled ones get a zero conic, which binning skips."""
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
        cov_world = wp.mat33(0.0)
        if from_scales:
            cov_world = covariance_from_scale_rotation(scales[i], rotations[i])
        else:
            cov_world = covariances[i]
        cov_camera = rotation * cov_world * wp.transpose(rotation)
        cov2d = J * cov_camera * wp.transpose(J)
        a = cov2d[0, 0] + DILATION
        b = 0.5 * (cov2d[0, 1] + cov2d[1, 0])  # symmetric in both, so the covariance gradient is symmetric
        c = cov2d[1, 1] + DILATION
        det = a * c - b * b
        if det > 0.0:
            conic = wp.vec3(c / det, -b / det, a / det)
        means2d[i] = wp.vec2(focal[0] * p[0] * rz + principal[0], focal[1] * p[1] * rz + principal[1])
        distances[i] = wp.length(p)  # the camera centre is the camera frame's origin (rigid world_to_camera)
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
    def of(cls, camera: Camera) -> _CameraArgs:
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


class _ProjectGaussians(torch.autograd.Function):
    """Differentiable in means and in either covariances or scales and rotations (the other pair is empty)."""

    @staticmethod
    def forward(ctx, means, covariances, scales, rotations, camera: Camera):
        G, device = means.shape[0], means.device
        ctx.camera_args, ctx.from_scales = _CameraArgs.of(camera), covariances.shape[0] == 0
        outputs = [torch.zeros(G, 2, device=device), torch.zeros(G, 3, device=device),
                   torch.zeros(G, device=device), torch.zeros(G, device=device)]
        launch(project_gaussians_kernel, G, inputs=_kernel_inputs(ctx, [means, covariances, scales, rotations]),
               outputs=_warp_outputs(outputs), device=device)
        ctx.save_for_backward(means, covariances, scales, rotations)
        ctx.mark_non_differentiable(outputs[3])
        return tuple(outputs)

    @staticmethod
    @torch_single_threaded()
    def backward(ctx, grad_means2d, grad_conics, grad_distances, _grad_depths):
        inputs = ctx.saved_tensors
        grads = [torch.zeros_like(x) for x in inputs]
        G, device = inputs[0].shape[0], inputs[0].device
        # The adjoint replays the forward pass; its outputs go to scratch arrays.
        scratch = [torch.empty(G, 2, device=device), torch.empty(G, 3, device=device),
                   torch.empty(G, device=device), torch.empty(G, device=device)]
        incoming = [grad_means2d.contiguous(), grad_conics.contiguous(), grad_distances.contiguous()]
        launch(project_gaussians_kernel, G, inputs=_kernel_inputs(ctx, inputs),
               outputs=_warp_outputs(scratch),
               adj_inputs=[*_warp_inputs(grads), 0, *_CameraArgs.zeros()],
               adj_outputs=[*_warp_outputs(incoming), None],
               adjoint=True, device=device)
        return (*grads, None)


def _kernel_inputs(ctx, tensors: list) -> list:
    return [*_warp_inputs([t.detach() for t in tensors]), int(ctx.from_scales), *ctx.camera_args.as_list()]


def _warp_inputs(tensors: list) -> list:
    """(means, covariances, scales, rotations) as Warp arrays."""
    return [wp.from_torch(t, dtype=d) for t, d in zip(tensors, (wp.vec3, wp.mat33, wp.vec3, wp.vec4))]


def _warp_outputs(tensors: list) -> list:
    """(means2d, conics, distances[, depths]) as Warp arrays."""
    return [wp.from_torch(t, dtype=d) for t, d in zip(tensors, (wp.vec2, wp.vec3, wp.float32, wp.float32))]


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


def project_gaussians(means: torch.Tensor, camera: Camera, *, covariances: torch.Tensor | None = None,
                      scales: torch.Tensor | None = None, rotations: torch.Tensor | None = None) -> Projection:
    """EWA-project Gaussians, differentiable in means and in the shape given.

    Args:
        means: (G, 3) float32 world positions, metres.
        camera: the view.
        covariances: (G, 3, 3) float32 world covariances, metres^2; or
        scales, rotations: (G, 3) linear standard deviations, metres, and (G, 4) quaternions (w, x, y, z).
    """
    empty = means.new_zeros(0)
    shape = [covariances.reshape(-1, 3, 3), empty.reshape(0, 3), empty.reshape(0, 4)] if covariances is not None \
        else [empty.reshape(0, 3, 3), scales, rotations]
    return Projection(*_ProjectGaussians.apply(means.contiguous(), *(t.contiguous() for t in shape), camera))
