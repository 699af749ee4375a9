"""Fixtures of the diffusion-backend tests: tiny random SD-2.1-shaped models, saved copies of
them, and a scene folder with coarse.h5 and gaussians.h5 of a small moving disc. All offline."""
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch
import yaml

from schemas.artifacts import CoarseArtifact, GaussiansArtifact, write_artifact
from schemas.solid import solid_fields
from testing.tiny_diffusion import save_tiny_models, tiny_components

SIZE = 64  # coarse frames and photo: 64 x 64 px -> 8 x 8 latents
FRAMES = 3


@pytest.fixture(autouse=True)
def _offline(monkeypatch, tmp_path_factory):
    """No model from the environment, a models file or the user's cache may leak into a test."""
    for name in ("PHYSMOTION_SD_PATH", "PHYSMOTION_CONTROLNET_DEPTH", "PHYSMOTION_CONTROLNET_CANNY"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("PHYSMOTION_MODELS_FILE", str(tmp_path_factory.getbasetemp() / "no-models.yaml"))
    monkeypatch.setenv("HF_HUB_CACHE", str(tmp_path_factory.mktemp("empty-hf-cache")))
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    torch.manual_seed(0)
    # The tiny models are too small to gain from threads, and lose 10x when the cores are busy.
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.fixture(scope="session")
def tiny():
    return tiny_components("v_prediction")


@pytest.fixture(scope="session")
def saved_models(tmp_path_factory) -> dict:
    """A v-prediction tiny model saved as the real weights are laid out; returns its three folders."""
    return save_tiny_models(tiny_components("v_prediction", seed=3), tmp_path_factory.mktemp("models"))


def _disc(cx: float, cy: float, r: float):
    rows, cols = np.mgrid[0:SIZE, 0:SIZE] + 0.5
    dist = np.hypot(cols - cx, rows - cy)
    return np.clip(r - dist + 0.5, 0, 1).astype(np.float32), dist


def write_inputs(folder: Path, enhance: dict) -> dict:
    """scene.yaml, photo, gaussians.h5 and coarse.h5 of a disc moving right; returns their paths."""
    folder.mkdir(parents=True, exist_ok=True)
    alpha0, _ = _disc(24, 32, 12)
    rng = np.random.default_rng(0)
    background = rng.integers(40, 90, (SIZE, SIZE, 3)).astype(np.uint8)
    photo = np.where(alpha0[..., None] > 0.5, np.array([220, 60, 40], np.uint8), background)
    cv2.imwrite(str(folder / "photo.png"), photo[..., ::-1])
    (folder / "scene.yaml").write_text(yaml.safe_dump({
        "image": "photo.png", "prompt": "a red ball on a wooden table",
        "enhance": {"backend": "diffusion", "diffusion": enhance}}))
    gaussians = GaussiansArtifact(
        K=np.eye(3), world_to_camera=np.eye(4), width=SIZE, height=SIZE,
        means=np.zeros((1, 3), np.float32), scales=np.full((1, 3), 0.1, np.float32),
        rotations=np.array([[1, 0, 0, 0]], np.float32), opacities=np.ones(1, np.float32),
        colors=np.full((1, 3), 0.5, np.float32), object_id=np.zeros(1, np.int32), photo=photo,
        mask=(alpha0 > 0.5).astype(np.uint8), background=background,
        depth_prior=np.full((SIZE, SIZE), np.nan, np.float32), **solid_fields([None]), loss=np.zeros((0, 2), np.float32),
        loss_terms=["colour", "depth"])
    frames = [_disc(24 + 6 * j, 32, 12) for j in range(FRAMES)]
    alpha = np.stack([a for a, _ in frames])
    depth = np.stack([a * (1.0 + 0.01 * d) for a, d in frames]).astype(np.float32)
    rgb = (alpha[..., None] * np.array([220, 60, 40])).astype(np.uint8)
    coarse = CoarseArtifact(rgb=rgb, alpha=alpha, depth=depth,
                            source_uv=np.zeros((FRAMES, SIZE, SIZE, 2), np.float32),
                            source_coherence=np.zeros((FRAMES, SIZE, SIZE), np.float32),
                            source_confidence=np.zeros((FRAMES, SIZE, SIZE), np.float32),
                            normal=np.zeros((FRAMES, SIZE, SIZE, 3), np.float32),
                            K=np.eye(3), width=SIZE, height=SIZE, fps=8.0)
    paths = {"scene": folder / "scene.yaml", "gaussians": folder / "gaussians.h5", "coarse": folder / "coarse.h5"}
    write_artifact(paths["gaussians"], gaussians, created_by="test", config_hash="0")
    write_artifact(paths["coarse"], coarse, created_by="test", config_hash="0")
    return paths


@pytest.fixture
def scene_inputs(tmp_path):
    """write_inputs(settings) in a fresh folder, with few steps and small batches unless overridden:
    four sampling steps over four inverted ones, three frames in batches of two."""
    def make(settings: dict | None = None) -> dict:
        fast = {"resolution": SIZE, "steps": 4, "inversion_stride": 250, "frame_batch": 2, "keyframe_window": 2}
        return write_inputs(tmp_path / "scene", {**fast, **(settings or {})})
    return make


@pytest.fixture
def with_models(saved_models) -> dict:
    """enhance.diffusion settings naming the saved tiny models."""
    return {"models": {k: str(v) for k, v in saved_models.items()}}
