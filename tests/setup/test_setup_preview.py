"""The preview's scene: only the cost keys lowered, never raised; paths point into the scene folder."""
from pathlib import Path

from stages.setup.preview import PREVIEW_KEYS, preview_scene
from stages.setup.scene_file import dump_scene, leading_comments, without_empty_sections


def test_preview_lowers_the_cost_keys_only():
    raw = {"image": "photo.png", "objects": [{"mask": "mask.png", "size_m": 0.2}, {"box": [1, 2, 3, 4], "hints": "h.png"}],
           "reconstruct": {"iterations": 10, "resolution": 512},
           "physics": {"duration_s": 2.0, "fps": 30, "conditions": [{"type": "fixed"}]}, "render": {"width": 64}}
    scene = preview_scene(raw, Path("/scenes/cup"))
    assert scene["reconstruct"] == {"iterations": 10, "resolution": PREVIEW_KEYS["reconstruct"]["resolution"]}
    assert scene["physics"]["fps"] == PREVIEW_KEYS["physics"]["fps"] and scene["physics"]["duration_s"] == 2.0
    assert scene["physics"]["grid"] == PREVIEW_KEYS["physics"]["grid"] and scene["render"]["width"] == 64
    assert scene["image"] == "/scenes/cup/photo.png" and scene["objects"][0]["mask"] == "/scenes/cup/mask.png"
    assert scene["objects"][1]["hints"] == "/scenes/cup/h.png" and scene["physics"]["conditions"] == [{"type": "fixed"}]
    assert raw["image"] == "photo.png" and raw["render"] == {"width": 64}  # the scene itself untouched


def test_scene_text_reads_like_the_examples():
    text = dump_scene({"image": "p.png", "objects": [{"box": [1, 2, 3, 4], "material": {"preset": "metal"}}],
                       "physics": {"conditions": [{"type": "impulse", "region": {"box": [0, 0, 0, 1, 1, 1]},
                                                   "velocity": [1.0, -2.0, 0.0]}]}}, "# a cup\n")
    assert text.startswith("# a cup\nimage: p.png\n")
    assert "- box: [1, 2, 3, 4]\n" in text and "material: {preset: metal}" in text
    assert "- {type: impulse, region: {box: [0, 0, 0, 1, 1, 1]}, velocity: [1.0, -2.0, 0.0]}" in text
    assert leading_comments("# one\n# two\nimage: x\n# not this\n") == "# one\n# two\n"


def test_sections_left_at_their_defaults_are_not_written():
    raw = {"image": "p.png", "objects": [{}], "camera": {}, "enhance": {"diffusion": {"lora": {}}, "relight": False}}
    assert without_empty_sections(raw) == {"image": "p.png", "objects": [{}], "enhance": {"relight": False}}
