"""pm-simulate: gaussians.h5 + the scene's physics -> trajectories.h5 (and setup.png beside it)."""
from __future__ import annotations

import argparse
import logging
from pathlib import Path

import warp as wp

from schemas import config_hash, load_scene, resolve_device, run_main, stage_keys, stage_parser
from schemas.artifacts import GaussiansArtifact, check_lineage, read_artifact, write_artifact
from schemas.files import check_writable, refuse_overwriting
from schemas.images import write_image

from .setup_image import draw_setup
from .simulation import Simulation

log = logging.getLogger("physmotion.simulate")

DESCRIPTION = """\
Simulate the reconstructed objects with MLS-MPM (APIC, quadratic B-splines, Warp kernels).
Each object's volume is filled with particles behind its Gaussians; every object has its own
material preset (jelly, metal, sand, plasticine, foam, snow, rigid, fracture); the scene's
conditions (impulse, velocity, force, torque, fixed) act on regions of the objects, their vectors
and regions read along gravity (x right, y down, z away; `frame: camera` for the camera's axes).
The ground is the plane normal to gravity on which the objects stand on their centres of mass,
and the bodies settle into their own weight before t = 0, so that with no condition nothing
moves; the grid follows the bodies, and only the ground and physics.walls stop them. Substeps
follow a CFL bound unless physics.dt is set; a run above physics.max_substeps_per_frame is
refused before it starts. Writes trajectories.h5 (positions and deformation gradients of every
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
    device = resolve_device(args.device)
    wp.config.quiet = not args.verbose
    setup = args.out.parent / "setup.png"
    refuse_overwriting({"--out": args.out, "setup.png": setup}, {"--scene": scene.file, "--gaussians": args.gaussians})
    check_writable([args.out, setup])  # before the simulation, not after it
    digests = check_lineage(scene, gaussians=args.gaussians)
    gaussians = read_artifact(args.gaussians, GaussiansArtifact)
    sim = Simulation(scene.physics, [o.material for o in scene.objects], gaussians.means, gaussians.object_id,
                     pitch_deg=scene.camera.pitch_deg, silhouette=(gaussians.mask, gaussians.K),
                     prior_volumes=gaussians.object_volumes,
                     scene_file=scene.file, device=device)
    write_image(setup, draw_setup(sim, gaussians.photo, gaussians.K))
    log.info("wrote %s", setup)
    trajectories = sim.run()
    write_artifact(args.out, trajectories, created_by="pm-simulate",
                   config_hash=config_hash(stage_keys(scene, "simulate")), inputs=digests)
    log.info("wrote %s", args.out)


def main(argv=None) -> None:
    run_main(simulate, build_parser(), argv)
