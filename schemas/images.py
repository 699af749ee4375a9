"""Reading the user's image files (photograph, masks, extra views) the way an image viewer shows them."""
from __future__ import annotations

from pathlib import Path
from typing import Optional

import cv2
import numpy as np

from .files import write_file


def read_image(path: Path | str) -> Optional[np.ndarray]:
    """An image file with its alpha and bit depth (as cv2.IMREAD_UNCHANGED reads it), turned upright as
    its EXIF orientation says; None when the file cannot be read as an image.

    Phones store a portrait photograph as landscape pixels plus an orientation tag. IMREAD_UNCHANGED
    ignores the tag, so boxes and masks drawn on the photograph as it is shown would land on the wrong
    pixels; OpenCV's other reads apply it but drop the alpha. So the file is read both ways, and the
    turn or flip of the first that gives the second is applied to all of its channels.

    Returns:
        (H, W) or (H, W, C) array in OpenCV's channel order (BGR, BGRA), u8 or u16.
    """
    stored = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if stored is None:
        return None
    shown = cv2.imread(str(path), cv2.IMREAD_ANYCOLOR | cv2.IMREAD_ANYDEPTH)
    for mirrored in (stored, stored[:, ::-1]):
        for quarter_turns in range(4):
            candidate = np.rot90(mirrored, quarter_turns)
            colour = candidate[..., :3] if candidate.ndim == 3 else candidate
            if shown is not None and colour.shape == shown.shape and np.array_equal(colour, shown):
                return np.ascontiguousarray(candidate)
    return stored  # a layout OpenCV reads differently with and without alpha (grey + alpha): as stored


def write_image(path: Path | str, image: np.ndarray) -> Path:
    """Write an image (H,W), (H,W,3) BGR or (H,W,4) BGRA, u8, in the format of ``path``'s suffix (.png),
    encoded in memory and written atomically (schemas.files.write_file): a failed write raises, never
    passes unnoticed."""
    path = Path(path)
    ok, encoded = cv2.imencode(path.suffix, image)
    if not ok:
        raise ValueError(f"OpenCV could not encode a {image.shape} {image.dtype} image as {path.suffix}")
    return write_file(path, encoded.tobytes())


HINT_OBJECT, HINT_BACKGROUND = (255, 255, 255, 255), (0, 0, 0, 255)
"""objects[].hints as written (BGRA): an opaque white stroke says object, an opaque black one background."""


def read_hints(path: Path | str, shape: tuple[int, int]) -> Optional[tuple[np.ndarray, np.ndarray]]:
    """(object, background) boolean masks (H,W) of a hint image; None when it is unreadable or not ``shape`` (H,W).

    With alpha, a stroke is an opaque pixel (alpha above 127): bright (grey above 127) marks the object, dark
    the background, so hints painted in any editor on a transparent layer work. Without alpha, white (grey
    250 and up) marks the object, black (5 and below) the background, every other grey no hint.
    """
    raw = read_image(path)
    if raw is None or raw.shape[:2] != tuple(shape):
        return None
    if raw.dtype != np.uint8:
        raw = (raw // 257).astype(np.uint8)
    grey = raw if raw.ndim == 2 else cv2.cvtColor(raw[..., :3], cv2.COLOR_BGR2GRAY)
    if raw.ndim == 3 and raw.shape[2] == 4:
        opaque = raw[..., 3] > 127
        return opaque & (grey > 127), opaque & (grey <= 127)
    return grey >= 250, grey <= 5
