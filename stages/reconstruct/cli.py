"""pm-reconstruct: one photograph -> gaussians.h5 (paper section 3.3)."""
from __future__ import annotations

import argparse
import logging
import os
import time
from pathlib import Path
from typing import Optional

import numpy as np
import torch

from schemas import InputError, config_hash, load_scene, resolve_device, run_main, stage_keys, stage_parser
from schemas.artifacts import GaussiansArtifact, file_digest, write_artifact
from schemas.files import check_writable, refuse_overwriting
from schemas.solid import solid_fields

from .optimize import LOSS_TERMS
from .pipeline import optimize_scene, prepare

log = logging.getLogger("physmotion.reconstruct")

DESCRIPTION = """\
Reconstruct the scene's objects as 3D Gaussians from its one photograph.

Segments each object (mask file, box refined by GrabCut or SAM, image alpha),
inpaints the background, builds a metric depth prior (silhouette inflation, or
a DPT/MiDaS model), lifts a closed surface of Gaussians (or places
reconstruct.init_ply, or with reconstruct.prior lgm places the Gaussians LGM
makes from four ImageDream views) and optimises it through splat on the input view with
the colour and hard-depth losses (reconstruct.iterations at
reconstruct.resolution). Writes gaussians.h5 (DESIGN.md, Artifacts).
"""


def build_parser() -> argparse.ArgumentParser:
    parser = stage_parser("pm-reconstruct", DESCRIPTION)
    parser.add_argument("--scene", required=True, type=Path, help="the scene.yaml (or its folder)")
    parser.add_argument("--out", required=True, type=Path, help="gaussians.h5 to write")
    parser.add_argument("--sam-model", type=Path, default=None,
                        help="folder of a transformers SAM model; refines boxes instead of GrabCut "
                             "(default: reconstruct.sam_model, else $PHYSMOTION_SAM_MODEL)")
    parser.add_argument("--depth-model", type=Path, default=None,
                        help="folder of a transformers DPT/MiDaS model; replaces the inflation prior's front "
                             "(default: reconstruct.depth_model, else $PHYSMOTION_DEPTH_MODEL)")
    parser.add_argument("--lgm-model", type=Path, default=None,
                        help="LGM checkpoint (model_fp16_fixrot.safetensors) or its folder, for reconstruct.prior "
                             "lgm (default: $PHYSMOTION_LGM_MODEL, else the Hugging Face cache of ashawkey/LGM)")
    parser.add_argument("--multiview-model", type=Path, default=None,
                        help="ImageDream folder in diffusers' layout, for reconstruct.prior lgm (default: "
                             "$PHYSMOTION_MULTIVIEW_MODEL, else the Hugging Face cache of "
                             "ashawkey/imagedream-ipmv-diffusers)")
    return parser


def learned_prior(scene, device: str, args: argparse.Namespace):
    """The loaded models of reconstruct.prior lgm, None for the symmetric prior; InputError before any work when
    the weights are missing or the scene also gives an init_ply."""
    if scene.reconstruct.prior != "lgm":
        return None
    if scene.reconstruct.init_ply is not None:
        raise InputError(scene.file, "reconstruct.prior", "prior lgm makes the initial Gaussians, and "
                         "reconstruct.init_ply gives them too", "remove one of reconstruct.init_ply and prior: lgm")
    from .lgm.prior import LearnedPrior

    return LearnedPrior.load(scene.file, device, args.lgm_model, args.multiview_model)


def model_folder(flag: Optional[Path], scene_key: Optional[Path], env: str) -> Optional[Path]:
    """The model folder to use: the command-line flag, else the scene's key, else the environment variable."""
    chosen = flag or scene_key or (Path(os.environ[env]) if os.environ.get(env) else None)
    if chosen is not None:
        log.info("using the model in %s", chosen)
    return chosen


def source_files(scene) -> dict:
    """The files the reconstruction reads besides scene.yaml, by their scene key."""
    files = {"image": scene.image, "reconstruct.init_ply": scene.reconstruct.init_ply}
    files.update({f"objects[{k}].mask": o.mask for k, o in enumerate(scene.objects)})
    files.update({f"reconstruct.extra_views[{i}].image": v.image for i, v in enumerate(scene.reconstruct.extra_views)})
    return {key: path for key, path in files.items() if path is not None}


def check_result(scene, initial: int, kept: int, loss: np.ndarray) -> None:
    """An InputError instead of an artifact when the optimisation diverged or kept no Gaussian."""
    total = loss[:, 0]
    if not np.isfinite(total).all():
        first = int(np.argmin(np.isfinite(total)))
        raise InputError(scene.file, "reconstruct", f"the optimisation diverged: its loss is {total[first]} from "
                         f"iteration {first + 1}", "check objects[].size_m (metres) and camera.fov_deg, or lower "
                         "reconstruct.iterations; nothing was written")
    if kept == 0:
        raise InputError(scene.file, "objects", f"no Gaussian is left of the {initial} lifted (all transparent "
                         "or off the camera)", "check objects[].size_m (metres), camera.fov_deg and the masks or "
                         "boxes; nothing was written")


def reconstruct(args: argparse.Namespace) -> None:
    started = time.perf_counter()
    device = resolve_device(args.device)
    if device == "cpu":
        # splat's kernels already use the cores from their own threads; torch's intra-op pool on top
        # oversubscribes them (SSIM forward+backward measured 1.5 s instead of 0.04 s on 2 busy cores).
        torch.set_num_threads(1)
    scene = load_scene(args.scene)
    sources = source_files(scene)
    refuse_overwriting({"--out": args.out}, {"--scene": scene.file, **sources})
    check_writable([args.out])
    learned = learned_prior(scene, device, args)
    prepared = prepare(scene, device, model_folder(args.sam_model, scene.reconstruct.sam_model, "PHYSMOTION_SAM_MODEL"),
                       model_folder(args.depth_model, scene.reconstruct.depth_model, "PHYSMOTION_DEPTH_MODEL"), learned)
    gaussians, loss = optimize_scene(scene, prepared, device)
    check_result(scene, len(prepared.initial), len(gaussians), loss)
    height, width = prepared.labels.shape
    artifact = GaussiansArtifact(
        K=prepared.K, world_to_camera=np.eye(4), width=width, height=height,
        means=gaussians.means, scales=gaussians.scales, rotations=gaussians.rotations,
        opacities=gaussians.opacities, colors=gaussians.colors, object_id=gaussians.object_id,
        photo=prepared.photo, mask=prepared.labels, background=prepared.background,
        depth_prior=prepared.depth_prior, **solid_fields(prepared.solids), loss=loss, loss_terms=LOSS_TERMS)
    write_artifact(args.out, artifact, created_by="pm-reconstruct",
                   config_hash=config_hash(stage_keys(scene, "reconstruct")),
                   inputs={"files": {key: file_digest(path) for key, path in sources.items()}, "stages": {}})
    log.info("wrote %s: %d Gaussians in %.1f s", args.out, len(gaussians), time.perf_counter() - started)


def main(argv=None) -> None:
    run_main(reconstruct, build_parser(), argv)


if __name__ == "__main__":
    main()
