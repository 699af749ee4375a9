"""The photograph with its objects inpainted away, for the enhancement's compositing (I_B^0)."""
from __future__ import annotations

import cv2
import numpy as np

INPAINT_RADIUS_PX = 5


def dilation_px(height: int, width: int) -> int:
    """How far past the masks to inpaint: soft edges and GrabCut's misses (1 % of the size, at least 3 px)."""
    return max(3, round(0.01 * max(height, width)))


def inpaint_background(photo: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """RGB u8 (H,W,3): ``photo`` with every object (``labels`` > 0), dilated, filled by OpenCV's Telea method."""
    radius = dilation_px(*labels.shape)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
    hole = cv2.dilate((labels > 0).astype(np.uint8), kernel)
    return cv2.inpaint(photo, hole, INPAINT_RADIUS_PX, cv2.INPAINT_TELEA)
