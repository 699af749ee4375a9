"""Quality of physmotion's results, printed as tables (recorded in benchmarks/RESULTS.md).

One function per section; run all or one:
    python benchmarks/quality.py [--section reconstruct] [--device cpu]

reconstruct: for every example scene, the default pm-reconstruct settings:
  masked PSNR of the input-view render against the photograph (at the
  optimisation resolution, over the object's pixels) and the runtime; on a
  synthetic capsule of known shape: median relative error of the rendered depth
  against the true depth, IoU of the side-view (azimuth 90 degrees) silhouette
  against the true one, and the hard-depth ablation as floater mass (summed
  opacity of Gaussians farther than 2 % of size_m from the true surface).
"""
from __future__ import annotations

import argparse
import logging
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import splat  # noqa: E402
from schemas import load_scene  # noqa: E402
from stages.reconstruct.metrics import iou, masked_psnr, median_relative_error  # noqa: E402
from stages.reconstruct.optimize import Settings  # noqa: E402
from stages.reconstruct.pipeline import optimize_scene, prepare  # noqa: E402
from stages.reconstruct.synthetic import Capsule, photograph, side_view, write_scene  # noqa: E402
from stages.reconstruct.views import input_view  # noqa: E402


def _render(g, camera: splat.Camera, device: str) -> splat.Render:
    t = lambda a: torch.tensor(a, dtype=torch.float32, device=device)  # noqa: E731
    with torch.no_grad():
        return splat.rasterize(t(g.means), t(g.opacities), t(g.colors), camera, scales=t(g.scales),
                               rotations=t(g.rotations))


def _reconstruct(scene_file: Path, device: str, hard_depth: bool = True):
    scene = load_scene(scene_file)
    started = time.perf_counter()
    prepared = prepare(scene, device)
    gaussians, _ = optimize_scene(scene, prepared, device,
                                  replace(Settings(iterations=scene.reconstruct.iterations), hard_depth=hard_depth))
    seconds = time.perf_counter() - started
    view = input_view(prepared.photo, prepared.labels, prepared.depth_prior, prepared.K,
                      scene.reconstruct.resolution, device)
    render = _render(gaussians, view.camera, device)
    object_pixels = view.target_alpha.cpu().numpy() > 0.5
    psnr = masked_psnr(render.features.cpu().numpy(), view.target_rgb.cpu().numpy(), object_pixels)
    return scene, gaussians, view, render, psnr, seconds


def reconstruction_section(device: str) -> str:
    """The table of section '## reconstruct' of RESULTS.md."""
    rows = ["| scene | Gaussians | masked PSNR (dB) | runtime (s) | depth median rel. error | side IoU "
            "| floater mass | median distance to surface |",
            "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for scene_file in sorted(ROOT.glob("scenes/*/scene.yaml")):
        scene, g, view, _, psnr, seconds = _reconstruct(scene_file, device)
        rows.append(f"| {scene_file.parent.name} ({view.camera.width}x{view.camera.height}, "
                    f"{scene.reconstruct.iterations} it) | {len(g)} | {psnr:.2f} | {seconds:.0f} | | | | |")
    capsule = Capsule.tilted()
    with tempfile.TemporaryDirectory() as tmp:
        scene_file = write_scene(Path(tmp), capsule)
        for hard_depth in (True, False):
            scene, g, view, render, psnr, seconds = _reconstruct(scene_file, device, hard_depth)
            camera = view.camera
            truth = photograph(capsule, camera.K, camera.world_to_camera, camera.width, camera.height)
            alpha = render.alpha.cpu().numpy()
            depth = render.depth.cpu().numpy() / np.maximum(alpha, 1e-6)
            depth_error = median_relative_error(depth, truth.distance, truth.mask & (alpha > 0.5))
            side = splat.Camera(camera.K, side_view(capsule), camera.width, camera.height)
            side_truth = photograph(capsule, side.K, side.world_to_camera, side.width, side.height)
            side_iou = iou(_render(g, side, device).alpha.cpu().numpy() > 0.5, side_truth.mask)
            distance = np.abs(capsule.signed_distance(g.means))
            floaters = g.opacities[distance > 0.02 * capsule.size_m].sum()
            rows.append(f"| capsule, hard depth {'on' if hard_depth else 'off'} ({camera.width}x{camera.height}, "
                        f"{scene.reconstruct.iterations} it) | {len(g)} | {psnr:.2f} | {seconds:.0f} | "
                        f"{100 * depth_error:.2f} % | {side_iou:.3f} | {floaters:.1f} "
                        f"({100 * floaters / g.opacities.sum():.2f} % of all opacity) | "
                        f"{1000 * np.median(distance):.1f} mm |")
    return "\n".join(rows)


SECTIONS = {"reconstruct": reconstruction_section}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--section", choices=sorted(SECTIONS), action="append",
                        help="section(s) to run (default: all)")
    parser.add_argument("--device", default="cpu", help="cpu or cuda")
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(message)s", datefmt="%H:%M:%S")
    if args.device == "cpu":
        torch.set_num_threads(1)  # as pm-reconstruct: splat's threads already use the cores
    for name in args.section or sorted(SECTIONS):
        print(f"## {name}\n\n{SECTIONS[name](args.device)}\n", flush=True)


if __name__ == "__main__":
    main()
