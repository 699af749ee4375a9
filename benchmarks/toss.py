"""Toss: a body tossed straight up must come down where it went up.

    python -m benchmarks.toss results/ball ... [--presets scene jelly rigid ...] [--speed 1.2] [--no-figures]

Each folder holds a scene's gaussians.h5 (from pm-reconstruct) and names its
scene by results/<name> -> scenes/<name>/scene.yaml unless --scenes-dir says
otherwise. Every condition of the scene is replaced by one impulse straight up
(against gravity) at t = 0, and the body is simulated under the scene's camera
and ground, once per preset and ground type. Printed per run: the largest
horizontal travel of the centre of mass from where it went up (mm, % of
size_m), the largest turn of the body (degrees, best rigid fit of all
particles), the largest rise of the total energy (kinetic + potential, the
trajectories' diagnostics) above its value at the first frame after the toss,
as a share of the toss's kinetic energy, substeps and seconds. The table goes to
benchmarks/results/toss.json (rows merged by scene, preset and ground), and RESULTS.md is regenerated.
"""
from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path

import numpy as np

from schemas import load_scene
from schemas.artifacts import GaussiansArtifact, read_artifact
from schemas.scene import GroundConfig, Impulse
from stages.simulate.simulation import Simulation

from benchmarks.figures import add_arguments, invocation, write_figures
from benchmarks.rest import drift, preset_materials


def energy_gain(tr) -> float:
    """Largest rise of kinetic + potential energy above its value at frame 1, over the kinetic energy at
    frame 1 (the toss's)."""
    total = tr.kinetic_energy + tr.potential_energy
    return float(np.max(total[1:] - total[1]) / tr.kinetic_energy[1])


def toss(scene, gaussians, materials, ground: str, speed: float, duration: float | None) -> tuple[Simulation, object]:
    """The scene's objects tossed straight up at `speed` m/s on a `ground` ground ('friction' keeps the
    scene's coefficient), every other condition removed."""
    physics = scene.physics
    ground_config = physics.ground if ground == "friction" else GroundConfig(type=ground)
    update = {"conditions": [Impulse(type="impulse", velocity=(0.0, -speed, 0.0))], "ground": ground_config}
    if duration:
        update["duration_s"] = duration
    physics = physics.model_copy(update=update)
    sim = Simulation(physics, materials, gaussians.means, gaussians.object_id, pitch_deg=scene.camera.pitch_deg,
                     silhouette=(gaussians.mask, gaussians.K), solids=gaussians.solids(),
                     scene_file=scene.file)
    return sim, sim.run()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("results", nargs="+", type=Path, help="folders holding gaussians.h5")
    parser.add_argument("--scenes-dir", type=Path, default=Path("scenes"))
    parser.add_argument("--presets", nargs="+", default=["scene", "jelly", "rigid", "metal", "plasticine"])
    parser.add_argument("--grounds", nargs="+", default=["friction", "slip"], choices=["friction", "slip", "sticky"])
    parser.add_argument("--speed", type=float, default=1.2, help="m/s straight up")
    parser.add_argument("--duration", type=float, default=None, help="seconds (default: the scene's)")
    add_arguments(parser)
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    columns = ["scene", "preset", "ground", "travel (mm)", "travel (% size)", "turn (deg)", "energy gain (% toss)",
               "substeps", "s"]
    print("| " + " | ".join(columns) + " |")
    print("|" + " --- |" * len(columns))
    rows = []
    for folder in args.results:
        scene = load_scene(args.scenes_dir / folder.name / "scene.yaml")
        gaussians = read_artifact(folder / "gaussians.h5", GaussiansArtifact)
        size = scene.objects[0].size_m
        for preset in args.presets:
            materials, label = preset_materials(scene, preset)
            for ground in args.grounds:
                start = time.perf_counter()
                sim, tr = toss(scene, gaussians, materials, ground, args.speed, args.duration)
                r = drift(sim, tr)
                rows.append([folder.name, label, ground, f"{1e3 * r['travel']:.1f}", f"{100 * r['travel'] / size:.2f}",
                             f"{r['turn']:.2f}", f"{100 * energy_gain(tr):.2f}", r["substeps"],
                             f"{time.perf_counter() - start:.0f}"])
                print("| " + " | ".join(str(c) for c in rows[-1]) + " |", flush=True)
    if not args.no_figures:
        write_figures(
            "toss", "Toss",
            f"""A body tossed straight up must come down where it went up. Each reconstruction's conditions are
            replaced by one impulse of {args.speed:g} m/s against gravity at t = 0, and it is simulated for its
            scene's duration under its scene's camera, as each preset with the preset's defaults (`scene's`: the
            scene's own material), on friction ground (the scene's coefficient) and on slip ground: the largest
            travel of its centre of mass along the ground from where it went up (mm and % of size_m), the
            largest turn of the body (best rigid fit of all particles), the largest rise of its total energy
            (kinetic + potential, the trajectories' diagnostics) above its value at the first frame after the
            toss, as a share of the toss's kinetic energy, substeps and seconds. Targets: 2 % of size_m, 3
            degrees, 2 %. ball is the example scene; cat, rocket, shuttle and coin are scikit-image's chelsea
            (the head, jelly), rocket (a 30 cm model standing on its pad, jelly of 5 MPa), astronaut (the model
            shuttle, jelly) and coins (the large coin at the right, metal, seen from 80 degrees above) as a new
            user writes them (benchmarks/scenes/, photographs by make_photos.py). Each scene's own material is
            jelly but the coin's, so its `scene's` rows are its jelly rows. A jelly
            that bounces turns by the lever between its contact and its centre of mass, which the
            reconstructed shape sets (docs/decisions/0029-toss-spin-is-the-body-s.md).""",
            invocation(__file__), columns, rows, merge_on=3)


if __name__ == "__main__":
    main()
