"""Quality measures of a reconstruction (benchmarks/quality.py and the tests)."""
from __future__ import annotations

import numpy as np


def masked_psnr(render: np.ndarray, target: np.ndarray, mask: np.ndarray) -> float:
    """PSNR in dB of two images (H,W,C) in [0,1] over the pixels where ``mask`` (H,W) is set."""
    mse = float(((render[mask] - target[mask]) ** 2).mean())
    return float("inf") if mse == 0 else 10 * np.log10(1.0 / mse)


def iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two boolean masks."""
    union = np.logical_or(a, b).sum()
    return float(np.logical_and(a, b).sum() / union) if union else 1.0


def median_relative_error(estimate: np.ndarray, truth: np.ndarray, where: np.ndarray) -> float:
    """Median of |estimate - truth| / truth over ``where``."""
    return float(np.median(np.abs(estimate[where] - truth[where]) / truth[where]))
