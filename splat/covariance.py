"""3D covariances from scales and rotations (torch, differentiable by autograd)."""
from __future__ import annotations

import torch


def rotation_matrices(quaternions: torch.Tensor) -> torch.Tensor:
    """Rotation matrices of quaternions (w, x, y, z), normalised first.

    Args:
        quaternions: (G, 4); need not be unit length (non-zero).
    Returns:
        (G, 3, 3) rotation matrices.
    """
    w, x, y, z = torch.nn.functional.normalize(quaternions, dim=-1).unbind(-1)
    return torch.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], dim=-1).reshape(*quaternions.shape[:-1], 3, 3)


def covariances_from_scales_rotations(scales: torch.Tensor, rotations: torch.Tensor) -> torch.Tensor:
    """H = R S S^T R^T.

    Args:
        scales: (G, 3) standard deviations along the Gaussian's axes, metres (linear, not log).
        rotations: (G, 4) quaternions (w, x, y, z).
    Returns:
        (G, 3, 3) covariances, metres^2.
    """
    M = rotation_matrices(rotations) * scales[..., None, :]
    return M @ M.transpose(-1, -2)
