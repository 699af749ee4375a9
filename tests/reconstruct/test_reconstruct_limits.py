"""pm-reconstruct's limits: a bounded copy of a large photograph, tiny photographs and objects refused,
no artifact from a diverged optimisation or without Gaussians."""
import logging

import cv2
import numpy as np
import pytest

from schemas import InputError, load_scene
from schemas.artifacts import GaussiansArtifact, read_artifact
from stages.reconstruct import pipeline
from stages.reconstruct.cli import check_result, main
from stages.reconstruct.geometry import intrinsics_from_fov
from stages.reconstruct.metrics import iou
from testing.photographs import Capsule, write_scene


@pytest.mark.parametrize("segmentation", ["mask", "box"])
def test_a_photograph_above_the_limit_is_reconstructed_from_a_bounded_copy(tmp_path, monkeypatch, caplog,
                                                                           segmentation):
    """The limit lowered to 40 px so that a 64 x 48 photograph is above it: the artifact holds the 40 x 30
    copy, its camera and a mask that matches the mask file shrunk independently."""
    scene = write_scene(tmp_path, Capsule.tilted(), width=64, height=48, iterations=2)
    mask = cv2.imread(str(tmp_path / "mask.png"), cv2.IMREAD_GRAYSCALE) > 0
    if segmentation == "box":
        rows, cols = np.nonzero(mask)
        text = scene.read_text().replace("mask: mask.png", f"box: [{cols.min() - 3}, {rows.min() - 3}, "
                                         f"{cols.max() + 4}, {rows.max() + 4}]")
        assert text != scene.read_text()
        scene.write_text(text)
    monkeypatch.setattr(pipeline, "MAX_PHOTO_PX", 40)
    with caplog.at_level(logging.INFO):
        main(["--scene", str(scene), "--out", str(tmp_path / "g.h5"), "--device", "cpu"])
    assert "photograph 64x48 px: working on a copy of 40x30 px" in caplog.text
    g = read_artifact(tmp_path / "g.h5", GaussiansArtifact)
    assert (g.width, g.height) == (40, 30) and g.photo.shape == (30, 40, 3)
    assert np.allclose(g.K, intrinsics_from_fov(40, 40, 30))
    shrunk = cv2.resize(mask.astype(np.uint8), (40, 30), interpolation=cv2.INTER_AREA) > 0
    assert iou(g.mask == 1, shrunk) > (0.97 if segmentation == "mask" else 0.8)


def test_a_one_pixel_photograph_is_refused(tmp_path, capsys):
    cv2.imwrite(str(tmp_path / "photo.png"), np.full((1, 1, 3), 128, np.uint8))
    (tmp_path / "scene.yaml").write_text("image: photo.png\n")
    with pytest.raises(SystemExit) as exit_:
        main(["--scene", str(tmp_path / "scene.yaml"), "--out", str(tmp_path / "g.h5"), "--device", "cpu"])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and "1x1 pixels, below the 16 px" in err and "Traceback" not in err


def test_a_box_over_the_whole_photograph_is_refused(tmp_path):
    scene = write_scene(tmp_path, Capsule.tilted(), width=64, height=48, iterations=2)
    scene.write_text(scene.read_text().replace("mask: mask.png", "box: [0, 0, 64, 48]"))
    with pytest.raises(InputError, match="covers the whole 64x48 photograph") as err:
        pipeline.prepare(load_scene(scene))
    assert err.value.field == "objects[0].box"


def test_an_object_nearer_than_the_renderer_sees_is_refused(tmp_path):
    scene = write_scene(tmp_path, Capsule.tilted(), width=64, height=48, iterations=2)
    # a 1 cm object covering the capsule's pixels under a wide lens (100 degrees: the capsule spans about 70
    # of them, not so wide that the lens is to blame)
    text = scene.read_text().replace("fov_deg: 40", "fov_deg: 100")
    scene.write_text(text.replace(f"size_m: {load_scene(scene).objects[0].size_m}", "size_m: 0.01"))
    assert "0.01" in scene.read_text() and "100" in scene.read_text()
    with pytest.raises(InputError, match="nearer than the renderer sees") as err:
        pipeline.prepare(load_scene(scene))
    assert err.value.field == "objects[0].size_m"


def test_no_artifact_from_a_nan_loss_or_without_gaussians(tmp_path):
    scene = load_scene(write_scene(tmp_path, Capsule.tilted(), width=64, height=48, iterations=2))
    loss = np.zeros((5, 4), np.float32)
    check_result(scene, 10, 10, loss)
    loss[3, 0] = np.nan
    with pytest.raises(InputError, match="diverged: its loss is nan from iteration 4"):
        check_result(scene, 10, 10, loss)
    with pytest.raises(InputError, match="no Gaussian is left of the 10"):
        check_result(scene, 10, 0, np.zeros((5, 4)))
