"""Keyframes and the propagation of their attention outputs to the other frames
(paper Sec. 3.4.2, Eq. 14-15; appendix A.2.2)."""
from __future__ import annotations

import bisect
from typing import List, Sequence, Tuple

import numpy as np
import torch
import torch.nn.functional as F

# Rows of the similarity matrix computed at once: at 768 px the finest layer has
# 9216 tokens per frame, so a chunk costs 2048 x 9216 floats (75 MB) instead of 340 MB.
SIMILARITY_ROWS = 2048


def draw_keyframes(n_frames: int, window: int, rng: np.random.Generator) -> List[int]:
    """The first frame, then one frame drawn uniformly from each later window of ``window`` frames.

    Redrawn at every denoising step so that every frame is sometimes a keyframe.
    """
    later = [int(rng.integers(start, min(start + window, n_frames))) for start in range(window, n_frames, window)]
    return [0] + later


def keyframe_neighbours(frame: int, keyframes: Sequence[int]) -> Tuple[int, int, float]:
    """(past keyframe j-, future keyframe j+, weight w_j of the future one), Eq. 14.

    w_j = (j - j-) / (j+ - j-); a frame after the last keyframe takes the past one alone
    (j+ = j-, w = 0). ``keyframes`` is sorted and holds frame 0.
    """
    i = bisect.bisect_right(keyframes, frame)
    past = keyframes[i - 1]
    if i == len(keyframes) or past == frame:
        return past, past, 0.0
    future = keyframes[i]
    return past, future, (frame - past) / (future - past)


def nearest_tokens(query: torch.Tensor, keys: torch.Tensor, rows: int = SIMILARITY_ROWS) -> torch.Tensor:
    """For each query token the index of the key token nearest by cosine distance, Eq. 15.

    Args:
        query: (N, C) features; keys: (M, C) features.
    Returns:
        (N,) long indices into keys.
    """
    keys = F.normalize(keys.float(), dim=-1)
    query = F.normalize(query.float(), dim=-1)
    return torch.cat([(chunk @ keys.T).argmax(dim=-1) for chunk in query.split(rows)])


def propagate(frame: int, keyframes: Sequence[int], features: torch.Tensor, keyframe_features: torch.Tensor,
              keyframe_outputs: torch.Tensor) -> torch.Tensor:
    """The attention output of a frame taken from its neighbouring keyframes, Eq. 14.

    A keyframe keeps its own output.

    Args:
        features: (N, C) the frame's coarse-branch features, to match on.
        keyframe_features: (K, N, C) the keyframes' coarse-branch features.
        keyframe_outputs: (B, K, N, C) the keyframes' outputs in B branches.
    Returns:
        (B, N, C).
    """
    if frame in keyframes:
        return keyframe_outputs[:, keyframes.index(frame)]
    past, future, weight = keyframe_neighbours(frame, keyframes)
    out = 0
    for key, w in ((past, 1 - weight), (future, weight)):
        if w == 0:
            continue
        k = keyframes.index(key)
        out = out + w * keyframe_outputs[:, k, nearest_tokens(features, keyframe_features[k])]
    return out
