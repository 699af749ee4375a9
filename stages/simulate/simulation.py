"""From Gaussians and a scene's physics to per-frame particle trajectories.

`Simulation` builds the particles (the G Gaussians first, then each object's
interior fill), the simulation frame and grid, the materials, conditions and
rigid bodies, then `run` steps the MPM solver frame by frame with CFL substeps
and records positions, the Gaussians' deformation gradients and diagnostics,
all in the world (camera) frame.
"""
from __future__ import annotations

import logging
import math
import time
from pathlib import Path

import numpy as np
import warp as wp

from schemas import InputError
from schemas.artifacts import TrajectoriesArtifact
from schemas.materials import PRESETS

from . import domain
from .conditions import Conditions
from .constitutive import elastic_energy, wave_speed
from .fill import fill_object
from .mpm import BOUNDARY_NODES, GROUND_NONE, GROUND_TYPES, Ground, MPMSolver
from .rigid import RigidBodies

log = logging.getLogger("physmotion.simulate")

# A particle faster than this many times the fastest physically expected speed
# (elastic wave + conditions + free fall over the whole run) means the explicit
# integration has blown up.
BLOW_UP_FACTOR = 10.0


class Simulation:
    """One scene's simulation.

    Args:
        physics: scene.physics (schemas.scene.PhysicsConfig).
        materials: one preset model per object (scene.objects[k].material).
        means: (G,3) Gaussian centres, world frame, m.
        object_id: (G,) object index k of each Gaussian.
        pitch_deg: camera.pitch_deg, turns the default gravity.
        scene_file: named in error messages.
        device: Warp device ("cpu", "cuda:0").
    """

    def __init__(self, physics, materials: list, means: np.ndarray, object_id: np.ndarray, *,
                 pitch_deg: float = 0.0, scene_file: Path | str = "scene.yaml", device: str = "cpu"):
        self.physics, self.materials, self.scene_file, self.device = physics, list(materials), scene_file, device
        means = np.asarray(means, np.float64)
        object_id = np.asarray(object_id, np.int64)
        if object_id.min(initial=0) < 0 or object_id.max(initial=0) >= len(self.materials):
            raise InputError(scene_file, "objects", f"the Gaussians name objects up to {object_id.max()} but the "
                             f"scene lists {len(self.materials)}", "rerun pm-reconstruct with this scene")
        for k in range(len(self.materials)):
            if not np.any(object_id == k):
                raise InputError(scene_file, f"objects[{k}]", "the reconstruction has no Gaussian for this object",
                                 "check the object's mask or box and rerun pm-reconstruct")
        self.gravity_world = domain.world_gravity(physics.gravity, pitch_deg)
        self.Q = domain.simulation_rotation(domain.down_direction(self.gravity_world, pitch_deg))
        g = float(np.linalg.norm(self.gravity_world))
        velocities = np.array([c.velocity for c in physics.conditions if c.type in ("impulse", "velocity")],
                              dtype=np.float64).reshape(-1, 3)
        self.speed_hint = float(np.max(np.linalg.norm(velocities, axis=1), initial=0.0))
        fit = dict(gravity=g, duration_s=physics.duration_s, velocities=velocities @ self.Q.T,
                   ground=physics.ground.enabled, walls=physics.walls)

        # the cell size comes from the Gaussians; the final grid also covers the fill
        means_sim = means @ self.Q.T
        dx = domain.fit_grid(means_sim, physics.grid, **fit).dx
        fills, gauss_volume = [], np.zeros(len(means))
        for k in range(len(self.materials)):
            sel = object_id == k
            # The fill lattice is laid in the simulation frame, its layers parallel to the ground: a
            # lattice along the camera's axes meets a pitched ground with a staircase that lands on
            # one side first and spins the body (tests/simulate: a sphere on slip ground).
            fill, gauss_volume[sel], fill_volume = fill_object(means_sim[sel], dx, physics.particles_per_cell)
            fills.append((fill @ self.Q, fill_volume, k))
        self.rest_world = np.concatenate([means] + [f for f, _, _ in fills])
        self.volumes = np.concatenate([gauss_volume] + [v for _, v, _ in fills])
        self.object_id = np.concatenate([object_id] + [np.full(len(f), k) for f, _, k in fills])
        self.n_gaussians = len(means)
        density = np.array([m.density for m in self.materials])
        self.masses = density[self.object_id] * self.volumes
        self.material_id = np.array([PRESETS.index(m.preset) for m in self.materials])[self.object_id]

        rest_sim = self.rest_world @ self.Q.T
        self._size = float(np.max(rest_sim.max(0) - rest_sim.min(0)))
        self.grid = domain.fit_grid(rest_sim, physics.grid, **fit)
        ground = physics.ground
        self.ground = Ground(GROUND_TYPES[ground.type] if ground.enabled else GROUND_NONE, ground.friction)
        self.ground_y = self.grid.origin[1] + BOUNDARY_NODES * self.grid.dx  # sim frame height of the ground
        self.solver = MPMSolver(self.grid, rest_sim, self.masses, self.volumes, self.object_id, self.materials,
                                self.Q @ self.gravity_world, self.ground, device=device)
        rigid = [k for k, m in enumerate(self.materials) if m.preset == "rigid"]
        if rigid:
            self.solver.rigid = RigidBodies(rest_sim, self.masses, self.object_id, rigid,
                                            self.ground_y if ground.enabled else -math.inf, device)
        self.conditions = Conditions(physics.conditions, self.rest_world, self.object_id, self.masses, self.Q,
                                     device, scene_file)
        self._energy = wp.zeros(len(self.masses), dtype=float, device=device)
        self._warned_walls = False
        self.wave_speed = max(wave_speed(m) for m in self.materials)
        self.n_frames = int(round(physics.duration_s * physics.fps)) + 1
        log.info("%d particles (%d Gaussians + %d fill), grid %s of %.1f mm cells, %d frames",
                 len(self.masses), self.n_gaussians, len(self.masses) - self.n_gaussians,
                 "x".join(map(str, self.grid.shape)), 1e3 * self.grid.dx, self.n_frames)

    def substep_size(self, max_speed: float) -> float:
        """physics.dt, or the CFL substep for particles up to max_speed (m/s) plus a frame of free fall."""
        if self.physics.dt is not None:
            return self.physics.dt
        fall = float(np.linalg.norm(self.gravity_world)) / self.physics.fps
        return domain.cfl_substep(self.grid.dx, self.materials, max_speed + self.speed_hint + fall)

    def run(self) -> TrajectoriesArtifact:
        """Simulate the whole duration; returns the trajectories artifact (world frame)."""
        T, G, P = self.n_frames, self.n_gaussians, len(self.masses)
        positions = np.zeros((T, P, 3), np.float32)
        F = np.zeros((T, G, 3, 3), np.float32)
        diag = {k: np.zeros((T,) + s) for k, s in [("kinetic_energy", ()), ("potential_energy", ()), ("momentum", (3,)),
                                                   ("angular_momentum", (3,)), ("max_speed", ()), ("substeps", ())]}
        times = np.arange(T) / self.physics.fps
        self._record(0, positions, F, diag)
        t, started = 0.0, time.perf_counter()
        for f in range(1, T):
            dt = self.substep_size(float(diag["max_speed"][f - 1]))
            n = max(1, math.ceil((times[f] - t) / dt - 1e-9))
            h = (times[f] - t) / n
            for _ in range(n):
                self.conditions.before_substep(t, self.solver)
                self.solver.substep(h)
                t += h
            t = times[f]
            diag["substeps"][f] = n
            self._record(f, positions, F, diag)
            self._check(f, h, positions[f], diag["max_speed"][f])
            log.info("frame %d/%d  t=%.3f s  %d substeps of %.2e s  max speed %.2f m/s  (%.0f s elapsed)",
                     f, T - 1, t, n, h, diag["max_speed"][f], time.perf_counter() - started)
        self.solver.close()
        return TrajectoriesArtifact(
            rest_positions=self.rest_world, volumes=self.volumes, masses=self.masses, material_id=self.material_id,
            object_id=self.object_id, is_gaussian=np.arange(P) < G, positions=positions, F=F, time_s=times,
            fps=float(self.physics.fps), duration_s=float(self.physics.duration_s), **diag)

    def _record(self, f: int, positions: np.ndarray, F: np.ndarray, diag: dict) -> None:
        """Store frame f: world positions, world F of the Gaussians, and the diagnostics."""
        s = self.solver
        x_sim = s.x.numpy().astype(np.float64)
        v = s.v.numpy().astype(np.float64) @ self.Q  # world = Q^T sim, for row vectors
        x = x_sim @ self.Q
        positions[f] = x
        F[f] = self.Q.T @ s.F.numpy()[: self.n_gaussians] @ self.Q
        m = self.masses
        wp.launch(elastic_energy, dim=len(m), device=self.device,
                  inputs=[s.materials, s.object_id, s.volume, s.F, s.history, self._energy])
        height = x_sim[:, 1] - self.ground_y
        diag["kinetic_energy"][f] = 0.5 * np.sum(m * np.sum(v * v, axis=1))
        diag["potential_energy"][f] = (np.linalg.norm(self.gravity_world) * np.sum(m * height)
                                       + np.sum(self._energy.numpy(), dtype=np.float64))
        diag["momentum"][f] = m @ v
        diag["angular_momentum"][f] = m @ np.cross(x, v)
        diag["max_speed"][f] = np.sqrt(np.max(np.sum(v * v, axis=1))) if len(v) else 0.0
        self._warn_at_walls(f, x_sim)

    def _warn_at_walls(self, f: int, x_sim: np.ndarray) -> None:
        """Say once when particles reach the domain's edge (mpm.grid_to_particle holds them there)."""
        g = self.grid
        lo = np.asarray(g.origin) + BOUNDARY_NODES * g.dx
        hi = np.asarray(g.origin) + (np.asarray(g.shape) - 1 - BOUNDARY_NODES) * g.dx
        tol = 1e-3 * g.dx
        at_low = x_sim <= lo + tol
        at_low[:, 1] &= self.ground.kind == GROUND_NONE  # resting on the ground is not leaving the domain
        n = int(np.count_nonzero(np.any(at_low | (x_sim >= hi - tol), axis=1)))
        if n and not self._warned_walls:
            self._warned_walls = True
            log.warning("frame %d: %d particles reached the edge of the simulation domain and are held there; "
                        "the objects travel farther than %.2f m from where they start (twice their size): "
                        "shorten physics.duration_s or weaken the conditions", f, n, 2 * self._size)

    def _check(self, f: int, h: float, x: np.ndarray, max_speed: float) -> None:
        """Stop with a message naming the frame, the object and the likely fix when the run blew up."""
        v = self.solver.v.numpy()
        bad = ~(np.isfinite(x).all(axis=1) & np.isfinite(v).all(axis=1))
        limit = BLOW_UP_FACTOR * (self.wave_speed + self.speed_hint
                                  + np.linalg.norm(self.gravity_world) * self.physics.duration_s)
        if not bad.any() and max_speed <= limit:
            return
        p = int(np.argmax(bad)) if bad.any() else int(np.argmax(np.sum(v * v, axis=1)))
        k = int(self.object_id[p])
        what = "non-finite positions (NaN)" if bad.any() else f"a particle at {max_speed:.3g} m/s (limit {limit:.3g})"
        raise InputError(self.scene_file, f"objects[{k}].material",
                         f"the simulation blew up at frame {f} (t = {f / self.physics.fps:.3f} s): object {k} "
                         f"({self.materials[k].preset}) has {what} with substeps of {h:.2e} s",
                         "lower its youngs_modulus or raise its density, set physics.dt below "
                         f"{0.5 * h:.1e} s, or soften the conditions acting on it")
