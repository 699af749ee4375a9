"""Rest drift: a photographed object with no conditions must stay where it stands.

    python -m benchmarks.rest results/ball results/coffee ... [--presets scene jelly rigid ...] [--no-figures]

Each folder holds a scene's gaussians.h5 (from pm-reconstruct) and names its
scene by results/<name> -> scenes/<name>/scene.yaml unless --scenes-dir says
otherwise. The object is simulated under the scene's camera, ground and
duration with every condition removed, once per preset (with the preset's
defaults; `scene`: the scene's own materials). Printed per run: the largest turn of the body
over the run (degrees, best rigid fit of all particles), the largest
horizontal travel of its centre of mass (mm and % of size_m), the largest
sag of the centre of mass (mm), substeps and seconds.

The rows go to benchmarks/results/rest.json, replacing those of the same scene and preset and keeping
the others (each row names its commit), and RESULTS.md is regenerated.
"""
from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository, before benchmarks/splat.py

from benchmarks.figures import add_arguments, invocation, write_figures  # noqa: E402
from schemas import load_scene  # noqa: E402
from schemas import materials as M  # noqa: E402
from schemas.artifacts import GaussiansArtifact, read_artifact  # noqa: E402
from stages.simulate.rest_state import turn_deg  # noqa: E402
from stages.simulate.simulation import Simulation  # noqa: E402

PRESET_MODELS = {"jelly": M.Jelly, "metal": M.Metal, "sand": M.Sand, "plasticine": M.Plasticine, "foam": M.Foam,
                 "snow": M.Snow, "rigid": M.Rigid, "fracture": M.Fracture}


def preset_materials(scene, preset: str) -> tuple[list, str]:
    """Each object's material as `preset` with the preset's defaults, or the scene's own ("scene"), and its
    label for a table."""
    if preset != "scene":
        return [PRESET_MODELS[preset]() for _ in scene.objects], preset
    materials = [o.material for o in scene.objects]
    return materials, "scene's: " + ", ".join(
        f"{m.preset} E={m.youngs_modulus:g}" if hasattr(m, "youngs_modulus") else m.preset for m in materials)


def drift(sim: Simulation, tr) -> dict:
    """Largest turn (deg), horizontal centre-of-mass travel (m) and sag (m, + down) over the run."""
    m = tr.masses
    com = (m @ tr.positions) / m.sum()  # (T,3) world
    d = (com - com[0]) @ sim.Q.T  # simulation frame: y up
    turns = [turn_deg(tr.positions[0], tr.positions[f], m) for f in range(len(tr.time_s))]
    return {"turn": max(turns), "travel": float(np.max(np.linalg.norm(d[:, [0, 2]], axis=1))),
            "sag": float(np.max(-d[:, 1])), "substeps": int(tr.substeps.sum())}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("results", nargs="+", type=Path, help="folders holding gaussians.h5")
    parser.add_argument("--scenes-dir", type=Path, default=Path("scenes"))
    parser.add_argument("--presets", nargs="+", default=["jelly", "metal", "rigid", "plasticine", "foam",
                                                         "fracture", "sand", "snow"])
    parser.add_argument("--duration", type=float, default=None, help="seconds (default: the scene's)")
    add_arguments(parser)
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    columns = ["scene", "preset", "turn (deg)", "travel (mm)", "travel (% size)", "sag (mm)", "substeps", "s"]
    print("| " + " | ".join(columns) + " |")
    print("| " + " | ".join("---" for _ in columns) + " |")
    rows = []
    for folder in args.results:
        scene = load_scene(args.scenes_dir / folder.name / "scene.yaml")
        g = read_artifact(folder / "gaussians.h5", GaussiansArtifact)
        physics = scene.physics.model_copy(update={"conditions": []})
        if args.duration:
            physics = physics.model_copy(update={"duration_s": args.duration})
        size = scene.objects[0].size_m
        for preset in args.presets:
            materials, label = preset_materials(scene, preset)
            start = time.perf_counter()
            sim = Simulation(physics, materials, g.means, g.object_id, pitch_deg=scene.camera.pitch_deg,
                             silhouette=(g.mask, g.K), solids=g.solids(), scene_file=scene.file)
            tr = sim.run()
            r = drift(sim, tr)
            rows.append([folder.name, label, f"{r['turn']:.2f}", f"{1e3 * r['travel']:.2f}",
                         f"{100 * r['travel'] / size:.2f}", f"{1e3 * r['sag']:.2f}", r["substeps"],
                         f"{time.perf_counter() - start:.0f}"])
            print("| " + " | ".join(str(c) for c in rows[-1]) + " |", flush=True)
    if not args.no_figures:
        write_figures(
            "rest", "Rest drift",
            """A photographed object with no conditions must stay where it stands. Each reconstruction is
            simulated for its scene's duration with every condition removed, as each preset with the preset's
            defaults (`scene's`: the scene's own material): the largest turn of the body (best rigid fit of all
            particles), the largest travel of its centre of mass along the ground (mm and % of size_m), the
            largest sag of its centre of mass, substeps and seconds. Target: 1 degree and 1 % of size_m. ball, loaf,
            coffee and clay are the example scenes (scenes/NAME); shuttle (the model shuttle at the right of
            scikit-image's astronaut, box [352, 0, 470, 290], 0.3 m), cat (chelsea's head, box [20, 0, 400,
            300], 0.15 m), rocket (scikit-image's rocket on its pad, box [296, 120, 348, 410], 0.3 m) and coin
            (scikit-image's coins, the large coin at the right, 3 cm of metal seen from 80 degrees above) are
            photographs new to the project, as a new user writes them. Every folder is
            reconstructed by `pm-reconstruct --scene DIR/NAME/scene.yaml --out results/NAME/gaussians.h5` at
            the commit named and measured with `--scenes-dir DIR`.""",
            invocation(__file__), columns, rows, merge_on=2)


if __name__ == "__main__":
    main()
