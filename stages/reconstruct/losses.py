"""Losses of the geometry-aware optimisation (paper Eq. 7-10).

Images are torch tensors (H,W,C) or (H,W); depths are metres along the ray.
"""
from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

SSIM_WINDOW = 11
SSIM_SIGMA = 1.5
SSIM_C1, SSIM_C2 = 0.01 ** 2, 0.03 ** 2


def _gaussian_taps(device) -> torch.Tensor:
    x = torch.arange(SSIM_WINDOW, dtype=torch.float32, device=device) - SSIM_WINDOW // 2
    g = torch.exp(-x ** 2 / (2 * SSIM_SIGMA ** 2))
    return g / g.sum()


def ssim(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Mean structural similarity of two images (H,W,C) in [0,1]: 11x11 Gaussian window, sigma 1.5 (as 3DGS).

    The window is separable, so it is applied as a row pass and a column pass (22 taps instead of 121);
    borders are zero-padded as in 3DGS's code.
    """
    channels = a.shape[2]
    taps = _gaussian_taps(a.device)
    rows = taps.view(1, 1, 1, -1).expand(5 * channels, 1, 1, SSIM_WINDOW)
    cols = taps.view(1, 1, -1, 1).expand(5 * channels, 1, SSIM_WINDOW, 1)
    x, y = a.permute(2, 0, 1)[None], b.permute(2, 0, 1)[None]
    stack = torch.cat([x, y, x * x, y * y, x * y], dim=1)  # all five blurs in one grouped convolution
    blurred = F.conv2d(F.conv2d(stack, rows, padding=(0, SSIM_WINDOW // 2), groups=5 * channels),
                       cols, padding=(SSIM_WINDOW // 2, 0), groups=5 * channels)
    mu_x, mu_y, xx, yy, xy = blurred.split(channels, dim=1)
    var_x, var_y, cov = xx - mu_x ** 2, yy - mu_y ** 2, xy - mu_x * mu_y
    num = (2 * mu_x * mu_y + SSIM_C1) * (2 * cov + SSIM_C2)
    den = (mu_x ** 2 + mu_y ** 2 + SSIM_C1) * (var_x + var_y + SSIM_C2)
    return (num / den).mean()


def color_loss(render: torch.Tensor, target: torch.Tensor, dssim_weight: float = 0.2) -> torch.Tensor:
    """Eq. 10: L1 + lambda D-SSIM of two images (H,W,C), with D-SSIM = 1 - SSIM as in 3DGS's code."""
    return (render - target).abs().mean() + dssim_weight * (1 - ssim(render, target))


def _patches(image: torch.Tensor, size: int, offset: tuple[int, int]) -> torch.Tensor:
    """Non-overlapping size x size patches (N, size*size) of (H,W) starting at ``offset`` (row, col)."""
    cropped = image[offset[0]:, offset[1]:]
    return F.unfold(cropped[None, None], kernel_size=size, stride=size)[0].T


def patch_range(valid: torch.Tensor) -> tuple[int, int]:
    """Patch sizes (pixels) for an object of ``valid`` pixels: a tenth to a quarter of its side, so that
    patches fit inside it at any resolution (DNGaussian's fixed range assumes ~500-pixel scenes)."""
    side = float(valid.sum()) ** 0.5
    return max(3, int(side / 10)), max(4, int(side / 4))


def hard_depth_loss(rendered: torch.Tensor, prior: torch.Tensor, valid: torch.Tensor,
                    rng: np.random.Generator, global_weight: float = 0.1) -> torch.Tensor:
    """Eq. 7 summed over patches: DNGaussian's local + global patch-normalised depth difference.

    Each patch of the rendered hard depth and of the prior depth is centred on
    its own mean; the local term divides by the patch's own standard deviation,
    the global term by the standard deviation over all valid pixels of that
    image. Only the shape within a patch is compared, so the prior's unknown
    scale and offset do not matter. Patch size (``patch_range``) and grid
    offset are drawn from ``rng`` each call, so patch borders do not stay in
    one place; only patches wholly inside ``valid`` count.

    Args:
        rendered, prior: (H,W) depths in metres; ``prior`` may hold NaN where ``valid`` is False.
        valid: (H,W) bool, the pixels to compare (object pixels, eroded); patches must lie inside it.
    Returns:
        scalar; zero (without gradient) when no patch fits.
    """
    smallest, largest = patch_range(valid)
    size = int(rng.integers(smallest, largest + 1))
    height, width = valid.shape
    if min(height, width) < size:
        return rendered.sum() * 0
    offset = (int(rng.integers(0, min(size, height - size + 1))), int(rng.integers(0, min(size, width - size + 1))))
    keep = _patches(valid.float(), size, offset).min(dim=1).values > 0.5
    if keep.sum() < 1:
        return rendered.sum() * 0
    prior = torch.where(valid, prior, torch.zeros_like(prior))
    loss = 0
    for local in (True, False):
        normalised = []
        for depth in (rendered, prior):
            patches = _patches(depth, size, offset)[keep]
            scale = patches.std(dim=1, keepdim=True) if local else depth[valid].std().detach()
            # DNGaussian's floor: a hundredth of the whole image's spread, so flat patches do not explode.
            normalised.append((patches - patches.mean(dim=1, keepdim=True)) / (scale + 1e-2 * depth[valid].std()))
        term = ((normalised[0] - normalised[1]) ** 2).mean()
        loss = loss + (term if local else global_weight * term)
    return loss
