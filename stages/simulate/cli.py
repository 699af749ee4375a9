"""pm-simulate: gaussians.h5 + the scene's physics -> trajectories.h5 (and setup.png beside it)."""
from __future__ import annotations

import argparse
import logging
from pathlib import Path

import numpy as np
import warp as wp

from schemas import InputError, config_hash, load_scene, resolve_device, run_main, stage_keys, stage_parser
from schemas.artifacts import GaussiansArtifact, TrajectoriesArtifact, check_lineage, read_artifact, write_artifact
from schemas.files import check_writable, refuse_overwriting
from schemas.images import write_image

from .constitutive import wave_speed
from .setup_image import draw_setup
from .simulation import Simulation

log = logging.getLogger("physmotion.simulate")

# An object whose particles all lie within this share of its rest extent, or more than half of whose mass has
# a deformation gradient of det F below COLLAPSED_DET (crushed a thousandfold, or inverted), has collapsed:
# an impact faster than its elastic waves piled it against walls and ground (the solver clamps particles onto
# them), or a material far too soft for its weight was crushed flat; neither is a body the run resolves.
COLLAPSED_EXTENT = 1e-2
COLLAPSED_DET = 1e-3

DESCRIPTION = """\
Simulate the reconstructed objects with MLS-MPM (APIC, quadratic B-splines, Warp kernels).
Each object's volume is filled with particles behind its Gaussians; every object has its own
material preset (jelly, metal, sand, plasticine, foam, snow, rigid, fracture); the scene's
conditions (impulse, velocity, force, torque, fixed) act on regions of the objects, their vectors
and regions read along gravity (x right, y down, z away; `frame: camera` for the camera's axes).
The ground is the plane normal to gravity on which the objects stand on their centres of mass,
and the bodies settle into their own weight before t = 0, so that with no condition nothing
moves; the grid follows the bodies, and only the ground and physics.walls stop them. Substeps
follow a CFL bound unless physics.dt is set; a run above physics.max_substeps_per_frame, or a
physics.dt above the CFL bound, is refused before it starts, and a run that blows up or collapses
a body onto a point writes nothing. Writes trajectories.h5 (positions and deformation gradients of every
particle, per-frame energies and momenta) and setup.png beside it (the
objects, ground, regions and arrows over the photograph: check it before a long run)."""


def build_parser() -> argparse.ArgumentParser:
    parser = stage_parser("pm-simulate", DESCRIPTION)
    parser.add_argument("--scene", required=True, type=Path, help="scene.yaml")
    parser.add_argument("--gaussians", required=True, type=Path, help="gaussians.h5 from pm-reconstruct")
    parser.add_argument("--out", required=True, type=Path, help="trajectories.h5 to write")
    return parser


def simulate(args: argparse.Namespace) -> None:
    scene = load_scene(args.scene)
    device = resolve_device(args.device, runtime="warp")
    wp.config.quiet = not args.verbose
    setup = args.out.parent / "setup.png"
    refuse_overwriting({"--out": args.out, "setup.png": setup}, {"--scene": scene.file, "--gaussians": args.gaussians})
    check_writable([args.out, setup])  # before the simulation, not after it
    digests = check_lineage(scene, gaussians=args.gaussians)
    gaussians = read_artifact(args.gaussians, GaussiansArtifact)
    sim = Simulation(scene.physics, [o.material for o in scene.objects], gaussians.means, gaussians.object_id,
                     pitch_deg=scene.camera.pitch_deg, silhouette=(gaussians.mask, gaussians.K),
                     solids=gaussians.solids(),
                     scene_file=scene.file, device=device)
    write_image(setup, draw_setup(sim, gaussians.photo, gaussians.K))
    log.info("wrote %s", setup)
    try:
        trajectories = sim.run()
        refuse_collapsed(trajectories, scene)
        write_artifact(args.out, trajectories, created_by="pm-simulate",
                       config_hash=config_hash(stage_keys(scene, "simulate")), inputs=digests)
    except BaseException:  # setup.png belongs to this run's trajectories: without them it is not left behind
        setup.unlink(missing_ok=True)
        raise
    log.info("wrote %s", args.out)


def refuse_collapsed(trajectories: TrajectoriesArtifact, scene) -> None:
    """An InputError, before anything is written, when an object's particles collapse onto a point or invert
    (COLLAPSED_EXTENT, COLLAPSED_DET) in some frame, naming the fastest impulse or velocity condition as the
    cause where there is one (else the object's material) and a speed below the material's elastic waves."""
    rest = trajectories.rest_positions
    for k, obj in enumerate(scene.objects):
        sel = trajectories.object_id == k
        size = float(np.max(np.ptp(rest[sel], axis=0)))
        masses = trajectories.masses[sel]
        for f in range(1, len(trajectories.time_s)):
            extent = float(np.max(np.ptp(trajectories.positions[f, sel], axis=0)))
            crushed = np.linalg.det(trajectories.F[f, sel].astype(np.float64)) < COLLAPSED_DET
            if extent > COLLAPSED_EXTENT * size and masses[crushed].sum() <= 0.5 * masses.sum():
                continue
            problem = (f"at frame {f} (t = {trajectories.time_s[f]:.3f} s) object {k} ({obj.material.preset}) has "
                       f"collapsed: its particles span {1e3 * extent:.3g} mm of its {1e3 * size:.3g} mm and "
                       f"{100 * masses[crushed].sum() / masses.sum():.0f} % of its mass is crushed or inverted "
                       "(det F below 1e-3): crushed to a sheet or a point, it is no longer a body the "
                       "simulation resolves")
            speed = wave_speed(obj.material)
            pushes = [(float(np.linalg.norm(c.velocity)), i) for i, c in enumerate(scene.physics.conditions)
                      if c.type in ("impulse", "velocity") and c.object == k]
            fastest, i = max(pushes, default=(0.0, None))
            if fastest > 0.5 * speed:
                raise InputError(scene.file, f"physics.conditions[{i}].velocity",
                                 f"{problem}: it is driven at {fastest:.3g} m/s, more than half its elastic wave "
                                 f"speed ({speed:.3g} m/s)", f"give it a speed below {0.5 * speed:.2g} m/s, "
                                 f"or a stiffer material (objects[{k}].material.youngs_modulus)"
                                 + (", or turn physics.walls off" if scene.physics.walls else ""))
            raise InputError(scene.file, f"objects[{k}].material", f"{problem}: its weight or the conditions "
                             "crush it", f"make objects[{k}].material stiffer (youngs_modulus) or lighter (density), "
                             "or soften the conditions acting on it")


def main(argv=None) -> None:
    run_main(simulate, build_parser(), argv)
