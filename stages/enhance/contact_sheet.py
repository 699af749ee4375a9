"""A contact sheet: evenly spaced frames in rows (input, coarse, enhanced), one PNG to glance at."""
from __future__ import annotations

from typing import Dict

import cv2
import numpy as np

LABEL_HEIGHT = 18
MIN_TILE_WIDTH = 200
"""Smaller frames are enlarged (nearest neighbour, so pixels stay honest) to keep labels readable."""


def _label(tile: np.ndarray, text: str) -> np.ndarray:
    """The tile with a dark strip of text above it."""
    strip = np.full((LABEL_HEIGHT, tile.shape[1], 3), 32, np.uint8)
    cv2.putText(strip, text, (4, LABEL_HEIGHT - 5), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (235, 235, 235), 1, cv2.LINE_AA)
    return np.concatenate([strip, tile], axis=0)


def contact_sheet(rows: Dict[str, np.ndarray], fps: float, columns: int = 5) -> np.ndarray:
    """Tile ``columns`` evenly spaced frames of each named row.

    Args:
        rows: name -> (T, h, w, 3) uint8 frames (all the same shape).
        fps: to label each column with its time.
    Returns:
        (rows * (zoom h + label), columns * zoom w, 3) uint8 RGB, zoom enlarging tiles to 200 px.
    """
    T, h, w = next(iter(rows.values())).shape[:3]
    zoom = max(1, -(-MIN_TILE_WIDTH // w))
    enlarge = lambda image: cv2.resize(image, (w * zoom, h * zoom), interpolation=cv2.INTER_NEAREST)  # noqa: E731
    picks = np.unique(np.linspace(0, T - 1, min(columns, T)).round().astype(int))
    return np.concatenate([
        np.concatenate([_label(enlarge(frames[t]), f"{name}  t={t / fps:.2f}s") for t in picks], axis=1)
        for name, frames in rows.items()
    ], axis=0)

