"""Tearing: a torn body must read as solid pieces, without dust or see-through material.

    python -m benchmarks.tearing results/loaf [results/... ...] [--no-figures]

(run as a module from the repository root: it reads its measures from the tests, and a script
run from benchmarks/ would take benchmarks/splat.py for the splat package)

Each folder holds a scene's gaussians.h5, trajectories.h5 and coarse.h5 (the README's workflow writes
them; benchmarks/scenes/loaf is a loaf torn by pulling its ends). Printed per sampled frame, with the
tests' own measures (tests/simulate and tests/render_enhance/test_render_interior.py):
- particle pieces: clusters of at least 50 particles linked closer than 1.5 lattice spacings, and
  the share of particles outside them (loose);
- picture bodies: pieces of the coarse render's solid picture (alpha >= 0.5) of at least 5 % of the
  body's picture at rest, and the pixels in smaller pieces (dust);
- see-through: of the pixels whose ray passes through the particles' occupancy (eroded by half a
  spacing), the share the coarse render leaves under alpha 0.5.
Each folder's table goes to benchmarks/results/tearing_<folder name>.json, and RESULTS.md is regenerated.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np

from benchmarks.figures import add_arguments, invocation, write_figures
from schemas.artifacts import CoarseArtifact, GaussiansArtifact, TrajectoriesArtifact, read_artifact
from tests.render_enhance.test_render_interior import bodies, lattice_spacing_of, occupancy
from tests.simulate.test_simulate_physics import cluster_sizes

SAMPLES = 9  # frames printed per scene, first and last included


def particle_pieces(positions: np.ndarray, spacing: float) -> tuple[int, float]:
    """(pieces of at least 50 particles, fraction of the particles outside them)."""
    sizes = cluster_sizes(positions, 1.5 * spacing)
    return int((sizes >= 50).sum()), float(sizes[sizes < 50].sum() / len(positions))


COLUMNS = ["t s", "particle pieces", "loose %", "picture bodies", "dust px", "see-through %"]


def measure(folder: str) -> tuple[str, list[list]]:
    """Print the table of one results folder; return what was measured and the rows."""
    gaussians = read_artifact(f"{folder}/gaussians.h5", GaussiansArtifact)
    trajectories = read_artifact(f"{folder}/trajectories.h5", TrajectoriesArtifact)
    coarse = read_artifact(f"{folder}/coarse.h5", CoarseArtifact)
    rotation, translation = gaussians.world_to_camera[:3, :3], gaussians.world_to_camera[:3, 3]
    camera_positions = trajectories.positions.astype(np.float64) @ rotation.T + translation
    spacing = lattice_spacing_of(trajectories)
    half_px = int(np.ceil(spacing / 2 * coarse.K[0, 0] / camera_positions[..., 2].min()))
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * half_px + 1, 2 * half_px + 1))
    rest_px = int((coarse.alpha[0] >= 0.5).sum())
    subject = (f"{len(trajectories.volumes)} particles of which {int(trajectories.is_gaussian.sum())} Gaussians, "
               f"spacing {1e3 * spacing:.2f} mm, {rest_px} px at rest")
    print(f"\n{folder}: {subject}\n")
    print("| " + " | ".join(COLUMNS) + " |")
    print("| " + " | ".join("---" for _ in COLUMNS) + " |")
    rows = []
    for t in np.unique(np.linspace(0, len(trajectories.time_s) - 1, SAMPLES).round().astype(int)):
        count, loose = particle_pieces(camera_positions[t], spacing)
        picture, dust = bodies(coarse.alpha[t], rest_px // 20)
        F = np.einsum("ij,njk,lk->nil", rotation, trajectories.F[t].astype(np.float64), rotation)
        material = occupancy(camera_positions[t], F, trajectories.volumes, coarse.K, coarse.alpha.shape[1:])
        material = cv2.erode(material.astype(np.uint8), disc) > 0
        see_through = 100 * float((coarse.alpha[t][material] < 0.5).mean()) if material.any() else float("nan")
        rows.append([f"{trajectories.time_s[t]:.2f}", count, f"{100 * loose:.2f}", picture, dust, f"{see_through:.2f}"])
        print("| " + " | ".join(str(c) for c in rows[-1]) + " |", flush=True)
    return subject, rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("folders", nargs="+")
    add_arguments(parser)
    args = parser.parse_args()
    for folder in args.folders:
        subject, rows = measure(folder)
        if not args.no_figures:
            name = Path(folder).resolve().name
            write_figures(
                f"tearing_{name}", f"Tearing: {name}",
                f"""The workflow's results of scene {name} ({subject}) measured per sampled frame with the tests'
                own measures: particle pieces (clusters of at least 50 particles linked closer than 1.5 lattice
                spacings) and the share of particles outside them (loose); picture bodies (pieces of the coarse
                render's solid picture, alpha >= 0.5, of at least 5 % of the body's picture at rest) and the pixels
                in smaller pieces (dust); see-through, the share of the pixels whose ray passes through the
                particles' occupancy that the render leaves under alpha 0.5.""",
                invocation(__file__), COLUMNS, rows)


if __name__ == "__main__":
    main()
