"""Write the photographs of the benchmark scenes: scikit-image's, new to the examples (not committed).

- rocket/:     `rocket`, a launch pad's rocket taken as a 30 cm model (the scene's box holds it).
- motorcycle/: the left view of `stereo_motorcycle`, taken as a 30 cm toy.
- loaf/:       a loaf made of scikit-image's textures (`gravel` as its crust, `brick` as the table), for
               tearing (benchmarks/tearing.py).
- cat/:        `chelsea`, the cat's head as a 15 cm jelly, tossed up (benchmarks/toss.py).
- coin/:       `coins`, the large coin at the right as a 3 cm metal disc seen from 80 degrees above.
- wheel/:      `colorwheel` on a light grey page, a 25 cm disc of coloured sand that collapses to a heap
               (benchmarks/quality.py, granular).
- shuttle_sand/: `astronaut`, the model shuttle behind her (white orbiter, brown tank) as 30 cm of sand.
- shuttle/:   the same shuttle as a 30 cm jelly toy knocked at its top (benchmarks/toss.py, rest.py).

Usage: python benchmarks/scenes/make_photos.py
"""
from pathlib import Path

import cv2
import numpy as np
import skimage.data

from schemas.images import write_image

HERE = Path(__file__).parent
LOAF = (210, 175, 150, 62)
"""The loaf's superellipse |(x - cx) / ax|^3 + |(y - cy) / ay|^3 < 1: (cx, cy, ax, ay), pixels."""


def loaf(height: int = 300, width: int = 420) -> np.ndarray:
    """(height, width, 3) BGR: a rounded loaf (a superellipse of gravel in crust colours, lit from above)
    with its shadow, on a brick table; the loaf spans about pixels [61, 114] to [359, 236]."""
    table = cv2.resize(skimage.data.brick(), (width, height)).astype(np.float32)
    image = np.stack([0.55 * table + 60, 0.5 * table + 50, 0.45 * table + 40], -1)
    grain = cv2.resize(skimage.data.gravel(), (width, height)).astype(np.float32)[..., None] / 255
    y, x = np.mgrid[0:height, 0:width]
    cx, cy, ax, ay = LOAF
    inside = np.abs((x - cx) / ax) ** 3 + np.abs((y - cy) / ay) ** 3 < 1
    light = np.clip(1.1 - 0.6 * (y - (cy - ay)) / (2 * ay), 0.4, 1.2)[..., None]
    crust = (np.array([40, 110, 170]) + np.array([60, 70, 70]) * grain) * light
    shadow = ((x - cx) / (1.05 * ax)) ** 2 + ((y - (cy + ay)) / 12) ** 2 < 1
    image[shadow & ~inside] *= 0.5
    image[inside] = crust[inside]
    return np.clip(image, 0, 255).astype(np.uint8)

if __name__ == "__main__":
    for name, rgb in (("rocket", skimage.data.rocket()), ("motorcycle", skimage.data.stereo_motorcycle()[0]),
                      ("cat", skimage.data.chelsea()), ("coin", cv2.cvtColor(skimage.data.coins(), cv2.COLOR_GRAY2RGB))):
        write_image(HERE / name / "photo.png", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    write_image(HERE / "loaf" / "photo.png", loaf())
    page = np.full((420, 620, 3), 235, np.uint8)
    page[25:395, 125:496] = skimage.data.colorwheel()
    write_image(HERE / "wheel" / "photo.png", cv2.cvtColor(page, cv2.COLOR_RGB2BGR))
    for name in ("shuttle_sand", "shuttle"):
        write_image(HERE / name / "photo.png", cv2.cvtColor(skimage.data.astronaut(), cv2.COLOR_RGB2BGR))
