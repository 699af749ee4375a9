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
