"""Toss: a body tossed straight up must come down where it went up.

    PYTHONPATH=. python benchmarks/toss.py results/ball ... [--presets jelly rigid ...] [--speed 1.2]

Each folder holds a scene's gaussians.h5 (from pm-reconstruct) and names its
scene by results/<name> -> scenes/<name>/scene.yaml unless --scenes-dir says
otherwise. Every condition of the scene is replaced by one impulse straight up
(against gravity) at t = 0, and the body is simulated under the scene's camera
and ground, once per preset and ground type. Printed per run: the largest
horizontal travel of the centre of mass from where it went up (mm, % of
size_m), the largest turn of the body (degrees, best rigid fit of all
particles), the largest rise of the total energy (kinetic + potential, the
trajectories' diagnostics) above its value at the first frame after the toss,
as a share of the toss's kinetic energy, substeps and seconds.
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

from benchmarks.rest import PRESET_MODELS, drift


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
                     silhouette=(gaussians.mask, gaussians.K), prior_volumes=gaussians.object_volumes,
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
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    print("| scene | preset | ground | travel (mm) | travel (% size) | turn (deg) | energy gain (% toss) | substeps | s |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for folder in args.results:
        scene = load_scene(args.scenes_dir / folder.name / "scene.yaml")
        gaussians = read_artifact(folder / "gaussians.h5", GaussiansArtifact)
        size = scene.objects[0].size_m
        for preset in args.presets:
            materials = ([o.material for o in scene.objects] if preset == "scene"
                         else [PRESET_MODELS[preset]() for _ in scene.objects])
            label = preset if preset != "scene" else "scene's " + ", ".join(m.preset for m in materials)
            for ground in args.grounds:
                start = time.perf_counter()
                sim, tr = toss(scene, gaussians, materials, ground, args.speed, args.duration)
                r = drift(sim, tr)
                print(f"| {folder.name} | {label} | {ground} | {1e3 * r['travel']:.1f} | "
                      f"{100 * r['travel'] / size:.2f} | {r['turn']:.2f} | {100 * energy_gain(tr):.2f} | "
                      f"{r['substeps']} | {time.perf_counter() - start:.0f} |", flush=True)


if __name__ == "__main__":
    main()
