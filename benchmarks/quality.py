"""Quality of physmotion's results, printed as tables and written to benchmarks/results/<section>.json
(RESULTS.md is regenerated from them).

One function per section; run all or one:
    python -m benchmarks.quality [--section NAME] [--device cpu] [--results results/]
                                 [--new-results DIR] [--no-figures]

reconstruct: for every example scene, the default pm-reconstruct settings:
  masked PSNR of the input-view render against the photograph (at the
  optimisation resolution, over the object's pixels) and the runtime; on a
  synthetic capsule of known shape: median relative error of the rendered depth
  against the true depth, IoU of the side-view (azimuth 90 degrees) silhouette
  against the true one, and the hard-depth ablation as floater mass (summed
  opacity of Gaussians farther than 2 % of size_m from the true surface).

enhance: the flow backend on the results of `make demo` (see enhancement_section).

unseen, shadows: the examples' reconstructions and those of photographs new to them (NEW_PHOTOGRAPHS,
  pm-reconstruct of benchmarks/scenes/NAME into --new-results/NAME), turned and moved: their unseen
  sides' detail and their shadows (see unseen_section, shadow_section).

granular: the granular examples' heaps against their photographs' colours (see granular_section).
"""
from __future__ import annotations

import argparse
import logging
import shlex
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path
from typing import Iterator

import cv2
import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import splat  # noqa: E402
from benchmarks.figures import add_arguments, write_figures  # noqa: E402
from schemas import load_scene  # noqa: E402
from schemas.artifacts import CoarseArtifact, GaussiansArtifact, TrajectoriesArtifact, read_artifact  # noqa: E402
from schemas.materials import PRESETS  # noqa: E402
from schemas.video import read_video  # noqa: E402
from stages.enhance import flow  # noqa: E402
from stages.enhance.compositing import (blend_over_background, resize_to, standing_still,  # noqa: E402
                                         unpremultiply)
from stages.reconstruct.metrics import iou, masked_psnr, median_relative_error  # noqa: E402
from stages.reconstruct.optimize import Settings  # noqa: E402
from stages.reconstruct.pipeline import optimize_scene, prepare  # noqa: E402
from testing.photographs import Capsule, photograph, side_view, write_scene  # noqa: E402
from stages.reconstruct.views import input_view  # noqa: E402
from stages.render.interior import GRANULAR, lattice_spacing, rest_ray_colours  # noqa: E402
from stages.render.render import render_camera, rendered_particles  # noqa: E402
from stages.render.source_map import to_camera  # noqa: E402


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


RECONSTRUCT_COLUMNS = ["scene", "Gaussians", "masked PSNR (dB)", "runtime (s)", "depth median rel. error", "side IoU",
                       "floater mass", "median distance to surface"]


def reconstruction_section(device: str) -> list[list]:
    """The rows of the reconstruction table (RECONSTRUCT_COLUMNS)."""
    rows = []
    for scene_file in sorted(ROOT.glob("scenes/*/scene.yaml")):
        scene, g, view, _, psnr, seconds = _reconstruct(scene_file, device)
        rows.append([f"{scene_file.parent.name} ({view.camera.width}x{view.camera.height}, "
                     f"{scene.reconstruct.iterations} it)", len(g), f"{psnr:.2f}", f"{seconds:.0f}", "", "", "", ""])
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
            rows.append([f"capsule, hard depth {'on' if hard_depth else 'off'} ({camera.width}x{camera.height}, "
                         f"{scene.reconstruct.iterations} it)", len(g), f"{psnr:.2f}", f"{seconds:.0f}",
                         f"{100 * depth_error:.2f} %", f"{side_iou:.3f}",
                         f"{floaters:.1f} ({100 * floaters / g.opacities.sum():.2f} % of all opacity)",
                         f"{1000 * np.median(distance):.1f} mm"])
    return rows


def _examples(results: Path) -> list[tuple[str, Path]]:
    """(name, the workflow's results folder) of every example scene (scenes/NAME/scene.yaml)."""
    return [(f.parent.name, results / f.parent.name) for f in sorted((ROOT / "scenes").glob("*/scene.yaml"))]


def _each_result(folders: list[tuple[str, Path]], needs: str, columns: list[str],
                 rows: list[list]) -> Iterator[tuple[str, Path]]:
    """Each (name, folder) whose folder holds the file ``needs``; for each other one, a row of ``rows``
    (of ``columns``) says which file is missing."""
    for name, folder in folders:
        if (folder / needs).exists():
            yield name, folder
        else:
            rows.append([name, f"missing: {folder / needs} (run `make demo`, or pm-reconstruct into {folder})",
                         *[""] * (len(columns) - 2)])


def _inside(mask: np.ndarray) -> np.ndarray:
    """The object's pixels without the silhouette's own edge (3 px), whose contrast against the
    background would outweigh the texture."""
    return cv2.erode(mask.astype(np.uint8), np.ones((7, 7), np.uint8)) > 0


def _variance_of_laplacian(rgb: np.ndarray, mask: np.ndarray) -> float:
    """Texture sharpness inside an object (see _inside)."""
    grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY).astype(np.float64)
    return float(cv2.Laplacian(grey, cv2.CV_64F)[_inside(mask)].var())


def _area_scale(uv: np.ndarray, mask: np.ndarray) -> float:
    """Median inside the object (see _inside) of det(d uv / d pixel) of a source map uv (h, w, 2)."""
    du, dv = np.gradient(uv, axis=1), np.gradient(uv, axis=0)
    det = du[..., 0] * dv[..., 1] - du[..., 1] * dv[..., 0]
    return float(np.median(det[_inside(mask) & np.isfinite(det)]))


def _objects_reader(gaussians: GaussiansArtifact, width: int, height: int):
    """The flow backend's lookup of the objects' colours in the photograph at (width, height)
    (flow.objects_reader): image points (h, w, 2) -> (h, w, 3) float32 sRGB."""
    photo = resize_to(gaussians.photo, width, height)
    return flow.objects_reader(photo, resize_to((gaussians.mask > 0).astype(np.float32), width, height) > 0.5)


def _shifted(read, width: int, height: int, offset_px: float) -> np.ndarray:
    """The photograph (width x height) moved by ``offset_px`` along x and y by the flow backend's lookup ``read``."""
    rows, cols = np.indices((height, width), dtype=np.float32)
    uv = np.stack([cols, rows], -1) + 0.5 - offset_px
    return (read(uv) + 0.5).astype(np.uint8)


def _psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2)
    return float(10 * np.log10(255.0 ** 2 / max(mse, 1e-12)))


ENHANCE_COLUMNS = ["scene", "frames", "frame-0 PSNR enhanced dB", "decoded video dB", "coarse dB",
                   "sharpness ratio min / mean / max (1st s)", "last 1/2 s", "moved photograph's",
                   "photograph shifted 1/4, 1/2 px", "area scale", "flicker (/255)"]


def enhancement_section(results: Path) -> list[list]:
    """Flow enhancement on each example scene's workflow results (run `make demo` first).

    frame-0 PSNR against the photograph at the output size, whole frame: of the enhancer's
    frame (recomputed from coarse.h5 and gaussians.h5, before encoding), of the decoded
    video.mp4 (H.264 yuv420p halves the chroma resolution) and of the coarse render blended
    over the inpainted background; sharpness: variance of the Laplacian of the enhanced frames
    inside the object (rendered alpha > 0.5, eroded by 3 px) over the first second, as a ratio
    to the photograph's inside its mask (likewise eroded; min / mean over frames), and its mean over the
    last half second (where sand has come to rest as a heap); beside it the
    same ratio for the moved photograph, the photograph read at source_uv over the whole object
    with no render fallback: the Laplacian's variance grows as 1/s^4 when a surface's image
    shrinks by s (foreshortened, compressed), so a moving object's own detail is not the
    photograph's; and for scale, the ratio of the photograph itself shifted by a quarter and by half
    a pixel along x and y by the backend's lookup (sub-pixel resampling can soften the finest
    detail, which this measure weighs most); the range over the first second of the source map's
    median area scale inside the object (photograph pixels per frame pixel: above 1 the surface's
    image shrank, which raises the measure by about its square); flicker: mean absolute change between
    consecutive decoded frames of the pixels no frame's object ever covers.
    """
    rows = []
    for name, folder in _each_result(_examples(results), "video.mp4", ENHANCE_COLUMNS, rows):
        scene = load_scene(ROOT / "scenes" / name / "scene.yaml")
        gaussians = read_artifact(folder / "gaussians.h5", GaussiansArtifact)
        coarse = read_artifact(folder / "coarse.h5", CoarseArtifact)
        enhanced = flow.enhance_frames(coarse, gaussians, scene.enhance.confidence_threshold,
                                       scene.enhance.hidden_surfaces, scene.enhance.relight,
                                       ground=scene.physics.ground.enabled)
        video, fps, _ = read_video(folder / "video.mp4")
        h, w = coarse.height, coarse.width
        photo = resize_to(gaussians.photo, w, h)
        background = resize_to(gaussians.background, w, h)
        coarse_blend = blend_over_background(unpremultiply(coarse.rgb[0], coarse.alpha[0]), coarse.alpha[0], background)
        photo_mask = resize_to((gaussians.mask > 0).astype(np.uint8), w, h) > 0
        photo_sharpness = _variance_of_laplacian(photo, photo_mask)
        first_second = [t for t in range(min(len(enhanced), int(round(fps)) + 1)) if (coarse.alpha[t] > 0.5).sum() > 100]
        ratios = [_variance_of_laplacian(enhanced[t], coarse.alpha[t] > 0.5) / photo_sharpness for t in first_second]
        last_half = [t for t in first_second if t >= len(enhanced) - 1 - fps / 2]
        settled = np.mean([ratios[first_second.index(t)] for t in last_half]) if last_half else float("nan")
        # The moved photograph: the object read from the photograph at source_uv everywhere, no render fallback
        read = _objects_reader(gaussians, w, h)
        moved, area = [], []
        for t in first_second:
            uv = flow.smooth_source(coarse.source_uv[t] * w / gaussians.width)
            frame = blend_over_background(read(uv), coarse.alpha[t], background)
            moved.append(_variance_of_laplacian(frame, coarse.alpha[t] > 0.5) / photo_sharpness)
            area.append(_area_scale(uv, coarse.alpha[t] > 0.5))
        never_covered = (coarse.alpha < 1.0 / 255).all(axis=0)
        flicker = np.abs(np.diff(video.astype(np.int16), axis=0))[:, never_covered].mean()
        shifted = ", ".join(f"{_variance_of_laplacian(_shifted(read, w, h, d), photo_mask) / photo_sharpness:.2f}"
                            for d in (0.25, 0.5))
        rows.append([name, len(video), f"{_psnr(enhanced[0], photo):.1f}", f"{_psnr(video[0], photo):.1f}",
                     f"{_psnr(coarse_blend, photo):.1f}",
                     f"{min(ratios):.2f} / {np.mean(ratios):.2f} / {max(ratios):.2f}", f"{settled:.2f}",
                     f"{min(moved):.2f} / {np.mean(moved):.2f} / {max(moved):.2f}", shifted,
                     f"{min(area):.2f}-{max(area):.2f}", f"{flicker:.2f}"])
    return rows


def _two_colours(rgb: np.ndarray, alpha: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The object's two main colours in a frame: k-means (k = 2, seeded) of the chromaticity (colour over
    its sum: a grain's shade does not count) of its pixels (alpha > 0.5): (2, 3) centres and the share
    of the pixels nearer each."""
    chroma = _chromaticity(rgb, alpha)
    cv2.setRNGSeed(0)
    _, labels, centres = cv2.kmeans(chroma.astype(np.float32), 2, None,
                                    (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4), 5,
                                    cv2.KMEANS_PP_CENTERS)
    return centres.astype(np.float64), np.bincount(labels.ravel(), minlength=2) / len(labels)


def _chromaticity(rgb: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """(n, 3) colour over its sum of the n pixels of alpha > 0.5 (plus one grey level: black is grey)."""
    colour = rgb[alpha > 0.5].astype(np.float64) + 1.0
    return colour / colour.sum(1, keepdims=True)


GRANULAR_COLUMNS = ["scene", "colour shares at frame 0", "in the last frame", "of the particles in front",
                    "largest share change %", "against the particles in front %", "particle px (spacing)",
                    "sharpness ratio last 1/2 s", "enhanced over coarse"]
NEW_GRANULAR = ("wheel", "shuttle_sand")
"""Photographs new to the examples (benchmarks/scenes) made of sand, whose workflow results (NAME/gaussians.h5,
trajectories.h5 and coarse.h5 under --new-results) the granular section measures beside the examples':
scikit-image's colour wheel, and the astronaut's model shuttle (white orbiter, brown tank)."""


def _shares_in_front(gaussians: GaussiansArtifact, trajectories: TrajectoriesArtifact, width: int,
                     centres: np.ndarray) -> np.ndarray:
    """(2,) of the last frame's solid pixels (alpha > 0.5), the share in front of which lie particles whose
    colour in the photograph (interior.rest_ray_colours, the colour a grain takes) is nearer in chromaticity
    to each of ``centres`` (2, 3): pm-render's own particles, shapes and depth order, each drawn in its
    class (one channel a class) instead of its colour. Where the heap's visible sand came from, which the
    material's motion decides, whatever colours the render draws."""
    camera = render_camera(gaussians, width)
    particles = rendered_particles(gaussians, trajectories, camera, "cpu")
    colours = rest_ray_colours(trajectories.rest_positions.astype(np.float64), trajectories.object_id,
                               gaussians.photo, gaussians.mask, gaussians.K, gaussians.world_to_camera)
    chroma = (255 * colours + 1) / (255 * colours + 1).sum(1, keepdims=True)  # as _chromaticity
    nearest = np.argmin(((chroma[:, None] - centres[None]) ** 2).sum(-1), 1)
    with torch.no_grad():
        for F, positions in zip(trajectories.F, trajectories.positions):  # Mixing keeps its past
            means, covariances, opacities, _, _ = particles.at(torch.as_tensor(F), torch.as_tensor(positions))
        classes = torch.as_tensor(np.eye(2)[nearest], dtype=means.dtype)
        render = splat.rasterize(means, opacities, classes, camera, covariances=covariances)
    solid = render.alpha > 0.5
    return (render.features[solid].sum(0) / render.alpha[solid].sum().clamp_min(1e-12)).double().numpy()


def granular_section(args) -> list[list]:
    """Each granular example's (sand, snow) heap, and those of the new photographs (NEW_GRANULAR), against
    its photograph, from the workflow's results.

    The object's two main colours at frame 0 (_two_colours of the coarse render); the share of the
    heap's pixels nearer each in the last frame, the share of the pixels in front of which lie particles of
    each colour (_shares_in_front: where the heap's surface came from), and the largest relative change of
    the last frame's share from frame 0's and from the particles'; the lattice spacing in pixels at the
    object's distance (a particle's size, within which the render draws the material's grains); the sharpness
    ratio over the last half second as
    in the enhance section (the enhanced frames' variance of the Laplacian inside the object over the
    photograph's), and the enhanced frames' over the coarse render's (what the flow backend keeps of the
    grains the render draws)."""
    rows = []
    granular_examples = [(name, folder) for name, folder in _examples(args.results)
                         if any(o.material.preset in GRANULAR for o in load_scene(ROOT / "scenes" / name
                                                                                  / "scene.yaml").objects)]
    new = [(name, args.new_results / name) for name in NEW_GRANULAR]
    for name, folder in _each_result(granular_examples + new, "coarse.h5", GRANULAR_COLUMNS, rows):
        scene = load_scene(ROOT / ("benchmarks/scenes" if name in NEW_GRANULAR else "scenes") / name / "scene.yaml")
        gaussians = read_artifact(folder / "gaussians.h5", GaussiansArtifact)
        trajectories = read_artifact(folder / "trajectories.h5", TrajectoriesArtifact)
        coarse = read_artifact(folder / "coarse.h5", CoarseArtifact)
        centres, at_rest = _two_colours(coarse.rgb[0], coarse.alpha[0])
        chroma = _chromaticity(coarse.rgb[-1], coarse.alpha[-1])
        nearest = np.argmin(((chroma[:, None] - centres[None]) ** 2).sum(-1), 1)
        last = np.bincount(nearest, minlength=2) / max(len(nearest), 1)
        in_front = _shares_in_front(gaussians, trajectories, coarse.width, centres)
        granular = np.isin(trajectories.material_id, [PRESETS.index(p) for p in GRANULAR])
        spacing = lattice_spacing(trajectories.lattice_spacing, trajectories.is_gaussian, trajectories.object_id)
        depth = to_camera(trajectories.rest_positions.astype(np.float64), gaussians.world_to_camera)[:, 2]
        spacing_px = float(np.median((spacing * coarse.K[0, 0] / depth)[granular & np.isfinite(spacing)]))
        enhanced = flow.enhance_frames(coarse, gaussians, scene.enhance.confidence_threshold,
                                       scene.enhance.hidden_surfaces, scene.enhance.relight)
        photo = resize_to(gaussians.photo, coarse.width, coarse.height)
        background = resize_to(gaussians.background, coarse.width, coarse.height)
        photo_mask = resize_to((gaussians.mask > 0).astype(np.uint8), coarse.width, coarse.height) > 0
        last_half = range(len(enhanced) - 1 - int(coarse.fps / 2), len(enhanced))
        sharpness = np.mean([_variance_of_laplacian(enhanced[t], coarse.alpha[t] > 0.5) for t in last_half])
        drawn = np.mean([_variance_of_laplacian(
            blend_over_background(unpremultiply(coarse.rgb[t], coarse.alpha[t]), coarse.alpha[t], background),
            coarse.alpha[t] > 0.5) for t in last_half])
        shares = lambda values: " / ".join(f"{100 * v:.0f} %" for v in values)  # noqa: E731
        change = lambda reference: f"{100 * (np.abs(last - reference) / reference).max():.0f}"  # noqa: E731
        rows.append([name, shares(at_rest), shares(last), shares(in_front), change(at_rest), change(in_front),
                     f"{spacing_px:.1f}", f"{sharpness / _variance_of_laplacian(photo, photo_mask):.2f}",
                     f"{sharpness / drawn:.2f}"])
    return rows


NEW_PHOTOGRAPHS = ("cat", "motorcycle")
"""Photographs new to the examples (benchmarks/scenes) whose reconstructions (NAME/gaussians.h5 under
--new-results) the hidden-surface and shadow sections turn and move beside the examples': chelsea's head
before a dark room, and a motorcycle casting its own shadow on a garage floor."""
TURNS_DEG = (0, 45, 90, 135, 180)


def _moved(gaussians: GaussiansArtifact, turns_deg=(0,), shift_m=(0.0, 0.0, 0.0)) -> TrajectoriesArtifact:
    """The reconstruction's Gaussians alone, frame t turned by turns_deg[t] about the vertical through
    their centre (world frame: y along gravity) and moved by shift_m (3,) from frame 1 on."""
    G, T = len(gaussians.means), len(turns_deg)
    centre = gaussians.means.mean(0)
    angles = np.radians(turns_deg)
    turns = np.array([[[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]] for a in angles])
    positions = np.einsum("tij,gj->tgi", turns, gaussians.means - centre) + centre
    positions[1:] += np.asarray(shift_m)
    zeros = np.zeros(T)
    return TrajectoriesArtifact(
        rest_positions=gaussians.means, volumes=np.ones(G), masses=np.ones(G), material_id=np.zeros(G),
        object_id=gaussians.object_id, is_gaussian=np.ones(G, bool), positions=positions,
        F=np.broadcast_to(turns[:, None], (T, G, 3, 3)), time_s=np.arange(T) / 8.0, substeps=zeros,
        kinetic_energy=zeros, potential_energy=zeros, momentum=np.zeros((T, 3)), angular_momentum=np.zeros((T, 3)),
        max_speed=zeros, lattice_spacing=0.01, fps=8.0, duration_s=(T - 1) / 8)


def _high_frequency(rgb: np.ndarray, pixels: np.ndarray) -> float:
    """Mean square of the luma's detail finer than a Gaussian of 1 px over ``pixels`` (h, w bool)."""
    grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY).astype(np.float64)
    return float(((grey - cv2.GaussianBlur(grey, (0, 0), 1.0)) ** 2)[pixels].mean())


UNSEEN_COLUMNS = ["scene", "turn (deg)", "unseen share of the object", "HF unseen / seen, read through the body",
                  "HF unseen / seen, flow backend"]


def _reconstructions(args) -> list[tuple[str, Path]]:
    """(name, folder) of the examples' results and of the new photographs' (NEW_PHOTOGRAPHS)."""
    return _examples(args.results) + [(name, args.new_results / name) for name in NEW_PHOTOGRAPHS]


def unseen_section(args) -> list[list]:
    """Each reconstruction turned about the vertical (TURNS_DEG) through pm-render: the high-frequency
    energy (_high_frequency) of the object's unseen pixels (seen fraction < 0.5, inside alpha > 0.5
    eroded by 3 px) over that of the photograph inside its object (the seen side, as photographed):
    of the photograph read at the source points (the read through the body), and of the flow backend
    (unseen.py)."""
    from stages.render.render import render_video

    rows = []
    for name, folder in _each_result(_reconstructions(args), "gaussians.h5", UNSEEN_COLUMNS, rows):
        gaussians = read_artifact(folder / "gaussians.h5", GaussiansArtifact)
        coarse = render_video(gaussians, _moved(gaussians, TURNS_DEG), width=320, device="cpu")
        after = flow.enhance_frames(coarse, gaussians, 0.5)
        h, w = coarse.height, coarse.width
        photo = resize_to(gaussians.photo, w, h)
        read = _objects_reader(gaussians, w, h)
        photographed = _high_frequency(photo, _inside(resize_to((gaussians.mask > 0).astype(np.uint8), w, h) > 0))
        for t, turn in enumerate(TURNS_DEG):
            if turn == 0:
                continue
            seen = flow.seen_fraction(coarse.source_confidence[t], coarse.source_coherence[t])
            unseen = _inside(coarse.alpha[t] > 0.5) & (seen < 0.5)
            share = unseen.sum() / max(_inside(coarse.alpha[t] > 0.5).sum(), 1)
            if unseen.sum() < 100:
                rows.append([name, turn, f"{100 * share:.0f} %", "", ""])
                continue
            uv = flow.smooth_source(coarse.source_uv[t] * w / gaussians.width)
            before = (read(uv) + 0.5).astype(np.uint8)
            rows.append([name, turn, f"{100 * share:.0f} %", f"{_high_frequency(before, unseen) / photographed:.2f}",
                         f"{_high_frequency(after[t], unseen) / photographed:.2f}"])
    return rows


SHADOW_COLUMNS = ["scene", "photograph's shadow, deepest", "light towards (camera frame)", "blur px",
                  "cast shadow drawn, deepest", "left at the old place"]


def shadow_section(args) -> list[list]:
    """Each reconstruction moved sideways by its own width (pm-render of its Gaussians alone, frame 1),
    its background inpainted anew from the photograph (reconstruct/background.py as it is now): the
    photograph's shadow (1 - photograph / shadow-free background, beside the object), the light and
    blur fitted to it (shadow.py), the darkening drawn under the moved object, and what is left of the
    photograph's shadow where the object stood (mean darkening of frame 1 over the photograph's, where
    that is over 15 % and the moved object is not)."""
    from stages.enhance.relight import Relighting
    from stages.enhance.shadow import Shadows
    from stages.enhance.unseen import MirrorPlanes
    from stages.reconstruct.background import inpaint_background
    from stages.render.render import render_video

    rows = []
    for name, folder in _each_result(_reconstructions(args), "gaussians.h5", SHADOW_COLUMNS, rows):
        gaussians = read_artifact(folder / "gaussians.h5", GaussiansArtifact)
        gaussians = gaussians.model_copy(update={"background": inpaint_background(gaussians.photo, gaussians.mask)})
        R = gaussians.world_to_camera[:3, :3]
        width = np.ptp(gaussians.means @ R[0])  # along the camera's x, in the world
        coarse = render_video(gaussians, _moved(gaussians, (0, 0), R[0] * width), width=320, device="cpu")
        relighting = Relighting.fit(coarse, resize_to(gaussians.photo, coarse.width, coarse.height))
        shadows = Shadows.fit(coarse, gaussians, relighting.shading.light if relighting is not None else None,
                              MirrorPlanes.of(gaussians))
        darkening = shadows(1, standing_still(coarse.source_uv[1] * coarse.width / gaussians.width))
        free = cv2.dilate((coarse.alpha[1] > 0.01).astype(np.uint8), np.ones((5, 5), np.uint8)) == 0
        old = free & (shadows.photographed > 0.15)
        left = f"{100 * darkening[old].mean() / shadows.photographed[old].mean():.0f} %" if old.sum() > 20 else "no shadow"
        rows.append([name, f"{100 * shadows.photographed.max():.0f} %", "({:.2f}, {:.2f}, {:.2f})".format(*shadows.light),
                     f"{shadows.softness_px:.1f}", f"{100 * darkening[free].max():.0f} %", left])
    return rows


SECTIONS = {
    "reconstruct": (lambda args: reconstruction_section(args.device), RECONSTRUCT_COLUMNS, "Reconstruction quality",
                    """pm-reconstruct with each example scene's default settings (600 iterations at 256 px on the
                    longest side, the inflation depth prior, hard depth on, at most 30000 initial Gaussians): the
                    masked PSNR of the input-view render against the photograph's foreground (premultiplied by the
                    mask's coverage, at the optimisation resolution, over the object's pixels) and the runtime from
                    segmentation to the optimised Gaussians, file not written. On a synthetic capsule (0.25 m long,
                    0.05 m radius, tilted 20 degrees in the image plane, 0.6 m away, ray-cast by
                    testing/photographs.py), with hard depth on and off: the median relative error of the
                    rendered depth (depth / alpha where alpha > 0.5) against the ray-cast distance, the IoU of the
                    side view's silhouette (alpha > 0.5 from azimuth 90 degrees) against the true one, the floater
                    mass (summed opacity of Gaussians farther than 2 % of size_m from the true surface) and the
                    median distance of the means to the surface.""",
                    ["Targets: masked PSNR 30 dB; runtime under 5 minutes for a 256-pixel image; depth error 5 % "
                     "and side IoU 0.8 on the capsule."]),
    "granular": (granular_section, GRANULAR_COLUMNS,
                 "Granular material keeps its colours",
                 """The granular examples (sand, snow), the colour wheel and the astronaut's model shuttle as sand
                 (benchmarks/scenes/wheel, shuttle_sand: new to the examples) from the workflow's results: the object's two main colours at frame 0 (k-means of the
                 coarse render's chromaticity, colour over its sum, over the pixels of alpha > 0.5), the share of
                 the heap's pixels nearer each in the last frame; the share of the pixels in front of which lie
                 particles of each photographed colour (pm-render's own particles, shapes and depth order, each
                 drawn in its class: where the heap's visible sand came from), and the largest relative change of
                 the last frame's share from frame 0's and from the particles'; the lattice spacing in pixels at
                 the object's distance (a particle's size; pm-render draws 0.5 mm grains within it, decision 0043); the
                 sharpness ratio over the last
                 half second as in the enhance section, and the enhanced frames' over the coarse render's.""",
                 ["Targets (issue 31): each share within 40 % of its share at frame 0; sharpness ratio at least "
                  "0.6.",
                  "Why the logo's heap filled the picture (decision 0037): a disc's silhouette makes a ball (a "
                  "standing body of revolution, or the medial balls), so the flat logo was a ball of sand, 0.30 x "
                  "0.30 x 0.30 m, 0.0141 m^3. It spread to 0.64 x 0.12 x 0.64 m, evenly about its centre (camera "
                  "z 0.31-0.95 m about 0.63 m): its front came to 0.31 m from the camera, where a grain of the "
                  "lattice spacing (9.5 mm) is 15 px, not 8. Before, as a ball, rendered by the same code: shares "
                  "41 % / 59 % -> 70 % / 30 % (change 70 %), sharpness ratio 0.39. After, with "
                  "objects[0].thickness_m: 0.03 (the 3 cm disc it shows, 0.0022 m^3): it heaps 0.50 x 0.06 x "
                  "0.20 m, no particle past the picture's sides (the row above).",
                  "The wheel keeps its scene (a ball, 0.27 m deep, whose heap reaches the camera's plane: the row "
                  "above). A copy of its scene with thickness_m: 0.03 heaps 0.71 x 0.06 x 0.50 m, 18 % of its "
                  "particles past the picture's sides: shares 71 % / 29 % -> 68 % / 32 % (change 10 %), "
                  "sharpness ratio 329. The shuttle, 0.09 m deep, heaps within the picture.",
                  "The shares follow the sand, not the render: each heap shows the colours of its particles in "
                  "front within 2 (logo) and 4 (shuttle) points. The wheel's near-black pixels have no stable "
                  "chromaticity (its box holds the photograph's black corners).",
                  "The sharpness ratio against the photograph measures the photograph: 77 % of the logo "
                  "photograph's Laplacian variance lies in 5 % of its pixels (ink lines, the white band), and the "
                  "wheel's photograph is a smooth gradient. The flow backend keeps the grains pm-render draws "
                  "(enhanced over coarse).",
                  "Each scene (scenes/logo; benchmarks/scenes/wheel, shuttle_sand) run by pm-reconstruct, "
                  "pm-simulate, pm-render and pm-enhance into --results and --new-results: the logo by `make "
                  "demo` on a clean clone of fe99407; the wheel and the shuttle reconstructed at 4298842 (a scene "
                  "without thickness_m reconstructs as before), simulated, rendered and enhanced at 2291a3c. "
                  "Before decision 0043 (grains a lattice spacing across, demo of 776b31b): changes logo 30 %, "
                  "wheel 8 %, shuttle 22 %; sharpness ratios logo 1.92, wheel 400, shuttle 20.4.",
                  "On tests/render_enhance/test_render_granular.py's log seen end-on (front half orange half "
                  "green, its unseen side green): orange 50 % at frame 0, 15 % of the heap with the colour of "
                  "the nearest surface Gaussian (before decision 0023), 49 % with the rest-ray colour."]),
    "enhance": (lambda args: enhancement_section(args.results), ENHANCE_COLUMNS, "Flow enhancement",
                """The flow backend on the example scenes' workflow results (1 s of video at 24 fps, at each
                scene's render width). Frame-0 PSNR against the photograph, whole frame at the output size: of
                the enhancer's frame before encoding, of the decoded video.mp4 and of the coarse render blended
                over the inpainted background. Sharpness: the variance of the Laplacian inside the object
                (rendered alpha > 0.5, its 3 px silhouette left out) as a ratio to the photograph's, min / mean /
                max over the first second and its mean over the last half second; beside it the same ratio for
                the moved photograph (the photograph read at source_uv over the whole object, no render
                fallback: the most detail the backend can keep), and for scale the photograph itself shifted by a
                quarter and by half a pixel by the backend's lookup. Area scale: the range of the source map's
                median photograph pixels per frame pixel (a surface whose image shrinks by s raises the measure
                by about 1/s^4). Flicker: the mean absolute change between consecutive decoded frames of the
                pixels no frame's object ever covers.""",
                ["Targets: frame-0 PSNR 35 dB, sharpness within 20 % of the photograph's, flicker at most "
                 "0.5/255."]),
    "unseen": (unseen_section, UNSEEN_COLUMNS, "Unseen surfaces",
               """Reconstructions turned about the vertical through pm-render (their Gaussians alone, at 320 px):
               the high-frequency energy (luma minus its Gaussian blur of 1 px, squared) of the pixels whose
               surface the photograph did not see (seen fraction under one half, inside the object less its 3 px
               silhouette), over that of the photograph inside its object. Read through the body: the photograph
               read at the source points (docs/decisions/0004-hidden-surfaces.md); flow backend: the mirrored
               front read as albedo and continued where the photograph recorded the surface poorly
               (docs/decisions/0024-unseen-surfaces.md, 0036-what-the-continuation-reads.md). The examples, and
               two photographs new to them (benchmarks/scenes: scikit-image's chelsea, the cat, and its
               motorcycle), reconstructed with their scenes' settings.""",
               ["Target: at most 1.5 (issue 31). The test ball coloured by height and spun "
                "(tests/render_enhance/test_enhance_unseen.py) is at least 30.8 dB PSNR-Y from its photograph "
                "past 30 degrees.",
                "The clay's photograph has almost no fine detail (its high-frequency energy is 1.2 grey levels "
                "squared), so any on its unseen side weighs heavily. The objects' colours are read, from 2 px "
                "inside their mask on, from a copy of the photograph whose background is the objects' colours "
                "continued (flow.objects_reader; both columns read it): from the photograph's own band-limited "
                "copy the step at the silhouette rang across the whole column (flow backend at 180 degrees 8.9 "
                "before, 2.6 after; the read through the body, which reads the limb, 29 before, 20 after; the "
                "ball, cat and logo change by at most 0.01). What is left at 45-135 degrees is the render, "
                "shown as drawn through holes in source_coherence along the seam (1-2 % of the unseen pixels, "
                "70-78 % of their high-frequency energy), where the closure's limb Gaussians hold a mix of the "
                "clay and the wall: a row of small pegs along the seam.",
                "Where the render shows what the source map does not carry (torn faces, grains, the interior), "
                "it is shown as drawn: neither re-lit nor replaced by the continued colour "
                "(tests/render_enhance/test_render_interior.py, test_render_granular.py)."]),
    "shadows": (shadow_section, SHADOW_COLUMNS, "Shadows",
                """Reconstructions moved sideways by their own width (pm-render of their Gaussians alone, at 320 px),
                their backgrounds inpainted anew from the photograph: the photograph's shadow (the photograph over
                the background with the shadow divided out, reconstruct/background.py), the light and blur fitted
                to it (enhance/shadow.py), the darkening drawn under the moved object, and how much of the
                photograph's shadow is left where the object stood (mean darkening of the moved frame over the
                photograph's, where that is over 15 % and the moved object is not). The examples, and two
                photographs new to them (benchmarks/scenes): the cat before a dark room, which casts no shadow,
                and the motorcycle, which casts its own on the garage floor.""",
                ["On a ray-traced floor (tests/render_enhance/test_enhance_shadow.py): 99 % of the old shadow "
                 "removed, 85 % of the ray-traced darkening drawn under the moved ball."]),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--section", choices=sorted(SECTIONS), action="append",
                        help="section(s) to run (default: all)")
    parser.add_argument("--device", default="cpu", help="cpu or cuda")
    parser.add_argument("--results", type=Path, default=ROOT / "results",
                        help="the workflow's results folder, for the enhance section (default: results/)")
    parser.add_argument("--new-results", type=Path, default=ROOT / "results",
                        help="a folder holding NAME/gaussians.h5 of each of NEW_PHOTOGRAPHS (pm-reconstruct of "
                             "benchmarks/scenes/NAME), for the unseen and shadows sections (default: results/)")
    add_arguments(parser)
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(message)s", datefmt="%H:%M:%S")
    if args.device == "cpu":
        torch.set_num_threads(1)  # as pm-reconstruct: splat's threads already use the cores
    for name in args.section or sorted(SECTIONS):
        measure, columns, title, description, notes = SECTIONS[name]
        rows = measure(args)
        table = ["| " + " | ".join(columns) + " |", "| " + " | ".join("---" for _ in columns) + " |",
                 *("| " + " | ".join(str(c) for c in row) + " |" for row in rows)]
        print(f"## {name}\n\n" + "\n".join(table) + "\n", flush=True)
        if not args.no_figures:
            command = shlex.join(["python", "-m", "benchmarks.quality", "--section", name,
                                  *(["--device", args.device] if args.device != "cpu" else []),
                                  *(["--results", str(args.results)] if args.results != ROOT / "results" else []),
                                  *(["--new-results", str(args.new_results)] if name in ("unseen", "shadows", "granular") else [])])
            write_figures(name, title, description, command, columns, rows, notes=notes, device=args.device)


if __name__ == "__main__":
    main()
