"""pm-enhance: coarse.h5 -> video.mp4 (+ contact_sheet.png beside it)."""
from __future__ import annotations

import argparse
import logging
from pathlib import Path

import cv2
import numpy as np

from schemas import InputError, config_hash, load_scene, resolve_device, run_main, stage_keys, stage_parser
from schemas.artifacts import CoarseArtifact, GaussiansArtifact, LatentsArtifact, check_lineage, read_artifact
from schemas.files import check_writable, refuse_overwriting
from schemas.images import write_image
from schemas.video import write_video

from . import flow
from .compositing import blend_over_background, resize_to, unpremultiply
from .contact_sheet import contact_sheet

log = logging.getLogger("physmotion.enhance")


def hidden_surfaces(scene) -> str:
    """enhance.hidden_surfaces where the scene gives it; else the render where reconstruct.prior lgm gave the unseen
    surfaces colours of their own (LGM's), the photograph (the mirrored front they continue) otherwise."""
    if "hidden_surfaces" not in scene.enhance.model_fields_set and scene.reconstruct.prior == "lgm":
        return "render"
    return scene.enhance.hidden_surfaces

DESCRIPTION = """\
Enhance the coarse render into the final video (paper Sec. 3.4), by the scene's enhance.backend:
  flow       (default, no model weights) the photograph's own pixels, carried along with the
             simulated motion through source_uv and trusted by source_confidence; surfaces the
             photograph never saw take the colour of the mirrored front they continue
             (enhance.hidden_surfaces: photo) or show the render (render); re-shaded for where the
             surface faces now (enhance.relight); blended over the inpainted background, with the
             objects' shadows cast where they are now when the scene has a ground.
  diffusion  Stable Diffusion 2.1 + ControlNets from local weights: needs --latents from pm-invert
             (and --lora from pm-lora when enhance.diffusion.lora.enabled).
Writes the video (H.264) and contact_sheet.png beside it (rows: input = the photograph, coarse =
the render over the inpainted background, enhanced)."""


def build_parser() -> argparse.ArgumentParser:
    parser = stage_parser("pm-enhance", DESCRIPTION)
    parser.add_argument("--scene", required=True, type=Path, help="scene.yaml")
    parser.add_argument("--coarse", required=True, type=Path, help="coarse.h5 from pm-render")
    parser.add_argument("--gaussians", required=True, type=Path, help="gaussians.h5 from pm-reconstruct")
    parser.add_argument("--latents", type=Path, help="latents.h5 from pm-invert (diffusion backend)")
    parser.add_argument("--lora", type=Path, help="LoRA folder from pm-lora (diffusion backend)")
    parser.add_argument("--out", required=True, type=Path, help="video.mp4 to write")
    return parser


def enhance(args: argparse.Namespace) -> None:
    scene = load_scene(args.scene)
    sheet_path = args.out.with_name("contact_sheet.png")
    refuse_overwriting({"--out": args.out, "contact_sheet.png": sheet_path},
                       {"--scene": scene.file, "--coarse": args.coarse, "--gaussians": args.gaussians,
                        "--latents": args.latents})
    check_writable([args.out, sheet_path])
    check_lineage(scene, gaussians=args.gaussians, coarse=args.coarse, latents=args.latents)
    coarse = read_artifact(args.coarse, CoarseArtifact)
    gaussians = read_artifact(args.gaussians, GaussiansArtifact)
    backend = scene.enhance.backend
    log.info("backend %s, %d frames of %dx%d", backend, len(coarse.alpha), coarse.width, coarse.height)
    if backend == "flow":
        frames = flow.enhance_frames(coarse, gaussians, scene.enhance.confidence_threshold,
                                     hidden_surfaces(scene), scene.enhance.relight,
                                     ground=scene.physics.ground.enabled)
    else:
        if args.latents is None:
            raise InputError(args.scene, "enhance.backend", "the diffusion backend needs the inverted latents",
                             "run pm-invert first and pass its output with --latents")
        device = resolve_device(args.device)  # the flow backend is OpenCV's on the CPU and never asks
        from .diffusion import enhance_video  # imports diffusers: only when asked for

        latents = read_artifact(args.latents, LatentsArtifact)
        frames = enhance_video(scene, coarse, gaussians, latents, args.lora, device)
    # Rows as the eye compares them: the photograph (the same in every column, for its detail), the
    # coarse render over the inpainted background (what the simulation alone gives), the enhanced video.
    photo = resize_to(gaussians.photo, coarse.width, coarse.height)
    background = resize_to(gaussians.background, coarse.width, coarse.height)
    coarse_over_background = blend_over_background(unpremultiply(coarse.rgb, coarse.alpha), coarse.alpha, background)
    sheet = contact_sheet({"input": np.broadcast_to(photo, frames.shape), "coarse": coarse_over_background,
                           "enhanced": frames}, coarse.fps)
    write_video(args.out, frames, coarse.fps)
    write_image(sheet_path, cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR))
    log.info("wrote %s (config %s)", args.out, config_hash(stage_keys(scene, "enhance"))[:12])


def main(argv=None) -> None:
    run_main(enhance, build_parser(), argv)
