"""pm-render: gaussians.h5 + trajectories.h5 -> coarse.h5 + coarse.mp4."""
from __future__ import annotations

import argparse
import logging
from pathlib import Path

import torch

from schemas import config_hash, load_scene, resolve_device, run_main, stage_keys, stage_parser
from schemas.artifacts import GaussiansArtifact, TrajectoriesArtifact, check_lineage, read_artifact, write_artifact
from schemas.files import check_writable, refuse_overwriting
from schemas.video import write_video

from .render import render_video

log = logging.getLogger("physmotion.render")

DESCRIPTION = """\
Render every simulated frame through the splat rasterizer from the input camera: every particle
k at x_k(t) with covariance F_k H_k F_k^T, the surface Gaussians as reconstructed and the
interior's fill particles as the body's material (hidden behind the surface at rest, shown
where it opens; grains where the material flows). Writes coarse.h5 (rgb over black, alpha, depth,
source_uv = where each surface was in the photograph at rest, source_coherence = how smoothly
the photograph maps there, source_confidence = how visible that surface was in it, times the
coherence, normal = the surface's normal now) and an H.264 preview of the rgb frames. Width
from the scene's render.width, capped at the photograph's and rounded to even sizes."""


def build_parser() -> argparse.ArgumentParser:
    parser = stage_parser("pm-render", DESCRIPTION)
    parser.add_argument("--scene", required=True, type=Path, help="scene.yaml")
    parser.add_argument("--gaussians", required=True, type=Path, help="gaussians.h5 from pm-reconstruct")
    parser.add_argument("--trajectories", required=True, type=Path, help="trajectories.h5 from pm-simulate")
    parser.add_argument("--out", required=True, type=Path, help="coarse.h5 to write")
    parser.add_argument("--video", required=True, type=Path, help="coarse.mp4 to write")
    return parser


def render(args: argparse.Namespace) -> None:
    scene = load_scene(args.scene)
    device = resolve_device(args.device)
    if device == "cpu":
        # One thread for torch's own ops (splat's kernels use the cores from their own threads). With two,
        # MKL may use fewer at run time (MKL_DYNAMIC): a run under load wrote a coarse.h5 whose normals
        # and source maps differed from the next run's by float rounding (up to 2e-5), not the same bytes.
        torch.set_num_threads(1)
    refuse_overwriting({"--out": args.out, "--video": args.video},
                       {"--scene": scene.file, "--gaussians": args.gaussians, "--trajectories": args.trajectories})
    check_writable([args.out, args.video])
    digests = check_lineage(scene, gaussians=args.gaussians, trajectories=args.trajectories)
    gaussians = read_artifact(args.gaussians, GaussiansArtifact)
    trajectories = read_artifact(args.trajectories, TrajectoriesArtifact)
    coarse = render_video(gaussians, trajectories, scene.render.width, device)
    write_artifact(args.out, coarse, created_by="pm-render", config_hash=config_hash(stage_keys(scene, "render")),
                   inputs=digests)
    write_video(args.video, coarse.rgb, coarse.fps)
    log.info("wrote %s and %s", args.out, args.video)


def main(argv=None) -> None:
    run_main(render, build_parser(), argv)
