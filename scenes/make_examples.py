"""Write the images of the example scenes (committed; rerun to regenerate them).

- coffee/: scikit-image's `coffee` photograph and a mask of the cup.
- logo/:   scikit-image's `logo`, given the alpha of its disc, which is the mask.
- ball/:   a textured ball on a table, drawn here, with its mask file.

Usage: python scenes/make_examples.py
"""
from pathlib import Path

import cv2
import numpy as np
import skimage.data

from schemas.images import write_image

HERE = Path(__file__).parent


def write_rgb(path: Path, rgb: np.ndarray) -> None:
    write_image(path, cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))


def coffee() -> None:
    """The photograph at 384x256 and a mask of the cup drawn from simple shapes: box-initialised
    GrabCut separates only the white rim and the coffee, since the red cup body has the colours
    of the saucer around it."""
    photo = cv2.resize(skimage.data.coffee(), (384, 256), interpolation=cv2.INTER_AREA)
    write_rgb(HERE / "coffee" / "photo.png", photo)
    mask = np.zeros(photo.shape[:2], np.uint8)
    cv2.ellipse(mask, (186, 70), (76, 62), 0, 0, 360, 255, -1)  # the rim, seen from above
    body = np.array([(111, 75), (263, 75), (252, 140), (236, 172), (205, 188), (165, 188), (140, 172), (118, 130)])
    cv2.fillPoly(mask, [body], 255)
    cv2.ellipse(mask, (142, 168), (18, 26), 20, 0, 360, 255, -1)  # the handle
    write_image(HERE / "coffee" / "mask.png", mask)


def logo(size: int = 256) -> None:
    """The bundled logo is opaque everywhere; give it the alpha of its disc (anti-aliased), so
    that the image alpha is the object's mask."""
    rgb = cv2.resize(skimage.data.logo()[..., :3], (size, size), interpolation=cv2.INTER_AREA)
    ink = rgb.min(axis=2) < 245  # everything that is not the white page
    rows, cols = np.nonzero(ink)
    centre, radius = np.array([cols.mean(), rows.mean()]) + 0.5, np.sqrt(ink.sum() / np.pi)
    r, c = np.mgrid[0:size, 0:size] + 0.5
    distance = np.hypot(c - centre[0], r - centre[1])
    alpha = np.clip(radius - distance + 0.5, 0, 1)  # one-pixel anti-aliased edge
    # Over white where transparent, so that colour and alpha agree (the page is off-white).
    rgb = np.round(rgb * alpha[..., None] + 255 * (1 - alpha[..., None])).astype(np.uint8)
    rgba = np.dstack([rgb, np.round(alpha * 255).astype(np.uint8)])
    write_image(HERE / "logo" / "logo.png", cv2.cvtColor(rgba, cv2.COLOR_RGBA2BGRA))


def ball(width: int = 320, height: int = 240, radius: float = 70.0) -> None:
    """A Lambert-shaded ball with a striped texture resting on a wooden-looking table."""
    rng = np.random.default_rng(0)
    rows, cols = np.mgrid[0:height, 0:width].astype(np.float64) + 0.5
    # Table: warm brown with horizontal grain, darker towards the top (further away).
    grain = 0.06 * np.sin(rows * 0.9 + 3.0 * np.sin(cols * 0.02)) + 0.03 * rng.standard_normal((height, width))
    shade = 0.55 + 0.35 * rows / height
    table = np.stack([0.62, 0.40, 0.24]) * (shade + grain)[..., None]
    # Ball: unit-sphere normals from the disc, light from the upper left.
    cx, cy = width / 2, height - radius - 30
    dx, dy = (cols - cx) / radius, (rows - cy) / radius
    inside = dx**2 + dy**2 < 1
    nz = np.sqrt(np.clip(1 - dx**2 - dy**2, 0, 1))
    light = np.array([-0.5, -0.6, 0.62])  # towards the light: left, up, towards the camera
    light /= np.linalg.norm(light)
    lambert = np.clip(dx * light[0] + dy * light[1] + nz * light[2], 0, 1)
    # Stripes follow latitude on the sphere so the texture shows 3D motion.
    latitude = np.arcsin(np.clip(dy, -1, 1))
    stripes = (np.sin(latitude * 9 + np.arctan2(dx, nz) * 3) > 0)[..., None]
    albedo = np.where(stripes, [0.85, 0.12, 0.10], [0.95, 0.85, 0.30])
    ball_rgb = albedo * (0.25 + 0.75 * lambert)[..., None]
    # Soft contact shadow under the ball.
    shadow = np.exp(-(((cols - cx) / (1.1 * radius)) ** 2 + ((rows - (cy + radius)) / 12) ** 2))
    table = table * (1 - 0.5 * shadow)[..., None]
    rgb = np.where(inside[..., None], ball_rgb, table)
    write_rgb(HERE / "ball" / "photo.png", np.clip(rgb * 255 + 0.5, 0, 255).astype(np.uint8))
    write_image(HERE / "ball" / "mask.png", inside.astype(np.uint8) * 255)


if __name__ == "__main__":
    for make in (coffee, logo, ball):
        (HERE / make.__name__).mkdir(exist_ok=True)
        make()
