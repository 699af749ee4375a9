"""Write the images of the example scenes (committed; rerun to regenerate them).

- coffee/: scikit-image's `coffee` photograph and a mask of the cup.
- logo/:   scikit-image's `logo`, turned so that its green half is on the left and its orange half on
           the right, on a page wider than the disc (room for the heap), with the alpha of its disc,
           which is the mask.
- ball/:   a textured ball on a table, drawn here, with its mask file.
- clay/:   a column of modelling clay on a table, drawn here, with its mask file.
- loaf/:   a loaf of bread made of scikit-image's textures (benchmarks/scenes/make_photos.py), with
           its mask file.

Images are named for their scene where the scene is new (clay.png, clay_mask.png): a test copies all
examples' images into one folder.

Usage: python scenes/make_examples.py
"""
import sys
from pathlib import Path

import cv2
import numpy as np
import skimage.data

from schemas.images import write_image

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE.parent))
from benchmarks.scenes.make_photos import LOAF, loaf as loaf_photo  # noqa: E402


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


def logo(size: int = 256, page: tuple[int, int] = (480, 360)) -> None:
    """The bundled logo is opaque everywhere; give it the alpha of its disc (anti-aliased), so
    that the image alpha is the object's mask. Turned a quarter left, its green half stands on
    the left and its orange half on the right, so that each half slumps into its own side of
    the heap. The page (width, height) is wider than the disc and reaches below it, so that the
    heap stays in the picture: a disc of sand d across slumps at 35 degrees into a heap about
    1.4 d across, which also spreads towards the camera (a level camera sees the ground nearer
    than the disc's foot lower in the picture)."""
    rgb = cv2.resize(np.rot90(skimage.data.logo()[..., :3]), (size, size), interpolation=cv2.INTER_AREA)
    ink = rgb.min(axis=2) < 245  # everything that is not the white page
    rows, cols = np.nonzero(ink)
    centre, radius = np.array([cols.mean(), rows.mean()]) + 0.5, np.sqrt(ink.sum() / np.pi)
    r, c = np.mgrid[0:size, 0:size] + 0.5
    distance = np.hypot(c - centre[0], r - centre[1])
    alpha = np.clip(radius - distance + 0.5, 0, 1)  # one-pixel anti-aliased edge
    # Over white where transparent, so that colour and alpha agree (the page is off-white).
    rgb = np.round(rgb * alpha[..., None] + 255 * (1 - alpha[..., None])).astype(np.uint8)
    rgba = np.dstack([rgb, np.round(alpha * 255).astype(np.uint8)])
    side = (page[0] - size) // 2
    rgba = cv2.copyMakeBorder(rgba, 0, page[1] - size, side, page[0] - size - side, cv2.BORDER_CONSTANT,
                              value=(255, 255, 255, 0))
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


def clay(width: int = 256, height: int = 320) -> None:
    """A column of terracotta modelling clay (rounded top, finger-smoothed texture, lit from the
    left as a cylinder) standing on a grey table in front of a pale wall; its mask."""
    rng = np.random.default_rng(1)
    rows, cols = np.mgrid[0:height, 0:width].astype(np.float64) + 0.5
    table_top = 0.8 * height
    wall = np.array([0.86, 0.84, 0.80]) * (0.95 + 0.05 * rows / height)[..., None]
    table = np.array([0.55, 0.56, 0.58]) * (0.75 + 0.25 * (rows - table_top) / (height - table_top))[..., None]
    rgb = np.where((rows < table_top)[..., None], wall, table)
    cx, half_width, top, foot = width / 2, 0.12 * width, 0.12 * height, table_top + 6
    across = (cols - cx) / half_width
    cap = top + half_width  # a rounded top: a half disc of the column's width
    inside = (np.abs(across) < 1) & (rows < foot) & ((rows > cap) | (np.hypot(across, (rows - cap) / half_width) < 1))
    normal_x = np.clip(across, -1, 1)
    lambert = np.clip(-0.6 * normal_x + 0.8 * np.sqrt(1 - normal_x ** 2), 0, 1)
    smear = cv2.GaussianBlur(rng.standard_normal((height, width)), (0, 0), sigmaX=1.5, sigmaY=6.0)
    smear /= smear.std()
    clay_rgb = np.array([0.78, 0.42, 0.26]) * (0.35 + 0.65 * lambert + 0.05 * smear)[..., None]
    shadow = np.exp(-(((cols - cx - 0.5 * half_width) / (1.6 * half_width)) ** 2 + ((rows - foot) / 6) ** 2))
    rgb = rgb * (1 - 0.45 * shadow * (rows > table_top))[..., None]
    rgb = np.where(inside[..., None], clay_rgb, rgb)
    write_rgb(HERE / "clay" / "clay.png", np.clip(rgb * 255 + 0.5, 0, 255).astype(np.uint8))
    write_image(HERE / "clay" / "clay_mask.png", inside.astype(np.uint8) * 255)


def loaf() -> None:
    """The loaf photograph of the tearing benchmark and the mask of its loaf (its superellipse)."""
    photo = loaf_photo()
    write_image(HERE / "loaf" / "loaf.png", photo)
    rows, cols = np.mgrid[0:photo.shape[0], 0:photo.shape[1]]
    cx, cy, ax, ay = LOAF
    write_image(HERE / "loaf" / "loaf_mask.png",
                (np.abs((cols - cx) / ax) ** 3 + np.abs((rows - cy) / ay) ** 3 < 1).astype(np.uint8) * 255)


if __name__ == "__main__":
    for make in (coffee, logo, ball, clay, loaf):
        (HERE / make.__name__).mkdir(exist_ok=True)
        make()
