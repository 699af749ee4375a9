"""pm-lora: personalise Stable Diffusion 2.1 on the object with a LoRA (paper Sec. 3.4.1)."""
from __future__ import annotations

import argparse
import json
import logging
import os
import shutil
from pathlib import Path

import cv2
import torch

from schemas import InputError, config_hash, load_scene, resolve_device, run_main, stage_keys, stage_parser
from schemas.artifacts import GaussiansArtifact, check_lineage, read_artifact

log = logging.getLogger("physmotion.diffusion")


def build_parser() -> argparse.ArgumentParser:
    parser = stage_parser("pm-lora", """\
Train a LoRA on Stable Diffusion 2.1's UNet from the segmented object (the
photograph's object pixels on white) and the scene's reconstruct.extra_views,
captioned with the scene's prompt, for enhance.diffusion.lora.steps steps
(paper: 1500 at learning rate 1e-6). Writes OUT/pytorch_lora_weights.safetensors
and OUT/training.json; pm-invert and pm-enhance take OUT with --lora.""")
    parser.add_argument("--scene", required=True, type=Path, help="scene.yaml")
    parser.add_argument("--gaussians", required=True, type=Path, help="gaussians.h5 from pm-reconstruct")
    parser.add_argument("--out", required=True, type=Path, help="folder to write the LoRA into")
    return parser


def _read_rgb(path: Path):
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise InputError(path, None, "cannot read this file as an image", "give a PNG or JPEG extra view")
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


def train(args: argparse.Namespace) -> None:
    from .lora import save_lora, train_lora, training_images
    from .models import load_components

    scene = load_scene(args.scene)
    settings = scene.enhance.diffusion
    device = resolve_device(args.device)
    check_lineage(scene, gaussians=args.gaussians)
    gaussians = read_artifact(args.gaussians, GaussiansArtifact)
    extra_views = [_read_rgb(view.image) for view in scene.reconstruct.extra_views]
    images = training_images(gaussians.photo, gaussians.mask, extra_views, settings.resolution)
    components = load_components(settings.models, scene.file, device, dtype=torch.float32)  # trains in float32
    log.info("training a rank-%d LoRA on %d image(s) for %d steps", settings.lora.rank, len(images),
             settings.lora.steps)
    losses = train_lora(components, images, scene.prompt, settings.lora, seed=settings.seed)
    # Written beside the target and renamed when complete: a killed run leaves no finished-looking folder.
    partial = args.out.with_name(f".{args.out.name}.partial-{os.getpid()}")
    try:
        save_lora(components.unet, partial)
        (partial / "training.json").write_text(json.dumps(
            {"config_hash": config_hash(stage_keys(scene, "lora")), "images": len(images), "loss": losses}))
        shutil.rmtree(args.out, ignore_errors=True)
        partial.rename(args.out)
    finally:
        shutil.rmtree(partial, ignore_errors=True)
    log.info("wrote %s (loss %.4f -> %.4f over the first and last 50 steps)", args.out,
             sum(losses[:50]) / len(losses[:50]), sum(losses[-50:]) / len(losses[-50:]))


def main(argv=None) -> None:
    run_main(train, build_parser(), argv)


if __name__ == "__main__":
    main()
