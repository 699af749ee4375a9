"""objects[].hints in scene.yaml: resolved, checked against the photograph, hashed only where given."""
import cv2
import numpy as np
import pytest

from schemas import InputError, config_hash, load_scene, stage_keys
from schemas.images import read_hints
from testing.tiny_scene import tiny_scene_dict, write_scene


def boxed_scene(folder, **obj):
    scene = tiny_scene_dict()
    merged = {"box": [12, 8, 52, 44], "size_m": 0.2, **obj}
    scene["objects"][0] = {k: v for k, v in merged.items() if v is not None}
    return write_scene(folder, scene)


def test_hints_resolve_and_change_only_reconstructs_hash(tmp_path):
    path = boxed_scene(tmp_path / "s")
    before = {stage: config_hash(stage_keys(load_scene(path), stage)) for stage in ("reconstruct", "simulate")}
    hints = np.zeros((48, 64, 4), np.uint8)
    cv2.line(hints, (20, 20), (40, 20), (255, 255, 255, 255), 3)
    cv2.imwrite(str(tmp_path / "s" / "hints.png"), hints)
    scene = load_scene(boxed_scene(tmp_path / "s", hints="hints.png"))
    assert scene.objects[0].hints == (tmp_path / "s" / "hints.png").resolve()
    assert config_hash(stage_keys(scene, "reconstruct")) != before["reconstruct"]
    assert config_hash(stage_keys(scene, "simulate")) == before["simulate"]
    obj, background = read_hints(scene.objects[0].hints, (48, 64))
    assert obj[20, 30] and not background.any() and obj.sum() == (hints[..., 3] > 0).sum()


@pytest.mark.parametrize("obj, field, words", [
    ({"hints": "missing.png"}, "objects[0].hints", "does not exist"),
    ({"hints": "small.png"}, "objects[0].hints", "is 32x24, the photograph is 64x48"),
    ({"box": None, "mask": "mask.png", "hints": "small.png"}, "objects[0]", "give mask or hints, not both"),
])
def test_bad_hints_are_named(tmp_path, obj, field, words):
    folder = tmp_path / "s"
    folder.mkdir()
    cv2.imwrite(str(folder / "small.png"), np.zeros((24, 32, 4), np.uint8))
    path = boxed_scene(folder, **obj)
    with pytest.raises(InputError) as err:
        load_scene(path)
    assert err.value.field == field and words in err.value.problem


def test_hints_without_alpha_mark_only_white_and_black(tmp_path):
    grey = np.full((48, 64), 128, np.uint8)
    grey[10, 10], grey[20, 20] = 255, 0
    cv2.imwrite(str(tmp_path / "h.png"), grey)
    obj, background = read_hints(tmp_path / "h.png", (48, 64))
    assert obj.sum() == 1 and obj[10, 10] and background.sum() == 1 and background[20, 20]
    assert read_hints(tmp_path / "h.png", (48, 65)) is None
