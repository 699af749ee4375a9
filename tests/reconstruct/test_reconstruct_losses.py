"""Colour and hard-depth losses against independent references."""
import numpy as np
import pytest
import torch
from skimage.metrics import structural_similarity

from stages.reconstruct.losses import hard_depth_loss, ssim


def test_ssim_matches_scikit_image():
    rng = np.random.default_rng(0)
    a = rng.random((64, 72, 3)).astype(np.float32)
    b = np.clip(a + 0.15 * rng.standard_normal(a.shape), 0, 1).astype(np.float32)
    ours = ssim(torch.tensor(a), torch.tensor(b)).item()
    reference = structural_similarity(a, b, channel_axis=2, gaussian_weights=True, sigma=1.5,
                                      use_sample_covariance=False, data_range=1.0)
    assert ours == pytest.approx(reference, abs=0.01)  # borders differ: zero padding vs cropping
    assert ssim(torch.tensor(a), torch.tensor(a)).item() == pytest.approx(1, abs=1e-5)


def test_hard_depth_loss_ignores_scale_and_offset_but_sees_shape():
    rows, cols = np.mgrid[:48, :48] / 48.0
    depth = torch.tensor(1 + 0.2 * np.sin(4 * rows) * np.cos(3 * cols), dtype=torch.float32)
    valid = torch.ones(48, 48, dtype=torch.bool)
    same_shape = 3 * depth + 5
    other_shape = torch.tensor(1 + 0.2 * np.cos(5 * rows + 2 * cols), dtype=torch.float32)
    loss = lambda prior: hard_depth_loss(depth, prior, valid, np.random.default_rng(1)).item()  # noqa: E731
    assert loss(same_shape) < 1e-6
    assert loss(other_shape) > 0.1


def test_hard_depth_loss_uses_only_patches_inside_the_valid_pixels():
    depth = torch.ones(32, 32, requires_grad=True)
    prior = torch.rand(32, 32, generator=torch.Generator().manual_seed(0))
    valid = torch.zeros(32, 32, dtype=torch.bool)
    valid[:4, :4] = True  # smaller than the smallest patch
    out = hard_depth_loss(depth, prior, valid, np.random.default_rng(0))
    assert out.item() == 0
