"""Mass and inertia of the simulated solid of reconstructed synthetic shapes, against their analytic values.

    python benchmarks/mass.py [--sizes 96 128 192] [--iterations 100]

Each shape (a 12 cm ball, the 25 cm capsule tilted 20 degrees, a 14 x 9 x 9 cm box seen face on) is
ray-cast by stages/reconstruct/synthetic.py at each photograph width, reconstructed by pm-reconstruct
and filled as pm-simulate fills it (grown to the photograph's silhouette). Printed: the solid's volume
and its principal moments of inertia (density 1000) over the analytic ones, the skin it was grown by
and the particle count.
"""
from __future__ import annotations

import argparse
import logging
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository, before benchmarks/splat.py

from schemas import materials as M  # noqa: E402
from schemas.artifacts import GaussiansArtifact, read_artifact  # noqa: E402
from schemas.scene import PhysicsConfig  # noqa: E402
from stages.reconstruct.cli import main as reconstruct  # noqa: E402
from stages.reconstruct.synthetic import Box, Capsule, write_scene  # noqa: E402
from stages.simulate.simulation import Simulation, mass_properties  # noqa: E402

RHO = 1000.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", nargs="+", type=int, default=[96, 128, 192])
    parser.add_argument("--iterations", type=int, default=100)
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    shapes = {"ball": Capsule(np.array([0.0, 0.0, 0.6]), np.array([1e-6, 0.0, 0.0]), 0.06),
              "capsule": Capsule.tilted(), "box": Box(np.array([0.0, 0.0, 0.6]), np.array([0.07, 0.045, 0.045]))}
    print("| shape | photo px | particles | volume / analytic | principal moments / analytic |")
    print("| --- | --- | --- | --- | --- |")
    for name, shape in shapes.items():
        volume, moments = shape.volume, shape.principal_moments(RHO)
        for width in args.sizes:
            with tempfile.TemporaryDirectory() as tmp:
                scene = write_scene(Path(tmp), shape, width=width, height=width * 3 // 4, iterations=args.iterations)
                reconstruct(["--scene", str(scene), "--out", f"{tmp}/g.h5", "--device", "cpu"])
                g = read_artifact(f"{tmp}/g.h5", GaussiansArtifact)
            sim = Simulation(PhysicsConfig(duration_s=0.01, grid=48), [M.Rigid(density=RHO)], g.means, g.object_id,
                             silhouette=(g.mask, g.K), prior_volumes=g.object_volumes)
            _, moments_sim = mass_properties(sim.masses, sim.rest_world)
            ratios = moments_sim / moments
            print(f"| {name} | {width} x {width * 3 // 4} | {len(sim.masses)} | {sim.volumes.sum() / volume:.3f} | "
                  f"{', '.join(f'{q:.3f}' for q in ratios)} |", flush=True)


if __name__ == "__main__":
    main()
