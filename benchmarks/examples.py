"""Speed of pm-simulate on the examples: seconds of simulation per second of video.

    .venv/bin/python benchmarks/examples.py [--scenes ball coffee] [--results results] [--device cpu]
                                            [--ball] [--presets jelly metal ...] [--duration S] [--no-figures]

Each example (every folder of scenes/, or those named) is simulated at its own settings from its
gaussians.h5: results/<name>/gaussians.h5 where `make demo` left one, else pm-reconstruct writes one into
a cache folder (--cache) first, not timed. `--ball` simulates instead a 23 cm ball ray-cast
(testing/photographs.py) and reconstructed from a 256 x 192 photograph, at rest at the default physics
settings, once per preset (--presets). Printed per run: particles, grid, the settle's and the run's
substeps, seconds to build (the fill), settle and run, and the whole over the video's duration, seconds
per video second. Substep counts do not depend on the machine's load; seconds do (the load average is
printed beside them). The rows go to benchmarks/results/examples.json (merged by example and preset), and
RESULTS.md is regenerated.
"""
from __future__ import annotations

import argparse
import logging
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository, before benchmarks/splat.py

from benchmarks.figures import add_arguments, invocation, write_figures  # noqa: E402
from benchmarks.rest import PRESET_MODELS  # noqa: E402
from schemas import load_scene  # noqa: E402
from schemas.artifacts import GaussiansArtifact, read_artifact, read_header  # noqa: E402
from schemas.scene import PhysicsConfig  # noqa: E402
from stages.reconstruct.cli import main as reconstruct  # noqa: E402
from stages.simulate.simulation import Simulation  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
BALL_SIZE = 0.23  # m
COLUMNS = ["example", "material", "particles", "grid", "settle substeps", "run substeps", "build s", "settle s",
           "run s", "s per video second", "load"]


def gaussians_of(scene_file: Path, results: Path, cache: Path) -> Path:
    """gaussians.h5 of a scene: the workflow's results/<name>/ one, else reconstructed into cache/<name>/
    (again where the cached one is of another schema version)."""
    name = scene_file.parent.name
    for path in (results / name / "gaussians.h5", cache / name / "gaussians.h5"):
        if path.exists() and read_header(path).get("schema_version") == GaussiansArtifact.VERSION:
            return path
    path = cache / name / "gaussians.h5"
    path.parent.mkdir(parents=True, exist_ok=True)
    print(f"reconstructing {name} into {path} (not timed)", file=sys.stderr, flush=True)
    reconstruct(["--scene", str(scene_file), "--out", str(path), "--device", "cpu"])
    return path


def ball_scene(cache: Path) -> Path:
    """scene.yaml of the 23 cm ball 1.2 m away on the optical axis, level camera."""
    from testing.photographs import Capsule, write_scene  # noqa: PLC0415 (test helper, only for --ball)

    folder = cache / "ball23"
    if not (folder / "scene.yaml").exists():
        shape = Capsule(np.array([0.0, 0.0, 1.2]), np.array([1e-6, 0.0, 0.0]), BALL_SIZE / 2)
        write_scene(folder, shape, width=256, height=192, iterations=300)
    return folder / "scene.yaml"


def simulate(physics, materials, gaussians, pitch_deg: float, scene_file, device: str) -> tuple[list, Simulation]:
    """The row's measured cells (particles .. s per video second) of one simulation, and the Simulation."""
    start = time.perf_counter()
    sim = Simulation(physics, materials, gaussians.means, gaussians.object_id, pitch_deg=pitch_deg,
                     silhouette=(gaussians.mask, gaussians.K), solids=gaussians.solids(),
                     scene_file=scene_file, device=device)
    built = time.perf_counter()
    tr = sim.run()
    done = time.perf_counter()
    settle_s = sim.settled.wall_s
    run_s = done - built - settle_s
    total = done - start
    return [len(sim.masses), "x".join(map(str, sim.grid.shape)), sim.settled.substeps, int(tr.substeps.sum()),
            f"{built - start:.1f}", f"{settle_s:.1f}", f"{run_s:.1f}", f"{total / physics.duration_s:.1f}",
            f"{os.getloadavg()[0]:.1f}"], sim


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", nargs="*", default=None, help="example names under --scenes-dir (default: all)")
    parser.add_argument("--scenes-dir", type=Path, default=ROOT / "scenes")
    parser.add_argument("--results", type=Path, default=ROOT / "results", help="where `make demo` wrote gaussians.h5")
    parser.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "physmotion-examples")
    parser.add_argument("--ball", action="store_true", help="the 23 cm ball at rest, once per preset")
    parser.add_argument("--presets", nargs="+", default=list(PRESET_MODELS), choices=list(PRESET_MODELS))
    parser.add_argument("--duration", type=float, default=None, help="seconds of video (default: the scene's)")
    parser.add_argument("--device", default="cpu")
    add_arguments(parser)
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    print("| " + " | ".join(COLUMNS) + " |")
    print("|" + " --- |" * len(COLUMNS))
    rows = []
    if args.ball:
        scene_file = ball_scene(args.cache)
        gaussians = read_artifact(gaussians_of(scene_file, args.cache, args.cache), GaussiansArtifact)
        physics = PhysicsConfig(**({"duration_s": args.duration} if args.duration else {}))
        for preset in args.presets:
            cells, _ = simulate(physics, [PRESET_MODELS[preset]()], gaussians, 0.0, scene_file, args.device)
            rows.append([f"{100 * BALL_SIZE:.0f} cm ball at rest", preset, *cells])
            print("| " + " | ".join(str(c) for c in rows[-1]) + " |", flush=True)
    else:
        names = args.scenes or sorted(p.parent.name for p in args.scenes_dir.glob("*/scene.yaml"))
        for name in names:
            scene = load_scene(args.scenes_dir / name / "scene.yaml")
            gaussians = read_artifact(gaussians_of(scene.file, args.results, args.cache), GaussiansArtifact)
            physics = scene.physics.model_copy(update={"duration_s": args.duration}) if args.duration else scene.physics
            materials = [o.material for o in scene.objects]
            label = ", ".join(f"{m.preset} E={m.youngs_modulus:g}" if hasattr(m, "youngs_modulus") else m.preset
                              for m in materials)
            cells, _ = simulate(physics, materials, gaussians, scene.camera.pitch_deg, scene.file, args.device)
            rows.append([name, label, *cells])
            print("| " + " | ".join(str(c) for c in rows[-1]) + " |", flush=True)
    if args.no_figures:
        return
    write_figures(
        "examples", "Simulate per second of video",
        """pm-simulate's work on each example at its own settings (scenes/*), and on a 23 cm ball ray-cast and
        reconstructed from a 256 x 192 photograph at rest at the default physics settings as each preset:
        particles, grid, the settle's and the run's substeps (independent of the machine's load), seconds to
        build the particles, to settle and to run, and the whole per second of video, with the load average
        beside it. Targets: 40 s per video second for every example, 2 minutes for every preset on the 23 cm
        ball.""", invocation(__file__), COLUMNS, rows, device=args.device, merge_on=2)


if __name__ == "__main__":
    main()
