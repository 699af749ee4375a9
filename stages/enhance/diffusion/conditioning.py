"""The images the diffusion model is conditioned on: blended frames and the two ControlNet controls."""
from __future__ import annotations

from typing import Tuple

import cv2
import numpy as np
import torch

# The depth ControlNet was trained on MiDaS maps: near bright, far dark, the background
# darkest. The object's inverse depth is spread over [OBJECT_FLOOR, 1] so that its
# farthest point stays brighter than the (unknown, hence 0) background.
OBJECT_FLOOR = 0.25


def model_size(height: int, width: int, target_width: int) -> Tuple[int, int]:
    """(height, width) in pixels at ``target_width``, both multiples of 64 (three UNet halvings of 8x latents)."""
    scale = target_width / width
    return max(64, round(height * scale / 64) * 64), max(64, round(target_width / 64) * 64)


def inverse_depth_control(depth: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Normalised inverse depth (T, h, w) in [0, 1] from the render's alpha-weighted depth (Eq. 2).

    The render stores sum(alpha_i d_i), so the surface distance is depth / alpha.
    One normalisation for the whole video keeps the control steady over time.
    """
    covered = alpha > 1e-3
    inverse = np.zeros_like(depth, dtype=np.float32)
    inverse[covered] = alpha[covered] / np.maximum(depth[covered], 1e-6)
    if not covered.any():
        return inverse
    lo, hi = inverse[covered].min(), inverse[covered].max()
    spread = (inverse - lo) / max(hi - lo, 1e-6)
    # Soft edges fade toward the background as the render's alpha does.
    return np.where(covered, (OBJECT_FLOOR + (1 - OBJECT_FLOOR) * spread) * np.minimum(alpha / 0.5, 1), 0)


def canny_control(frames: np.ndarray, thresholds: Tuple[int, int]) -> np.ndarray:
    """Canny edges (T, h, w) in {0, 1} of u8 RGB frames (T, h, w, 3), by OpenCV."""
    return np.stack([cv2.Canny(cv2.cvtColor(f, cv2.COLOR_RGB2GRAY), *thresholds) for f in frames]) / np.float32(255)


def to_tensor(images: np.ndarray) -> torch.Tensor:
    """(T, h, w, 3) u8 or (T, h, w) float in [0, 1] -> (T, 3, h, w) float32 in [0, 1]."""
    t = torch.from_numpy(np.ascontiguousarray(images))
    t = t.float() / 255 if t.dtype == torch.uint8 else t.float()
    return t.permute(0, 3, 1, 2) if t.ndim == 4 else t[:, None].expand(-1, 3, -1, -1)


def to_u8(images: torch.Tensor) -> np.ndarray:
    """(T, 3, h, w) float in [0, 1] -> (T, h, w, 3) u8."""
    return (images.permute(0, 2, 3, 1).float().cpu().numpy() * 255 + 0.5).clip(0, 255).astype(np.uint8)
