"""pm-invert: DDIM+ inversion of the blended coarse frames into latents.h5 (paper Sec. 3.4.1)."""
from __future__ import annotations

import argparse
import logging
from pathlib import Path

from schemas import config_hash, load_scene, resolve_device, run_main, stage_keys, stage_parser
from schemas.artifacts import CoarseArtifact, GaussiansArtifact, check_lineage, read_artifact, write_artifact
from schemas.files import check_writable, refuse_overwriting

log = logging.getLogger("physmotion.diffusion")


def build_parser() -> argparse.ArgumentParser:
    parser = stage_parser("pm-invert", """\
Blend every coarse frame over the inpainted background, encode it with Stable
Diffusion 2.1's VAE and invert it deterministically (DDIM, CFG 1, depth and Canny
ControlNets, the scene's prompt) from t = 0 up to enhance.diffusion.inversion_total_steps
in strides of inversion_stride. Every intermediate latent is kept in latents.h5, so
that pm-enhance can replay them. Needs local model weights (see enhance.diffusion.models).""")
    parser.add_argument("--scene", required=True, type=Path, help="scene.yaml")
    parser.add_argument("--coarse", required=True, type=Path, help="coarse.h5 from pm-render")
    parser.add_argument("--gaussians", required=True, type=Path, help="gaussians.h5 from pm-reconstruct")
    parser.add_argument("--lora", type=Path, help="LoRA folder from pm-lora")
    parser.add_argument("--out", required=True, type=Path, help="latents.h5 to write")
    return parser


def invert(args: argparse.Namespace) -> None:
    from .pipeline import make_latents  # imports diffusers

    scene = load_scene(args.scene)
    device = resolve_device(args.device)
    refuse_overwriting({"--out": args.out}, {"--scene": scene.file, "--coarse": args.coarse,
                                             "--gaussians": args.gaussians})
    check_writable([args.out])
    digests = check_lineage(scene, gaussians=args.gaussians, coarse=args.coarse)
    coarse = read_artifact(args.coarse, CoarseArtifact)
    gaussians = read_artifact(args.gaussians, GaussiansArtifact)
    latents = make_latents(scene, coarse, gaussians, args.lora, device)
    write_artifact(args.out, latents, created_by="pm-invert", config_hash=config_hash(stage_keys(scene, "invert")),
                   inputs=digests)
    log.info("wrote %s: latents %s", args.out, latents.latents.shape)


def main(argv=None) -> None:
    run_main(invert, build_parser(), argv)


if __name__ == "__main__":
    main()
