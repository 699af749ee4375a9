"""Bad scenes refused at load under their own key: non-finite numbers, duplicate keys, out-of-bounds sizes,
folders given as files."""
import math

import pytest

from schemas import InputError, load_scene
from testing.tiny_scene import make_photo, tiny_scene_dict, write_scene

from .conftest import scene_refusal


NON_FINITE = [
    ("physics.fps", lambda s, v: s["physics"].update(fps=v)),
    ("camera.pitch_deg", lambda s, v: s["camera"].update(pitch_deg=v)),
    ("physics.duration_s", lambda s, v: s["physics"].update(duration_s=v)),
    ("objects[0].material.youngs_modulus", lambda s, v: s["objects"][0]["material"].update(youngs_modulus=v)),
    ("physics.conditions[0].velocity[0]", lambda s, v: s["physics"]["conditions"][0].update(velocity=[v, 0, 0])),
    ("physics.gravity[1]", lambda s, v: s["physics"].update(gravity=[0, v, 0])),
    ("enhance.diffusion.guidance_scale", lambda s, v: s["enhance"].update(diffusion={"guidance_scale": v})),
]


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
@pytest.mark.parametrize("field, edit", NON_FINITE, ids=[f for f, _ in NON_FINITE])
def test_non_finite_numbers_are_refused_under_their_own_key(tmp_path, field, edit, value):
    scene = tiny_scene_dict()
    edit(scene, value)
    err = scene_refusal(tmp_path, scene)
    assert err.field == field
    assert "infinite or not a number" in err.problem and "less than" not in err.problem


def test_yaml_spellings_of_nan_and_inf_are_refused(tmp_path):
    for spelling in (".nan", ".inf", "-.Inf", "1e999"):
        text = f"image: photo.png\nobjects:\n  - mask: mask.png\nphysics:\n  fps: {spelling}\n"
        err = scene_refusal(tmp_path, text=text)
        assert err.field == "physics.fps" and "infinite or not a number" in err.problem, spelling


def test_duplicate_keys_are_refused_naming_both_lines(tmp_path):
    text = "image: photo.png\nobjects:\n  - mask: mask.png\n    size_m: 0.2\n    size_m: 5\n"
    err = scene_refusal(tmp_path, text=text)
    assert err.field == "size_m" and "line 4 and line 5" in err.problem


def test_a_key_in_two_different_mappings_is_not_a_duplicate(tmp_path):
    text = ("image: photo.png\nobjects:\n  - {mask: mask.png, size_m: 0.2}\n  - {mask: mask.png, size_m: 0.2}\n"
            "physics: {duration_s: 0.25}\n")
    assert len(load_scene(write_scene(tmp_path, text=text)).objects) == 2


@pytest.mark.parametrize("field, edit", [
    ("objects[0].size_m", lambda s: s["objects"][0].update(size_m=1e30)),
    ("objects[0].size_m", lambda s: s["objects"][0].update(size_m=1e-6)),
    ("physics.duration_s", lambda s: s["physics"].update(duration_s=1e6)),
    ("physics.fps", lambda s: s["physics"].update(fps=1e-3)),
    ("physics.grid", lambda s: s["physics"].update(grid=10 ** 6)),
])
def test_sizes_and_times_outside_their_bounds_are_refused(tmp_path, field, edit):
    scene = tiny_scene_dict()
    edit(scene)
    assert scene_refusal(tmp_path, scene).field == field


def test_an_image_path_that_is_a_folder_is_called_a_folder(tmp_path):
    (tmp_path / "photos").mkdir()
    scene = tiny_scene_dict()
    scene["image"] = "photos"
    err = scene_refusal(tmp_path, scene)
    assert err.field == "image" and "is a folder" in err.problem and "does not exist" not in err.problem


def test_a_scene_file_that_is_not_utf8_is_refused(tmp_path):
    write_scene(tmp_path)
    (tmp_path / "scene.yaml").write_bytes(b"image: photo\xff.png\n")
    with pytest.raises(InputError, match="UTF-8"):
        load_scene(tmp_path / "scene.yaml")


def test_pm_setup_refused_at_start_leaves_nothing_behind(tmp_path, capsys):
    """pm-setup with a missing --image makes no scene folder; with its port taken it copies no photograph."""
    import socket

    from stages.setup import cli as setup_cli

    def start(*args) -> int:
        with pytest.raises(SystemExit) as exit_info:
            setup_cli.main([*map(str, args), "--device", "cpu"])
        assert "Traceback" not in capsys.readouterr().err
        return exit_info.value.code

    folder = tmp_path / "scene"
    assert start(folder, "--image", tmp_path / "missing.png", "--port", "0") == 2
    assert not folder.exists()
    (tmp_path / "photos").mkdir()
    photo = make_photo(tmp_path / "photos")
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        assert start(folder, "--image", photo, "--port", taken.getsockname()[1]) == 2
    assert not folder.exists()


@pytest.mark.parametrize("fov", [120, 170])
def test_a_field_of_view_too_wide_for_the_object_is_blamed_on_camera_fov_deg(tmp_path, capsys, fov):
    """The tiny scene's disc spans 92 degrees at fov_deg 120, which runs, and 164 at 170, where no body of any
    size stands in front of the camera: refused under camera.fov_deg (not size_m, with a negative distance),
    nothing written."""
    from stages.reconstruct import cli as reconstruct_cli

    scene = tiny_scene_dict()
    scene["camera"]["fov_deg"] = fov
    scene["reconstruct"]["iterations"] = 0
    path = write_scene(tmp_path / "scene", scene)
    out = tmp_path / "run" / "gaussians.h5"
    try:
        reconstruct_cli.main(["--scene", str(path), "--out", str(out), "--device", "cpu"])
        code = 0
    except SystemExit as exit_info:
        code = exit_info.code
    err = capsys.readouterr().err
    assert "Traceback" not in err
    if code == 0:
        assert fov == 120 and out.exists()
    else:
        assert code == 2 and "field 'camera.fov_deg'" in err and "size_m" not in err and "-0." not in err, err
        assert not out.exists()
    assert (code == 0) == (fov == 120)
