"""Loading from local folders, missing weights, control images, and pm-invert / pm-lora / enhance_video end to end."""
import json

import numpy as np
import pytest
import torch

from schemas import InputError, load_scene
from schemas.artifacts import CoarseArtifact, GaussiansArtifact, LatentsArtifact, read_artifact
from stages.enhance.diffusion import enhance_video
from stages.enhance.diffusion.conditioning import canny_control, inverse_depth_control
from stages.enhance.diffusion.invert_cli import main as invert_main
from stages.enhance.diffusion.lora_cli import main as lora_main
from stages.enhance.diffusion.models import load_components
from stages.enhance.diffusion.pipeline import enhance_frames, invert_frames, video_inputs
from testing.tiny_diffusion import tiny_components


FRAMES, SIZE = 3, 64  # of the coarse video the scene_inputs fixture writes


def test_missing_weights_name_each_model_and_leave_no_output(tmp_path, capsys, scene_inputs):
    paths = scene_inputs({"models": {"controlnet_depth": str(tmp_path / "nowhere")}})
    out = tmp_path / "results" / "latents.h5"
    with pytest.raises(SystemExit) as exit_info:
        invert_main(["--scene", str(paths["scene"]), "--coarse", str(paths["coarse"]),
                     "--gaussians", str(paths["gaussians"]), "--out", str(out), "--device", "cpu"])
    assert exit_info.value.code == 2
    message = capsys.readouterr().err
    for name, env in (("stable_diffusion", "PHYSMOTION_SD_PATH"), ("controlnet_depth", "PHYSMOTION_CONTROLNET_DEPTH"),
                      ("controlnet_canny", "PHYSMOTION_CONTROLNET_CANNY")):
        assert name in message and env in message
    assert str(tmp_path / "nowhere") in message  # where it looked
    assert "model_index.json" in message and "huggingface-cli download" in message  # layout and how to supply
    assert not out.parent.exists() or not list(out.parent.iterdir())


def test_an_incomplete_folder_is_reported_with_what_it_lacks(tmp_path, saved_models, monkeypatch, scene_inputs):
    broken = tmp_path / "sd"
    (broken / "unet").mkdir(parents=True)
    monkeypatch.setenv("PHYSMOTION_SD_PATH", str(broken))
    monkeypatch.setenv("PHYSMOTION_CONTROLNET_DEPTH", str(saved_models["controlnet_depth"]))
    monkeypatch.setenv("PHYSMOTION_CONTROLNET_CANNY", str(saved_models["controlnet_canny"]))
    paths = scene_inputs()
    with pytest.raises(InputError) as err:
        load_components(load_scene(paths["scene"]).enhance.diffusion.models, paths["scene"], "cpu")
    assert "stable_diffusion" in str(err.value) and "lacks unet (config.json + weights), vae" in str(err.value)
    assert "controlnet_depth" not in str(err.value).split("missing model weights:")[1]


def test_controls_depth_is_normalised_inverse_depth_and_canny_finds_edges():
    alpha = np.zeros((1, 8, 8), np.float32)
    alpha[0, 2:6, 2:6] = 1
    alpha[0, 2, 2] = 0.5
    distance = np.full((1, 8, 8), 2.0, np.float32)
    distance[0, 2:6, 4:6] = 4.0  # right half of the square is farther
    control = inverse_depth_control(alpha * distance, alpha)  # the render stores alpha-weighted depth
    assert control[0, 3, 3] == pytest.approx(1.0) and control[0, 3, 5] == pytest.approx(0.25)
    assert control[0, 0, 0] == 0 and control[0, 2, 2] == pytest.approx(1.0)  # alpha 0.5: edge of the object
    frame = np.zeros((1, 32, 32, 3), np.uint8)
    frame[0, 8:24, 8:24] = 255
    edges = canny_control(frame, (100, 200))
    assert set(np.unique(edges)) == {0.0, 1.0}
    assert edges[0, 16, 7:9].max() == 1 and edges[0, 16, 16] == 0 and edges[0, 2, 2] == 0


def test_blended_frames_are_alpha_over_the_background(scene_inputs):
    paths = scene_inputs()
    coarse = read_artifact(paths["coarse"], CoarseArtifact)
    gaussians = read_artifact(paths["gaussians"], GaussiansArtifact)
    inputs = video_inputs(coarse, gaussians, load_scene(paths["scene"]).enhance.diffusion)
    assert inputs.blended.shape == (FRAMES, SIZE, SIZE, 3) and inputs.depth.shape == (FRAMES, SIZE, SIZE)
    a = coarse.alpha
    inside, outside = np.unravel_index(np.argmax(a[1]), a[1].shape), (0, SIZE - 1)
    assert np.array_equal(inputs.blended[1][inside], [220, 60, 40])  # alpha 1: the object's colour
    assert np.array_equal(inputs.blended[1][outside], gaussians.background[outside])


def test_saved_pipeline_loads_through_our_code_and_gives_the_same_frames(tmp_path, scene_inputs, with_models):
    paths = scene_inputs(with_models)
    scene = load_scene(paths["scene"])
    out = tmp_path / "results" / "latents.h5"
    invert_main(["--scene", str(paths["scene"]), "--coarse", str(paths["coarse"]),
                 "--gaussians", str(paths["gaussians"]), "--out", str(out), "--device", "cpu"])
    latents = read_artifact(out, LatentsArtifact)
    assert latents.latents.shape == (FRAMES, 5, 4, SIZE // 8, SIZE // 8) and latents.latents.dtype == np.float16
    assert latents.timesteps.tolist() == [-1, 1, 251, 501, 751]
    assert latents.prompt == scene.prompt and json.loads(latents.scheduler)["prediction_type"] == "v_prediction"
    coarse = read_artifact(paths["coarse"], CoarseArtifact)
    gaussians = read_artifact(paths["gaussians"], GaussiansArtifact)
    frames = enhance_video(scene, coarse, gaussians, latents, None, "cpu")
    assert frames.shape == (FRAMES, SIZE, SIZE, 3) and frames.dtype == np.uint8

    in_memory = tiny_components("v_prediction", seed=3)  # the very model the fixture saved
    settings = scene.enhance.diffusion
    inputs = video_inputs(coarse, gaussians, settings)
    reference = invert_frames(in_memory, inputs, scene.prompt, settings)
    # Equal up to float rounding: oneDNN convolutions round differently with differently aligned weights.
    np.testing.assert_allclose(reference.latents.astype(np.float32), latents.latents, rtol=1e-2, atol=1e-4)
    again = enhance_frames(in_memory, inputs, latents, scene.prompt, settings)
    assert np.abs(again.astype(int) - frames).max() <= 1


def test_enhance_refuses_latents_of_another_prompt(scene_inputs, with_models):
    paths = scene_inputs(with_models)
    scene = load_scene(paths["scene"])
    latents = LatentsArtifact(latents=np.zeros((FRAMES, 5, 4, 8, 8), np.float16),
                              timesteps=np.array([-1, 1, 251, 501, 751]), scheduler="{}", prompt="a blue chair")
    with pytest.raises(InputError, match="a blue chair"):
        enhance_video(scene, read_artifact(paths["coarse"], CoarseArtifact),
                      read_artifact(paths["gaussians"], GaussiansArtifact), latents, None, "cpu")


def test_enhance_asks_for_the_lora_when_it_is_enabled(scene_inputs, with_models):
    paths = scene_inputs({**with_models, "lora": {"enabled": True}})
    with pytest.raises(InputError, match="pm-lora"):
        enhance_video(load_scene(paths["scene"]), None, None, None, None, "cpu")


def test_pm_lora_trains_saves_and_the_lora_changes_the_model(tmp_path, scene_inputs, with_models):
    paths = scene_inputs({**with_models, "lora": {"enabled": True, "steps": 3, "learning_rate": 1e-2}})
    out = tmp_path / "results" / "lora"
    lora_main(["--scene", str(paths["scene"]), "--gaussians", str(paths["gaussians"]), "--out", str(out),
               "--device", "cpu"])
    report = json.loads((out / "training.json").read_text())
    assert len(report["loss"]) == 3 and report["images"] == 1
    scene = load_scene(paths["scene"])
    base = load_components(scene.enhance.diffusion.models, scene.file, "cpu")
    tuned = load_components(scene.enhance.diffusion.models, scene.file, "cpu", lora_dir=out)
    x, text = torch.randn(1, 4, 8, 8), base.encode_prompt("a red ball")
    with torch.no_grad():
        assert not torch.allclose(base.unet(x, 500, text).sample, tuned.unet(x, 500, text).sample)
    assert not list(out.parent.glob(".lora.partial-*"))


def test_enhance_refuses_latents_without_the_sampling_timesteps(scene_inputs, with_models):
    paths = scene_inputs({**with_models, "steps": 5})  # 5 sampling steps visit t = 801, ... not inverted
    scene = load_scene(paths["scene"])
    latents = LatentsArtifact(latents=np.zeros((FRAMES, 5, 4, 8, 8), np.float16),
                              timesteps=np.array([-1, 1, 251, 501, 751]), scheduler=json.dumps(
                                  {"prediction_type": "v_prediction", "beta_schedule": "scaled_linear",
                                   "beta_start": 0.00085, "beta_end": 0.012, "num_train_timesteps": 1000}),
                              prompt=scene.prompt)
    with pytest.raises(InputError, match="not inverted"):
        enhance_video(scene, read_artifact(paths["coarse"], CoarseArtifact),
                      read_artifact(paths["gaussians"], GaussiansArtifact), latents, None, "cpu")
