"""Run every pm-simulate kernel in Warp's debug mode, where array indexing is bounds-checked.

    PYTHONPATH=. python benchmarks/debug_kernels.py [--device cpu]

Release CPU kernels do not check bounds, so an index off the grid silently
corrupts memory. With PHYSMOTION_WARP_DEBUG=1 (set here before stages.simulate
is imported, see stages/simulate/__init__.py) every kernel asserts its indices:
an out-of-bounds access aborts the process with the failed check.

First it proves that the checks are live: a kernel that reads one past the end
of an array must abort a child process. Then it simulates a few frames of
three small scenes that together reach every simulate kernel, with the solver's
two-thread split: all eight material presets side by side in a walled domain
with impulse, velocity, force, torque and fixed conditions and friction
ground; a cube thrown into the walls' corner, so that particles are
held at the wall layer and stencils reach the grid's edge; a cube torn apart
faster than the grid follows, so that particles fly off it, land on the
ground and come back. Exit status 0 means no kernel indexed out of bounds.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys

os.environ["PHYSMOTION_WARP_DEBUG"] = "1"

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

from schemas import materials as M  # noqa: E402
from schemas.scene import PhysicsConfig  # noqa: E402
from stages.simulate.simulation import Simulation  # noqa: E402
from testing.particles import boxes  # noqa: E402


@wp.kernel
def read_past_end(a: wp.array(dtype=float), out: wp.array(dtype=float)):
    """Reads a[tid + 1]: the last thread is one past the end."""
    out[0] = a[wp.tid() + 1]


PRESETS = [M.Jelly(), M.Metal(), M.Sand(), M.Plasticine(), M.Foam(), M.Snow(), M.Rigid(), M.Fracture()]


def checks_are_live(device: str) -> bool:
    """True when an out-of-bounds read in a debug-mode kernel stops the process that runs it with a failed
    assertion."""
    child = subprocess.run([sys.executable, __file__, "--device", device, "--read-past-end"],
                           capture_output=True, text=True)
    return child.returncode != 0 and "assert" in child.stderr.lower()


def launch_read_past_end(device: str) -> None:
    a = wp.zeros(4, dtype=float, device=device)
    wp.launch(read_past_end, dim=4, inputs=[a, wp.zeros(1, dtype=float, device=device)], device=device)
    wp.synchronize_device(device)


def scenes() -> list[tuple[str, dict, list, list]]:
    """(name, physics, materials, box extents) of the scenes to run."""
    cube = 0.06
    row = [((0.1 * k, 0, 0), (0.1 * k + cube, cube, cube)) for k in range(len(PRESETS))]
    every_condition = [
        {"type": "impulse", "object": 0, "region": "all", "velocity": [0.5, -1.0, 0.0]},
        {"type": "velocity", "object": 1, "region": {"box": [0, 0, 0, 1, 0.3, 1]}, "velocity": [0.2, 0, 0],
         "start_s": 0.0, "end_s": 0.05},
        {"type": "force", "object": 2, "region": {"sphere": [0.5, 0.5, 0.5, 0.4]}, "force": [0, -2, 0],
         "start_s": 0.0, "end_s": 0.1},
        {"type": "torque", "object": 6, "region": "all", "torque": [0, 0, 0.01], "start_s": 0.0, "end_s": 0.1},
        {"type": "fixed", "object": 7, "region": {"box": [0, 0, 0, 1, 0.2, 1]}},
    ]
    return [
        ("every preset, every condition, friction ground, walls",
         dict(duration_s=0.1, fps=20, grid=24, walls=True, conditions=every_condition,
              ground={"enabled": True, "type": "friction", "friction": 0.3}), PRESETS, row),
        # thrown hard at the walls' corner: particles are clamped at the wall layer, stencils at the grid's edge
        ("a cube thrown into the walls' corner, no ground",
         dict(duration_s=0.2, fps=10, grid=16, gravity=[0, 0, 0], ground={"enabled": False}, walls=True,
              conditions=[{"type": "impulse", "velocity": [-20.0, -20.0, -20.0]}]),
         [M.Jelly()], [((0, 0, 0), (0.05, 0.05, 0.05))]),
        # torn apart faster than the grid can follow: particles leave it, fly freely, land on the ground
        ("a cube torn apart off the grid, onto the ground",
         dict(duration_s=0.3, fps=10, grid=16, ground={"enabled": True, "type": "friction", "friction": 0.5},
              conditions=[{"type": "velocity", "region": {"box": [0, 0, 0, 0.5, 1, 1]}, "velocity": [-6, -2, 0],
                           "end_s": 0.02},
                          {"type": "velocity", "region": {"box": [0.5, 0, 0, 1, 1, 1]}, "velocity": [6, -2, 0],
                           "end_s": 0.02}]),
         [M.Fracture(critical_stretch=0.01, toughness=0.01)], [((0, 0, 0), (0.05, 0.05, 0.05))]),
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--read-past-end", action="store_true", help=argparse.SUPPRESS)  # the child's job
    args = parser.parse_args()
    wp.config.quiet = True
    assert wp.config.mode == "debug", "stages.simulate did not switch Warp to debug mode"
    if args.read_past_end:
        launch_read_past_end(args.device)
        return
    if not checks_are_live(args.device):
        sys.exit("debug mode did not catch an out-of-bounds read; the bounds checks are not active")
    print("debug mode catches an out-of-bounds read (checked in a child process)")
    for name, physics, materials, extents in scenes():
        means, object_id = boxes(*extents, spacing=0.01)
        sim = Simulation(PhysicsConfig(**physics), materials, means, object_id, device=args.device)
        tr = sim.run()
        assert np.all(np.isfinite(tr.positions)), f"{name}: non-finite positions"
        print(f"ok: {name} ({len(tr.masses)} particles, {int(tr.substeps.sum())} substeps, debug-mode kernels)")


if __name__ == "__main__":
    main()
