"""Write the photographs of the benchmark scenes: scikit-image's, new to the examples (not committed).

- rocket/:     `rocket`, a launch pad's rocket taken as a 30 cm model (the scene's box holds it).
- motorcycle/: the left view of `stereo_motorcycle`, taken as a 30 cm toy.

Usage: python benchmarks/scenes/make_photos.py
"""
from pathlib import Path

import cv2
import skimage.data

from schemas.images import write_image

HERE = Path(__file__).parent

if __name__ == "__main__":
    for name, rgb in (("rocket", skimage.data.rocket()), ("motorcycle", skimage.data.stereo_motorcycle()[0])):
        write_image(HERE / name / "photo.png", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
