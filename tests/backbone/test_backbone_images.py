"""Image files are read as viewers show them: EXIF orientation applied, alpha and bit depth kept."""
import numpy as np
import pytest
import yaml
from PIL import Image, ImageOps

from schemas import load_scene
from schemas.images import read_image
from stages.reconstruct.segment import read_photo
from testing.tiny_scene import tiny_scene_dict

EXIF_ORIENTATION = 0x0112


def save_with_orientation(image: np.ndarray, path, orientation: int) -> None:
    exif = Image.Exif()
    exif[EXIF_ORIENTATION] = orientation
    Image.fromarray(image).save(path, exif=exif.tobytes())


@pytest.mark.parametrize("orientation", range(1, 9))
def test_every_exif_orientation_is_applied_as_pillow_applies_it(tmp_path, orientation):
    rgba = np.random.default_rng(orientation).integers(0, 256, (12, 20, 4), dtype=np.uint8)
    path = tmp_path / "photo.png"
    save_with_orientation(rgba, path, orientation)
    expected = np.asarray(ImageOps.exif_transpose(Image.open(path)))
    bgra = read_image(path)
    assert bgra.shape == expected.shape
    assert np.array_equal(bgra[..., [2, 1, 0, 3]], expected)


def test_a_portrait_phone_photograph_is_upright_for_its_box(tmp_path):
    """Stored 64 wide and 48 high with orientation 6 (turn clockwise): shown 48 wide and 64 high. The box
    is drawn on what is shown; read as stored, it reached outside the image."""
    stored = np.zeros((48, 64, 3), np.uint8)
    stored[:, :8] = 255  # the stored left edge is the shown top edge
    save_with_orientation(stored, tmp_path / "photo.jpg", 6)
    scene = tiny_scene_dict()
    scene["image"] = "photo.jpg"
    scene["objects"][0] = {"box": [4, 40, 44, 62], "size_m": 0.2}
    (tmp_path / "scene.yaml").write_text(yaml.safe_dump(scene))
    load_scene(tmp_path / "scene.yaml")
    rgb, alpha = read_photo(tmp_path / "photo.jpg")
    assert rgb.shape == (64, 48, 3) and alpha is None
    assert rgb[:6].min() > 200 and rgb[10:].max() < 50
