"""Mass and inertia of the simulated solid of reconstructed synthetic shapes, against their analytic values.

    python -m benchmarks.mass [--sizes 96 128 192] [--iterations 100] [--no-figures]
    python -m benchmarks.mass --off-axis [--balls 120] [--no-figures]

Each shape (a 12 cm ball 0.6 m away, a 20 cm ball 0.35 m away, the 25 cm capsule tilted 20 degrees, a
14 x 9 x 9 cm box seen face on) is ray-cast by testing/photographs.py at each photograph width,
reconstructed by pm-reconstruct and filled as pm-simulate fills it (the lattice in the solid the
reconstruction passes on). Printed: the solid's volume and its principal moments of inertia
(density 1000) over the analytic ones and the particle count.

--off-axis: the depth prior's own volume (no optimisation) of balls of radius 3-12 cm, 0.5-1.5 m away,
0-24 degrees off the axis of a 50 degree camera at 320 x 240, and of upright capsules half as wide, 2-4
times as long as wide (their axis along the image's columns, at one depth), over the shape's, per band of
angle off the axis (ray-cast silhouettes, random).

The tables go to benchmarks/results/mass.json and mass_off_axis.json, and RESULTS.md is regenerated.
"""
from __future__ import annotations

import argparse
import logging
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository, before benchmarks/splat.py

from benchmarks.figures import add_arguments, invocation, write_figures  # noqa: E402
from schemas import materials as M  # noqa: E402
from schemas.artifacts import GaussiansArtifact, read_artifact  # noqa: E402
from schemas.scene import PhysicsConfig  # noqa: E402
from stages.reconstruct.cli import main as reconstruct  # noqa: E402
from stages.reconstruct.closure import object_depths  # noqa: E402
from stages.reconstruct.geometry import intrinsics_from_fov  # noqa: E402
from testing.photographs import Box, Capsule, photograph, write_scene  # noqa: E402
from stages.simulate.simulation import Simulation, mass_properties  # noqa: E402

RHO = 1000.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", nargs="+", type=int, default=[96, 128, 192])
    parser.add_argument("--iterations", type=int, default=100)
    parser.add_argument("--off-axis", action="store_true", help="the prior's volume of balls off the axis")
    parser.add_argument("--balls", type=int, default=120)
    add_arguments(parser)
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    if args.off_axis:
        columns, rows = off_axis(args.balls)
        if not args.no_figures:
            write_figures(
                "mass_off_axis", "The depth prior's volume off the optical axis",
                """The volume the depth prior encloses (which the particles carry) of shapes ray-cast at random off
                the optical axis of a 50 degree camera at 320 x 240, 0.5-1.5 m away, over the shape's volume, per
                band of angle off the axis: balls of radius 3-12 cm, and upright capsules half as wide, 2-4 times as
                long as wide, their axis along the image's columns at one depth.""",
                invocation(__file__), columns, rows)
        return
    # (shape, field of view in degrees); the near ball fills half a 60 degree view, 35 cm away
    shapes = {"ball": (Capsule(np.array([0.0, 0.0, 0.6]), np.array([1e-6, 0.0, 0.0]), 0.06), 40.0),
              "near ball": (Capsule(np.array([0.0, 0.0, 0.35]), np.array([1e-6, 0.0, 0.0]), 0.1), 60.0),
              "capsule": (Capsule.tilted(), 40.0),
              "box": (Box(np.array([0.0, 0.0, 0.6]), np.array([0.07, 0.045, 0.045])), 40.0)}
    columns = ["shape", "photo px", "particles", "volume / analytic", "principal moments / analytic"]
    print("| " + " | ".join(columns) + " |")
    print("| " + " | ".join("---" for _ in columns) + " |")
    rows = []
    for name, (shape, fov_deg) in shapes.items():
        volume, moments = shape.volume, shape.principal_moments(RHO)
        for width in args.sizes:
            with tempfile.TemporaryDirectory() as tmp:
                scene = write_scene(Path(tmp), shape, fov_deg, width=width, height=width * 3 // 4,
                                    iterations=args.iterations)
                reconstruct(["--scene", str(scene), "--out", f"{tmp}/g.h5", "--device", "cpu"])
                g = read_artifact(f"{tmp}/g.h5", GaussiansArtifact)
            sim = Simulation(PhysicsConfig(duration_s=0.01, grid=48), [M.Rigid(density=RHO)], g.means, g.object_id,
                             silhouette=(g.mask, g.K), solids=g.solids())
            _, moments_sim = mass_properties(sim.masses, sim.rest_world)
            ratios = moments_sim / moments
            rows.append([name, f"{width} x {width * 3 // 4}", len(sim.masses), f"{sim.volumes.sum() / volume:.3f}",
                         ", ".join(f"{q:.3f}" for q in ratios)])
            print("| " + " | ".join(str(c) for c in rows[-1]) + " |", flush=True)
    if not args.no_figures:
        write_figures(
            "mass", "Mass and inertia",
            f"""The simulated solid of shapes ray-cast by testing/photographs.py and reconstructed by
            pm-reconstruct ({args.iterations} iterations) over the analytic solid (density 1000): its volume and
            principal moments of inertia. The shapes: a 12 cm ball 0.6 m from a 40 degree camera, a 20 cm ball
            0.35 m from a 60 degree one (near ball), the 25 cm capsule tilted 20 degrees, a 14 x 9 x 9 cm box
            seen face on. Each object's particles carry the volume its depth prior encloses, what the solid
            lacks of it laid on its side walls (docs/decisions/0005-prior-volume-on-the-side-walls.md).""",
            invocation(__file__), columns, rows,
            notes=["Target: volume within 5 %, principal moments within 10 %."])


def off_axis(count: int, band_deg: float = 8.0) -> tuple[list[str], list[list]]:
    """Print (and return as columns and rows) the prior's volume over the shape's per band of angle off the
    optical axis: balls, and upright capsules (their axis along the image's columns, at one depth) for the
    other reading of a silhouette off the axis."""
    height, width = 240, 320
    K = intrinsics_from_fov(50, width, height)
    rng = np.random.default_rng(0)
    bands: dict[tuple[str, int], list[float]] = {}
    for kind in ("ball", "upright capsule"):
        for _ in range(count):
            distance, radius = rng.uniform(0.5, 1.5), rng.uniform(0.03, 0.12)
            off, turn = math.radians(rng.uniform(0, 3 * band_deg)), rng.uniform(0, 2 * math.pi)
            direction = np.array([math.tan(off) * math.cos(turn), math.tan(off) * math.sin(turn), 1.0])
            centre = distance * direction / np.linalg.norm(direction)
            if kind == "ball":
                shape = Capsule(centre, np.array([1e-6, 0.0, 0.0]), radius)
            else:  # as long as the ball is wide or twice that, half as wide
                shape = Capsule(centre, np.array([0.0, radius * rng.uniform(0.5, 1.5), 0.0]), radius / 2)
            mask = photograph(shape, K, np.eye(4), width, height).mask
            if not mask.any() or mask[[0, -1]].any() or mask[:, [0, -1]].any():
                continue  # cut by the border
            volume = object_depths(mask.astype(np.uint8), K, [shape.size_m], 0.0)[0].volume(K)
            bands.setdefault((kind, int(math.degrees(off) // band_deg)), []).append(volume / shape.volume)
    columns = ["shape", "degrees off the axis", "shapes", "prior volume / shape: mean", "sd", "min", "max"]
    rows = [[kind, f"{band * band_deg:.0f}-{(band + 1) * band_deg:.0f}", len(v), f"{np.mean(v):.3f}",
             f"{np.std(v):.3f}", f"{np.min(v):.3f}", f"{np.max(v):.3f}"] for (kind, band), v in sorted(bands.items())]
    print("| " + " | ".join(columns) + " |")
    print("| " + " | ".join("---" for _ in columns) + " |")
    for row in rows:
        print("| " + " | ".join(str(c) for c in row) + " |")
    return columns, rows


if __name__ == "__main__":
    main()
