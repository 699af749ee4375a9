"""scene.yaml: YAML 1.2 numbers, validation and the messages users see."""
import json
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from schemas import config_hash, load_scene, scene_json_schema, stage_keys
from testing.tiny_scene import tiny_scene_dict, write_scene

from .conftest import scene_refusal

REPO = Path(__file__).resolve().parents[2]


def test_yaml12_exponent_floats_are_numbers(scene_dir):
    text = (scene_dir / "scene.yaml").read_text().replace("20000.0", "2e4")
    assert "2e4" in text
    (scene_dir / "scene.yaml").write_text(text + "\n")
    scene = load_scene(scene_dir / "scene.yaml")
    assert scene.objects[0].material.youngs_modulus == 2e4
    assert scene.physics.grid == 16 and isinstance(scene.physics.grid, int)


def test_paths_resolve_relative_to_the_scene(scene_dir):
    scene = load_scene(scene_dir)
    assert scene.image == (scene_dir / "photo.png").resolve()
    assert scene.objects[0].mask == (scene_dir / "mask.png").resolve()


def test_unknown_key_names_key_and_place(tmp_path):
    scene = tiny_scene_dict()
    scene["objects"][0]["material"]["yield_stress"] = 1e4  # not a jelly key
    err = scene_refusal(tmp_path, scene)
    assert err.field == "objects[0].material.yield_stress"
    assert "unknown key" in err.problem and "scene.yaml" in err.file


def test_out_of_range_poisson_ratio(tmp_path):
    scene = tiny_scene_dict()
    scene["objects"][0]["material"]["poisson_ratio"] = 0.5
    err = scene_refusal(tmp_path, scene)
    assert err.field == "objects[0].material.poisson_ratio" and "0.5" in err.problem


@pytest.mark.parametrize("section, key, value", [
    ("physics", "fps", 0), ("physics", "duration_s", -1.0), ("render", "width", 0)])
def test_non_positive_values_are_refused(tmp_path, section, key, value):
    scene = tiny_scene_dict()
    scene[section][key] = value
    assert scene_refusal(tmp_path, scene).field == f"{section}.{key}"


def test_unknown_preset_lists_the_presets(tmp_path):
    scene = tiny_scene_dict()
    scene["objects"][0]["material"] = {"preset": "rubber"}
    err = scene_refusal(tmp_path, scene)
    assert err.field == "objects[0].material" and "jelly" in err.problem


def test_yaml_syntax_error_gives_line(tmp_path):
    err = scene_refusal(tmp_path, text="image: photo.png\nobjects: [\n  {size_m: 0.2\n")
    assert "YAML syntax error at line" in err.problem and err.file.endswith("scene.yaml")


def test_missing_image(tmp_path):
    scene = tiny_scene_dict()
    scene["image"] = "nothere.png"
    err = scene_refusal(tmp_path, scene)
    assert err.field == "image" and "nothere.png" in err.problem


def test_unreadable_image(tmp_path):
    write_scene(tmp_path)
    (tmp_path / "photo.png").write_text("not a png")
    err = scene_refusal(tmp_path)
    assert err.file.endswith("photo.png") and "cannot read" in err.problem


def test_empty_mask(tmp_path):
    write_scene(tmp_path)
    cv2.imwrite(str(tmp_path / "mask.png"), np.zeros((48, 64), np.uint8))
    err = scene_refusal(tmp_path)
    assert err.field == "objects[0].mask" and "empty" in err.problem


def test_mask_of_other_size(tmp_path):
    write_scene(tmp_path)
    cv2.imwrite(str(tmp_path / "mask.png"), np.full((10, 10), 255, np.uint8))
    err = scene_refusal(tmp_path)
    assert "10x10" in err.problem and "64x48" in err.problem


def test_box_outside_image(tmp_path):
    scene = tiny_scene_dict()
    scene["objects"][0] = {"box": [10, 10, 80, 40], "size_m": 0.2}
    err = scene_refusal(tmp_path, scene)
    assert err.field == "objects[0].box" and "outside" in err.problem


def test_condition_naming_a_missing_object(tmp_path):
    scene = tiny_scene_dict()
    scene["physics"]["conditions"][0]["object"] = 3
    assert "object is 3" in scene_refusal(tmp_path, scene).problem


def test_paragraph_names_file_field_and_fix(tmp_path):
    scene = tiny_scene_dict()
    scene["physics"]["fps"] = 0
    text = scene_refusal(tmp_path, scene).paragraph()
    assert "scene.yaml" in text and "physics.fps" in text and "Fix:" in text


def rehashed_stages(scene_dir: Path, edit) -> list[str]:
    """The stages whose config hash changes when ``edit`` edits the scene's YAML mapping in place."""
    stages = ("reconstruct", "simulate", "render", "enhance")
    before = {s: config_hash(stage_keys(load_scene(scene_dir), s)) for s in stages}
    raw = yaml.safe_load((scene_dir / "scene.yaml").read_text())
    edit(raw)
    write_scene(scene_dir, raw)
    return [s for s in stages if config_hash(stage_keys(load_scene(scene_dir), s)) != before[s]]


def test_stage_keys_separate_the_stages(scene_dir):
    assert rehashed_stages(scene_dir, lambda raw: raw["physics"].update(fps=12)) == ["simulate"]


def test_thickness_is_hashed_for_reconstruct_only_where_given(scene_dir):
    """objects[].thickness_m reruns reconstruct alone, and a scene without it hashes as before the key existed
    (the reconstruct key of a scene without it holds no thickness_m at all)."""
    assert "thickness_m" not in stage_keys(load_scene(scene_dir), "reconstruct")["objects"][0]
    assert rehashed_stages(scene_dir, lambda raw: raw["objects"][0].update(thickness_m=0.02)) == ["reconstruct"]


def test_hash_does_not_depend_on_where_the_scene_lives(tmp_path):
    a, b = write_scene(tmp_path / "a"), write_scene(tmp_path / "elsewhere" / "b")
    assert config_hash(stage_keys(load_scene(a), "reconstruct")) == config_hash(stage_keys(load_scene(b), "reconstruct"))


def test_example_scenes_are_valid():
    names = sorted(p.parent.name for p in (REPO / "scenes").glob("*/scene.yaml"))
    assert len(names) >= 3
    for name in names:
        load_scene(REPO / "scenes" / name)


def test_exported_json_schema_is_current():
    committed = json.loads((REPO / "docs" / "scene.schema.json").read_text())
    assert committed == scene_json_schema(), "regenerate with: python -m schemas.export_schema"


def test_model_folders_resolve_or_are_refused(tmp_path):
    scene = tiny_scene_dict()
    scene["reconstruct"]["depth_model"] = "models/dpt"
    err = scene_refusal(tmp_path, scene)
    assert err.field == "reconstruct.depth_model" and "models/dpt" in err.problem
    (tmp_path / "models" / "dpt").mkdir(parents=True)
    assert load_scene(tmp_path).reconstruct.depth_model == (tmp_path / "models" / "dpt").resolve()


def test_error_inside_a_condition_names_its_field(tmp_path):
    scene = tiny_scene_dict()
    scene["physics"]["conditions"][0]["velocity"] = [1.0, 2.0]  # an impulse's 'velocity' is also a condition type
    assert scene_refusal(tmp_path, scene).field.startswith("physics.conditions[0].velocity")
