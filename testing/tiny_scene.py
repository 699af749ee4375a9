"""The tiny scene: a textured disc photographed at 64x48 px, with its mask, and a scene.yaml that runs the
whole workflow in seconds (few iterations, a coarse grid, few frames). The workflow and scene tests of
tests/backbone and tests/containers write it."""
from pathlib import Path

import cv2
import numpy as np
import yaml


def make_photo(folder: Path, width: int = 64, height: int = 48, name: str = "photo.png") -> Path:
    """A textured disc on a plain background, with its mask (mask.png)."""
    rows, cols = np.mgrid[0:height, 0:width]
    disc = (cols - width / 2) ** 2 + (rows - height * 0.55) ** 2 < (height * 0.3) ** 2
    rgb = np.full((height, width, 3), (90, 120, 160), np.uint8)
    stripes = ((cols // 3) % 2 == 0)
    rgb[disc & stripes] = (230, 60, 40)
    rgb[disc & ~stripes] = (250, 210, 70)
    cv2.imwrite(str(folder / name), rgb[..., ::-1])
    cv2.imwrite(str(folder / "mask.png"), disc.astype(np.uint8) * 255)
    return folder / name


def tiny_scene_dict() -> dict:
    """A scene that runs end to end in seconds: 64 px, few iterations, coarse grid, few frames."""
    return {
        "image": "photo.png",
        "camera": {"fov_deg": 40, "pitch_deg": 0},
        "objects": [{"mask": "mask.png", "size_m": 0.2,
                     "material": {"preset": "jelly", "youngs_modulus": 2.0e4}}],
        "reconstruct": {"resolution": 64, "iterations": 10},
        "physics": {"duration_s": 0.25, "fps": 8, "grid": 16, "particles_per_cell": 2,
                    "conditions": [{"type": "impulse", "velocity": [0.5, -0.5, 0.0]}]},
        "render": {"width": 64},
        "enhance": {"backend": "flow"},
    }


def write_scene(folder: Path, scene: dict | None = None, text: str | None = None) -> Path:
    """Write folder/scene.yaml (the scene dict, or the raw text where a test needs malformed YAML; by default
    tiny_scene_dict()) beside the tiny photograph (written once): the scene file's path."""
    folder.mkdir(parents=True, exist_ok=True)
    if not (folder / "photo.png").exists():
        make_photo(folder)
    path = folder / "scene.yaml"
    path.write_text(text if text is not None else yaml.safe_dump(scene or tiny_scene_dict(), sort_keys=False))
    return path
