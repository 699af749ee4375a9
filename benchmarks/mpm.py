"""Speed of the MLS-MPM substep: particle-substeps per second for an elastic cube on a 64^3 grid, as
jelly and as fracture (which adds the crack fields' passes, stages/simulate/crack_fields.py);
the same scene simulated as jelly and as rigid (substeps and seconds); and a 1 s fall with the ground
off (the centre of mass against g t^2 / 2).

    python -m benchmarks.mpm [--device cpu] [--steps 40] [--repeats 3] [--no-figures]

The cube is a lattice of 2x2x2 particles per cell (fixed-corotated jelly,
E = 2e5 Pa) in a 1 m domain of 64^3 cells, falling under gravity onto a
sticky ground; the time per substep is the best of `repeats` runs of `steps`
substeps after a warm-up, once with one CPU thread and once with the default
(two on a 2-core CPU). The second table tosses a 10 cm cube (Gaussians 5 mm apart on its faces, the
fill at 8 particles per cell of a 48-cell grid) 1 m/s up from friction ground for 1 s, as jelly
(E = 5e4 Pa) and as rigid: a rigid body has no elastic wave to bound its substep. The third
sets a scene's substep (Simulation.run: conditions, the grid that follows, rigid bodies, free flight,
diagnostics every frame) against the bare solver's (MPMSolver.substep alone) at the same particles,
grid and substep size. `--only scene` runs that table alone.

Each table goes to benchmarks/results/mpm*.json (``_cuda`` appended on a GPU), and RESULTS.md is regenerated.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import warp as wp

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository, before benchmarks/splat.py

from benchmarks.figures import add_arguments, invocation, write_figures  # noqa: E402
from schemas.materials import Fracture, Jelly, Rigid  # noqa: E402
from schemas.scene import PhysicsConfig  # noqa: E402
from stages.simulate.mpm import GROUND_STICKY, Grid, Ground, MPMSolver  # noqa: E402
from stages.simulate.rigid import RigidBodies  # noqa: E402
from stages.simulate.simulation import Simulation  # noqa: E402
from testing.particles import boxes  # noqa: E402


GRID = 64


def cube(n_particles: int, dx: float) -> np.ndarray:
    """Lattice cube of about n_particles at dx / 2 spacing, resting 2 cells above the grid floor's wall layer."""
    side = round(n_particles ** (1 / 3))
    axis = (np.arange(side) + 0.5) * dx / 2
    corner = np.array([0.5 - side * dx / 4, 5 * dx, 0.5 - side * dx / 4])
    return corner + np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3)


def best_substep_s(solver: MPMSolver, dt: float, steps: int, repeats: int, device: str) -> float:
    """The fastest of `repeats` timings of `steps` substeps of `dt` seconds, in seconds per substep."""
    best = float("inf")
    for _ in range(repeats):
        wp.synchronize_device(device)
        start = time.perf_counter()
        for _ in range(steps):
            solver.substep(dt)
        wp.synchronize_device(device)
        best = min(best, (time.perf_counter() - start) / steps)
    return best


def time_substep(material, n_particles: int, threads: int | None, device: str, steps: int,
                 repeats: int) -> tuple[int, int, float]:
    """(particles, threads used, best seconds per substep) for one cube of `material`."""
    dx = 1.0 / GRID
    x = cube(n_particles, dx)
    volume = np.full(len(x), (dx / 2) ** 3)
    solver = MPMSolver(Grid((0.0, 0.0, 0.0), dx, (GRID + 1,) * 3), x, 1000 * volume, volume, np.zeros(len(x), int),
                       [material], np.array([0.0, -9.81, 0.0]), Ground(GROUND_STICKY), device=device, n_parts=threads)
    dt = 1e-4
    for _ in range(10):
        solver.substep(dt)
    best = best_substep_s(solver, dt, steps, repeats, device)
    used = solver.n_parts
    solver.close()
    return len(x), used, best


def print_table(columns: list[str], rows: list[list]) -> None:
    print("| " + " | ".join(columns) + " |")
    print("| " + " | ".join("---" for _ in columns) + " |")
    for row in rows:
        print("| " + " | ".join(str(c) for c in row) + " |", flush=True)


RIGID_COLUMNS = ["preset", "particles", "substeps in 1 s", "seconds"]
SCENE_COLUMNS = ["scene", "particles", "grid", "substeps", "scene ms / substep", "bare solver ms / substep",
                 "scene / bare"]
FALL_COLUMNS = ["fall", "frames", "largest error / (g t^2 / 2)", "at t", "error at 1 s", "grid cells moved"]


def rigid_against_jelly(device: str) -> list[list]:
    """Rows of substeps and seconds of the tossed cube as jelly and as rigid."""
    means, object_id = boxes(((0.0, 0.0, 0.4), (0.1, 0.1, 0.5)), spacing=0.005)
    physics = PhysicsConfig(duration_s=1.0, fps=24, grid=48, ground={"type": "friction", "friction": 0.5},
                            conditions=[{"type": "impulse", "velocity": [0.0, -1.0, 0.0]}])
    rows = []
    for material in (Jelly(youngs_modulus=5e4), Rigid()):
        start = time.perf_counter()
        sim = Simulation(physics, [material], means, object_id, device=device)
        trajectories = sim.run()
        label = "jelly (E = 5e4 Pa)" if material.preset == "jelly" else material.preset
        rows.append([label, len(sim.masses), int(trajectories.substeps.sum()), f"{time.perf_counter() - start:.1f}"])
    return rows


def scene_against_solver(device: str, repeats: int) -> list[list]:
    """Rows of a scene's substep (Simulation.run, settle excluded, over its substeps) against the bare
    solver's (MPMSolver.substep on the same particles, grid and substep size, best of `repeats`)."""
    means, object_id = boxes(((0.0, 0.0, 0.4), (0.1, 0.1, 0.5)), spacing=0.005)
    pushed = [{"type": "fixed", "region": {"box": [0, 0.85, 0, 1, 1, 1]}},
              {"type": "force", "region": {"box": [0, 0, 0, 0.4, 0.4, 1]}, "force": [0.5, 0, 0], "end_s": 0.15}]
    tossed = [{"type": "impulse", "velocity": [0.0, -1.0, 0.0]}]
    rows = []
    for label, material, conditions in (("jelly (E = 5e4 Pa), top held, pushed", Jelly(youngs_modulus=5e4), pushed),
                                        ("rigid, tossed", Rigid(), tossed)):
        physics = PhysicsConfig(duration_s=0.25, fps=24, grid=48, ground={"type": "friction", "friction": 0.5},
                                conditions=conditions)
        sim = Simulation(physics, [material], means, object_id, device=device)
        start = time.perf_counter()
        trajectories = sim.run()
        wp.synchronize_device(device)
        substeps = int(trajectories.substeps.sum())
        scene = (time.perf_counter() - start - sim.settled.wall_s) / substeps
        h = physics.duration_s / substeps
        solver = MPMSolver(sim.grid, sim.rest_sim, sim.masses, sim.volumes, sim.object_id, sim.materials,
                           sim.Q @ sim.gravity_world, sim.ground, device=device)
        if material.preset == "rigid":
            solver.attach_rigid(RigidBodies(sim.rest_sim, sim.masses, sim.object_id, {0: material}, sim.ground,
                                            0.5 * sim.spacing, device))
        bare = best_substep_s(solver, h, substeps, repeats, device)
        solver.close()
        rows.append([label, len(sim.masses), "x".join(map(str, sim.grid.shape)), substeps, f"{1e3 * scene:.2f}",
                     f"{1e3 * bare:.2f}", f"{scene / bare:.2f}"])
    return rows


def free_fall(device: str) -> list[list]:
    """The row of the largest error of the cube's centre of mass against g t^2 / 2 over a 1 s fall, ground off."""
    means, object_id = boxes(((0.0, 0.0, 0.4), (0.1, 0.1, 0.5)), spacing=0.005)
    physics = PhysicsConfig(duration_s=1.0, fps=24, grid=48, ground={"enabled": False})
    sim = Simulation(physics, [Jelly()], means, object_id, device=device)
    trajectories = sim.run()
    com = (trajectories.masses @ trajectories.positions) / trajectories.masses.sum()
    drop = com[1:, 1] - com[0, 1]
    expected = 0.5 * 9.81 * trajectories.time_s[1:] ** 2
    error = np.abs(drop - expected) / expected
    moved = (np.asarray(sim.solver.grid.origin) - np.asarray(sim.grid.origin)) / sim.grid.dx
    return [[f"{drop[-1]:.3f} m", len(drop), f"{100 * error.max():.2f} %", f"{trajectories.time_s[1 + error.argmax()]:.3f} s",
             f"{100 * error[-1]:.3f} %", str(np.round(moved).astype(int).tolist())]]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--steps", type=int, default=40)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--only", choices=["scene"], default=None, help="run the scene-against-solver table alone")
    add_arguments(parser)
    args = parser.parse_args()
    wp.config.quiet = True
    wp.init()
    cpu = wp.get_device(args.device).is_cpu
    suffix, command, on = "" if cpu else "_cuda", invocation(__file__), "" if cpu else " on CUDA"
    scene = scene_against_solver(args.device, args.repeats)
    print_table(SCENE_COLUMNS, scene)
    print()
    if not args.no_figures:
        write_figures(
            "mpm_scene" + suffix, "A scene's substep against the bare solver's" + on,
            """A 10 cm cube (Gaussians 5 mm apart on its faces, the fill at 8 particles per cell of a 48-cell
            grid) simulated for 0.25 s by Simulation.run (its conditions, the grid that follows, rigid bodies,
            free flight, the diagnostics of every frame), as jelly with its top held and its lower corner
            pushed, and as rigid tossed up: wall seconds per substep, the settle left out, against
            MPMSolver.substep alone on the same particles, grid and substep size (best of the repeats).
            Target: at most 1.3 times.""", command, SCENE_COLUMNS, scene, device=args.device)
    if args.only == "scene":
        return
    columns = ["material", "particles", "grid", "threads" if cpu else "device", "ms / substep",
               "million particle-substeps / s"]
    print("| " + " | ".join(columns) + " |")
    print("| " + " | ".join("---" for _ in columns) + " |")
    rows = []
    for material in (Jelly(youngs_modulus=2e5), Fracture(youngs_modulus=2e5)):
        for n in (30_000, 100_000):
            for threads in ((1, None) if cpu else (None,)):
                count, used, seconds = time_substep(material, n, threads, args.device, args.steps, args.repeats)
                rows.append([material.preset, count, f"{GRID}^3", used if cpu else args.device,
                             f"{1e3 * seconds:.2f}", f"{count / seconds / 1e6:.2f}"])
                print("| " + " | ".join(str(c) for c in rows[-1]) + " |", flush=True)
    print()
    rigid = rigid_against_jelly(args.device)
    print_table(RIGID_COLUMNS, rigid)
    print()
    fall = free_fall(args.device)
    print_table(FALL_COLUMNS, fall)
    if args.no_figures:
        return
    write_figures(
        "mpm" + suffix, "MLS-MPM substep" + on,
        f"""Time of one MLS-MPM substep (P2G, the grid update over the particles' node box, G2P, the return
        mapping and stress) for a cube of 2x2x2 particles per cell (E = 2e5 Pa) falling onto sticky ground in
        a 1 m domain of {GRID}^3 cells, as jelly and as fracture, whose substep adds the crack fields' passes
        (stages/simulate/crack_fields.py: the damage to the grid, the damage gradient, each node's crack
        direction, then two fields through P2G, the grid update and G2P). Best of {args.repeats} runs of
        {args.steps} substeps after a warm-up{', on one CPU thread and on the default two' if cpu else ''}.""",
        command, columns, rows, device=args.device,
        notes=["Target: 2.5 million particle-substeps/s at 30k particles (PhysGaussian's Warp MPM about 1.0 "
               "million, single-threaded Taichi MLS-MPM about 1.3 million on the 2-core CPU)."])
    write_figures(
        "mpm_rigid" + suffix, "Rigid against jelly" + on,
        """A 10 cm cube (Gaussians 5 mm apart on its faces, the fill at 8 particles per cell of a 48-cell grid)
        tossed 1 m/s up from friction ground for 1 s, as jelly (E = 5e4 Pa) and as rigid: substeps and wall
        seconds of the whole simulation.""", command, RIGID_COLUMNS, rigid, device=args.device)
    write_figures(
        "mpm_fall" + suffix, "A 1 s fall" + on,
        """A 10 cm cube (Gaussians 5 mm apart on its faces, the fill at 8 particles per cell of a 48-cell grid)
        falling for 1 s with the ground off: its centre of mass against g t^2 / 2 over 24 frames, and how far
        the grid that follows the bodies moved.""", command, FALL_COLUMNS, fall, device=args.device)


if __name__ == "__main__":
    main()
