"""From Gaussians and a scene's physics to per-frame particle trajectories.

`Simulation` builds the particles (the G Gaussians first, then each object's
interior fill), the simulation frame, the ground through the objects' lowest
point and the one grid, the materials, conditions and rigid bodies; `run` first
settles the deformable bodies whose weight the grid resolves into the stress
that holds their photographed shape up (rest_state.py), then steps the MPM solver frame by frame with CFL
substeps and records positions, every particle's deformation gradient and
diagnostics, all in the world (camera) frame.
"""
from __future__ import annotations

import logging
import math
import os
import time
from pathlib import Path

import numpy as np
import warp as wp

from schemas import InputError
from schemas.artifacts import TrajectoriesArtifact
from schemas.camera import project_points
from schemas.materials import PRESETS

from . import domain, rest_state
from .conditions import Conditions, inertia_about_centre, largest_acceleration
from .constitutive import deformation_since_rest, elastic_energy, wave_speed
from .fill import fill_object, fill_solid, lattice_spacing
from .mpm import GROUND_NONE, GROUND_TYPES, Ground, MPMSolver
from .quasi_static import RELAXED, QuasiStatic
from .rigid import RigidBodies

log = logging.getLogger("physmotion.simulate")

# A particle faster than this many times the fastest physically expected speed
# (elastic wave + conditions + free fall over the whole run) means the explicit
# integration has blown up.
BLOW_UP_FACTOR = 10.0
# A frame in which every body is carried and no particle that carries mass moved more than this share of
# a cell, nor more than in the frame before, is at rest: while no condition acts, the next frame is the
# same (docs/decisions/0021-frames-at-rest.md, 0034-rest-judged-on-mass.md).
QUIET_CELLS = 0.05
# ... where each object's motion is the largest but that of this share of its particles, its fastest: a few
# grains of a heap that has stopped, at the grid's edge, are pushed off it by the unbalanced pressure of the
# sand beyond, which flies freely and no longer scatters to the grid
# (docs/decisions/0039-granular-substeps.md). A body of fewer than 1 / RESTLESS_SHARE particles sets none aside.
RESTLESS_SHARE = 1.0e-4
# The settle says how far it has come this often, in seconds.
SETTLE_LOG_EVERY_S = 10.0
# The grid follows the particles with this many free cells inside its wall layers.
FOLLOW_MARGIN_CELLS = 2


def mass_properties(masses: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(centre of mass (3,) m, sorted principal moments of inertia about it (3,) kg m^2) of point masses
    (P,) kg at points (P,3) m."""
    centre, inertia = inertia_about_centre(points, masses)
    return centre, np.linalg.eigvalsh(inertia)


class Simulation:
    """One scene's simulation.

    Args:
        physics: scene.physics (schemas.scene.PhysicsConfig).
        materials: one preset model per object (scene.objects[k].material).
        means: (G,3) Gaussian centres, world frame, m.
        object_id: (G,) object index k of each Gaussian.
        pitch_deg: camera.pitch_deg, turns the default gravity.
        silhouette: (mask (H,W) u8 with k + 1 for object k, K (3,3)) of the photograph, world = its camera
            frame: the particles that leave its view are named; None: none are.
        solids: per object its solid (schemas.solid.SolidGrid, gaussians.h5's /objects/solid), which its
            particles fill, the Gaussians riding on it without mass; None (for all or one object): the
            solid the Gaussians' means enclose (fill.fill_object), which they share.
        scene_file: named in error messages.
        device: Warp device ("cpu", "cuda:0").
    """

    def __init__(self, physics, materials: list, means: np.ndarray, object_id: np.ndarray, *,
                 pitch_deg: float = 0.0, silhouette: tuple | None = None, solids: list | None = None,
                 scene_file: Path | str = "scene.yaml", device: str = "cpu"):
        self.physics, self.materials, self.scene_file, self.device = physics, list(materials), scene_file, device
        means = np.asarray(means, np.float64)
        object_id = np.asarray(object_id, np.int64)
        if object_id.min(initial=0) < 0 or object_id.max(initial=0) >= len(self.materials):
            raise InputError(scene_file, "objects", f"the Gaussians name objects up to {object_id.max()} but the "
                             f"scene lists {len(self.materials)}", "rerun pm-reconstruct with this scene")
        if solids is not None and len(solids) != len(self.materials):
            raise InputError(scene_file, "objects", f"the reconstruction gives the solids of {len(solids)} "
                             f"object(s) but the scene lists {len(self.materials)}", "rerun pm-reconstruct with this scene")
        for k in range(len(self.materials)):
            if not np.any(object_id == k):
                raise InputError(scene_file, f"objects[{k}]", "the reconstruction has no Gaussian for this object",
                                 "check the object's mask or box and rerun pm-reconstruct")
        self.gravity_world = domain.world_gravity(physics.gravity, pitch_deg)
        self.Q = domain.simulation_rotation(domain.down_direction(self.gravity_world, pitch_deg))
        self.gravity_frame = domain.gravity_frame(self.Q)
        moving = [c for c in physics.conditions if c.type in ("impulse", "velocity")]
        speeds = np.array([np.linalg.norm(c.velocity) for c in moving], dtype=np.float64)  # m/s, in any frame
        # m/s, per object: the fastest its own conditions set it moving
        self._object_speeds = [float(np.max(speeds[[c.object == k for c in moving]], initial=0.0))
                               for k in range(len(self.materials))]
        self.speed_hint = max(self._object_speeds)
        ground = physics.ground

        # the cell size comes from the Gaussians, the one grid is laid over the whole solid they fill
        means_sim = means @ self.Q.T
        dx = domain.cell_size(means_sim, physics.grid, ground=ground.enabled, walls=physics.walls)
        self.spacing = spacing = lattice_spacing(dx, physics.particles_per_cell)
        fills, gauss_volume = self._fill_objects(means_sim, object_id, dx, solids or [None] * len(self.materials))
        self.rest_world = np.concatenate([means] + [f for f, _, _ in fills])
        self.volumes = np.concatenate([gauss_volume] + [v for _, v, _ in fills])
        self.object_id = np.concatenate([object_id] + [np.full(len(f), k) for f, _, k in fills])
        self.n_gaussians = len(means)
        density = np.array([m.density for m in self.materials])
        self.masses = density[self.object_id] * self.volumes
        self.material_id = np.array([PRESETS.index(m.preset) for m in self.materials])[self.object_id]
        self._carries_mass = self.masses > 0  # the massless Gaussians ride on the grid velocity of these

        self.rest_sim = rest_sim = self.rest_world @ self.Q.T
        self._size = float(np.max(rest_sim.max(0) - rest_sim.min(0)))
        # the ground: the plane, normal to gravity, through the objects' lowest particle that carries mass;
        # they stand on their base
        self.ground_y = float(rest_sim[self.masses > 0, 1].min()) if ground.enabled else None
        largest = np.argmax(np.bincount(object_id))
        box = means_sim[object_id == largest]
        self.grid = domain.fit_grid(rest_sim, dx, ground_y=self.ground_y, walls=physics.walls,
                                    centre=0.5 * (box.min(axis=0) + box.max(axis=0)))
        self.ground = (Ground(GROUND_TYPES[ground.type], ground.friction, self.ground_y)
                       if ground.enabled else Ground(GROUND_NONE))
        # potential energy is measured from the ground, else from the grid's starting floor
        self._height_zero = self.ground_y if ground.enabled else self.grid.origin[1]
        # the CFL substep follows snow's hardening, unless physics.dt fixes the substep
        self.solver = MPMSolver(self.grid, rest_sim, self.masses, self.volumes, self.object_id, self.materials,
                                self.Q @ self.gravity_world, self.ground, walls=physics.walls, device=device,
                                follow_hardening=physics.dt is None)
        rigid = {k: m for k, m in enumerate(self.materials) if m.preset == "rigid"}
        if rigid:  # points within half a lattice spacing of the ground touch it
            self.solver.attach_rigid(RigidBodies(rest_sim, self.masses, self.object_id, rigid, self.ground,
                                                 0.5 * spacing, device))
        self.conditions = Conditions(physics.conditions, self.rest_world, self.object_id, self.masses, self.Q,
                                     self.gravity_frame, device, scene_file)
        self._pushes = self._condition_pushes()
        self._energy = wp.zeros(len(self.masses), dtype=float, device=device)
        self._free_logged = self._outside_logged = 0
        self._camera = None if silhouette is None else (silhouette[1], silhouette[0].shape)  # K, (H, W)
        # each particle's F at rest, inverted: settle() sets it where it loaded a body
        eye = np.broadcast_to(np.eye(3, dtype=np.float32), (len(self.masses), 3, 3))
        self._rest_F_inverse = wp.array(eye, dtype=wp.mat33, device=device)
        self._world_F = wp.empty_like(self._rest_F_inverse)
        self.settled: rest_state.Settled | None = None  # what run()'s settle found
        self.wave_speed = max(wave_speed(m) for m in self.materials)
        self.n_frames = int(round(physics.duration_s * physics.fps)) + 1
        log.info("%d particles (%d Gaussians + %d fill), grid %s of %.1f mm cells, %d frames",
                 len(self.masses), self.n_gaussians, len(self.masses) - self.n_gaussians,
                 "x".join(map(str, self.grid.shape)), 1e3 * self.grid.dx, self.n_frames)
        self._log_bodies(rest_sim)
        self._check_budget()

    def _fill_objects(self, means_sim: np.ndarray, object_id: np.ndarray, dx: float, solids: list
                      ) -> tuple[list, np.ndarray]:
        """Each object's interior: [(fill (N,3) world m, fill volumes (N,) m^3, object)], and the Gaussians'
        volumes (G,) m^3. An object with a solid (schemas.solid.SolidGrid) fills it (fill.fill_solid) and its
        Gaussians carry no volume; one without fills what its means enclose (fill.fill_object), its
        Gaussians sharing the volume. means_sim: (G,3) the means in the simulation frame, m."""
        per_cell = self.physics.particles_per_cell
        fills, gauss_volume = [], np.zeros(len(means_sim))
        for k in range(len(self.materials)):
            sel = object_id == k
            # The fill lattice is laid in the simulation frame, its layers parallel to the ground: a
            # lattice along the camera's axes meets a pitched ground with a staircase that lands on
            # one side first and spins the body (tests/simulate: a sphere on slip ground).
            if solids[k] is not None:
                fill, volumes = fill_solid(solids[k], self.Q, lattice_spacing(dx, per_cell))
                log.info("object %d: its solid filled by %d particles holding %.4g m^3", k, len(fill),
                         volumes.sum())
            else:
                solid = fill_object(means_sim[sel], dx, per_cell)
                gauss_volume[sel] = solid.volume[:int(sel.sum())]
                fill, volumes = solid.fill, solid.volume[int(sel.sum()):]
            fills.append((fill @ self.Q, volumes, k))
        return fills, gauss_volume

    def _check_budget(self) -> None:
        """Refuse, before any work, a run whose substeps or recorded frames cannot be afforded; log the estimate."""
        physics = self.physics
        if physics.dt is not None:
            bound = self._cfl_substep(0.0)
            if min(physics.dt, 1.0 / physics.fps) > bound * (1.0 + 1e-9):
                raise InputError(self.scene_file, "physics.dt",
                                 f"{physics.dt:g} s is above this scene's CFL bound, {bound:.2e} s (a {1e3 * self.grid.dx:.3g}"
                                 " mm cell over its fastest elastic wave, its conditions' speeds and a frame of their "
                                 "forces and free fall), where the explicit solver blows up",
                                 f"set physics.dt to {float(f'{0.9 * bound:.1e}'):.1e} s or less, or remove it to "
                                 "let the CFL bound choose each substep")
        per_frame = math.ceil(1.0 / (physics.fps * self.substep_size(0.0)) - 1e-9)
        total = per_frame * (self.n_frames - 1)
        if per_frame > physics.max_substeps_per_frame:
            raise InputError(self.scene_file, self._substep_cause(),
                             f"the CFL bound asks for {per_frame} substeps per frame ({total:.3g} in all) before "
                             f"anything moves, above physics.max_substeps_per_frame = "
                             f"{physics.max_substeps_per_frame}", self._substep_fix())
        frames_bytes = 4 * 12 * self.n_frames * len(self.masses)  # positions and F, float32, every frame
        available = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
        if frames_bytes > 0.5 * available:
            raise InputError(self.scene_file, "physics.duration_s",
                             f"{self.n_frames} frames of {len(self.masses)} particles need "
                             f"{frames_bytes / 2 ** 30:.1f} GiB, more than half of this machine's "
                             f"{available / 2 ** 30:.0f} GiB", "shorten physics.duration_s, lower physics.fps, or "
                             "lower physics.particles_per_cell or physics.grid")
        log.info("about %d substeps per frame at rest (%d in all; more while things move fast), %.2f GiB of frames",
                 per_frame, total, frames_bytes / 2 ** 30)
        self.substeps_at_rest = total

    def _substep_cause(self) -> str:
        """The scene key that sets the substep: physics.dt, a condition's velocity or force, gravity (a frame of
        free fall), or the stiffest material."""
        if self.physics.dt is not None:
            return "physics.dt"
        speeds = [wave_speed(m) for m in self.materials]
        k = int(np.argmax(speeds))
        causes = {f"objects[{k}].material.youngs_modulus": speeds[k], "physics.conditions": max(
            self.speed_hint, self.conditions.acceleration / self.physics.fps),
            "physics.gravity": float(np.linalg.norm(self.gravity_world)) / self.physics.fps}
        return max(causes, key=causes.get)

    def _substep_fix(self) -> str:
        cause = self._substep_cause()
        if cause == "physics.dt":
            return "raise physics.dt (or remove it to use the CFL bound)"
        if cause == "physics.conditions":
            return "lower the conditions' velocities and forces"
        if cause == "physics.gravity":
            return ("give physics.gravity a magnitude nearer 9.81 m/s^2 (a frame of free fall sets the substep), "
                    "or raise physics.max_substeps_per_frame if you mean it")
        material = self.materials[int(cause.split("[")[1].split("]")[0])]
        # a substep is CFL dx / (wave + other speeds) and the wave grows as sqrt(E): the largest E whose wave
        # fits the limit's substep beside the same other speeds, with a twentieth to spare; named only where
        # this material's wave is the one the substep follows and lowering it alone can fit the limit
        waves = [wave_speed(m, self.solver.stiffening) for m in self.materials]
        wave = wave_speed(material, self.solver.stiffening)
        others = domain.CFL * self.grid.dx / self.substep_size(0.0) - wave
        longest_wave = self.physics.max_substeps_per_frame * self.physics.fps * domain.CFL * self.grid.dx
        fitting_wave = 0.95 * longest_wave - others
        lower = "lower that youngs_modulus"
        if wave >= max(waves) and fitting_wave > 0:
            lower += f" to {float(f'{material.youngs_modulus * (fitting_wave / wave) ** 2:.1e}'):.1e} Pa or less"
        return (f"{lower}, or raise its density (the elastic wave speed sqrt(E / density) sets the substep), "
                "lower physics.grid, or raise physics.max_substeps_per_frame if you mean it")

    def _log_bodies(self, rest_sim: np.ndarray) -> None:
        """Each object's mass, volume and principal moments of inertia about its centre of mass; and the
        warnings of a body its weight crushes or no support holds (rest_state.warn_*)."""
        if self.ground_y is not None:
            log.info("the ground lies through the objects' lowest point")
        g = float(np.linalg.norm(self.gravity_world))
        for k, material in enumerate(self.materials):
            sel = self.object_id == k
            m, x = self.masses[sel], rest_sim[sel]
            centre, moments = mass_properties(m, x)
            log.info("object %d (%s): mass %.4g kg, volume %.4g m^3, principal moments %s kg m^2", k,
                     material.preset, m.sum(), self.volumes[sel].sum(), ", ".join(f"{i:.3g}" for i in moments))
            rest_state.warn_crushed_by_weight(k, material, float(np.ptp(x[:, 1])), g)
            rest_state.warn_dented_by_impact(k, material, self._object_speeds[k])
            if self.ground_y is not None:
                rest_state.warn_unsupported(k, x, centre, self.ground_y, self.spacing)

    def substep_size(self, max_speed: float, since: float = 0.0, until: float = math.inf) -> float:
        """physics.dt, or the CFL substep for particles up to max_speed (m/s) over since .. until (s)."""
        return self.physics.dt if self.physics.dt is not None else self._cfl_substep(max_speed, since, until)

    def _cfl_substep(self, max_speed: float, since: float = 0.0, until: float = math.inf) -> float:
        """The CFL substep in s for particles up to max_speed (m/s), what a condition acting between since and
        until (s; by default the whole run) may give them, and a frame of free fall and of those conditions'
        forces; at most a frame. A condition outside the window adds nothing: what it set moving before,
        max_speed holds. Snow's wave is that of the hardening its stress may reach in the next substep
        (MPMSolver.stiffening)."""
        speed, acceleration = 0.0, 0.0
        for start, end, kick, push in self._pushes:
            if start <= until and (end is None or end >= since):
                speed, acceleration = max(speed, kick), max(acceleration, push)
        fall = (float(np.linalg.norm(self.gravity_world)) + acceleration) / self.physics.fps
        return domain.cfl_substep(self.grid.dx, self.materials, max_speed + speed + fall, 1.0 / self.physics.fps,
                                  self.solver.stiffening)

    def _condition_pushes(self) -> list[tuple[float, float | None, float, float]]:
        """(start s, end s (None: to the end; an impulse's is its start), speed m/s it gives, largest acceleration
        m/s^2 it gives, conditions.largest_acceleration) of each condition."""
        pushes = []
        for item in self.conditions.items:
            c = item.condition
            speed = float(np.linalg.norm(c.velocity)) if c.type in ("impulse", "velocity") else 0.0
            body = self.rest_world[self.object_id == c.object]
            push = largest_acceleration(c, self.Q.T @ item.to_sim, self.rest_world[item.members],
                                        self.masses[item.members], body)
            pushes.append((c.start_s, c.start_s if c.type == "impulse" else getattr(c, "end_s", None), speed, push))
        return pushes

    def _lifted(self) -> np.ndarray:
        """Boolean (objects,) of the objects that an impulse or velocity at t = 0 lifts off the ground: their
        mean upward start speed (simulation frame) is more than a frame of free fall gives back."""
        up = np.zeros(len(self.materials))
        for item in self.conditions.items:
            c = item.condition
            if c.type in ("impulse", "velocity") and c.start_s <= 0.0:
                speed = float((item.to_sim @ np.asarray(c.velocity, np.float64))[1])
                np.add.at(up, self.object_id[item.members], self.masses[item.members] * speed)
        mass = np.bincount(self.object_id, self.masses, minlength=len(self.materials))
        return up / mass > float(np.linalg.norm(self.gravity_world)) / self.physics.fps

    def _settle_plan(self) -> tuple[list[int], dict[int, str], np.ndarray]:
        """(the deformable objects on the ground or held at t = 0 that settle, {object: why not} for the others
        of them (rest_state.why_not_settled), (P,) bool of the particles a fixed condition holds)."""
        held = self.conditions.fixed_at_start()
        loaded = {int(k) for k in np.unique(self.object_id[held])}
        if self.ground_y is not None:
            loaded |= {int(k) for k in np.unique(self.object_id[self.rest_sim[:, 1] <= self.ground_y + self.grid.dx])}
        held_objects = {int(k) for k in np.unique(self.object_id[held])}
        lifted = self._lifted()
        g = float(np.linalg.norm(self.gravity_world))
        settling, skipped = [], {}
        for k in sorted(loaded):
            if self.materials[k].preset == "rigid":
                continue
            height = float(np.ptp(self.rest_sim[self.object_id == k, 1]))
            why = rest_state.why_not_settled(self.materials[k], height, self.grid.dx, g,
                                             bool(lifted[k]) and k not in held_objects)
            if why is None:
                settling.append(k)
            else:
                skipped[k] = why
        return settling, skipped, held

    def settle(self) -> rest_state.Settled:
        """Find the stress under which the deformable bodies stand as photographed (rest_state.py); returns
        what it found.

        The bodies that touch the ground or are held by a `fixed` condition at t = 0 and need it
        (rest_state.why_not_settled) take up their own weight by kinetic damping (quasi_static.QuasiStatic),
        every particle pinned at its rest position while its velocity and F evolve; all others are held
        still meanwhile. Then every particle is at rest, keeping the elastic F and history of the settled
        bodies.
        """
        s, rest_sim = self.solver, self.rest_sim
        deformable, skipped, held = self._settle_plan()
        for k, why in skipped.items():
            log.info("object %d starts unstressed, not settled: %s", k, why)
        result = rest_state.Settled(skipped=skipped)
        if not deformable:
            return result
        extents = [np.ptp(rest_sim[self.object_id == k], axis=0) for k in deformable]
        period = max(rest_state.fundamental_period(self.materials[k], float(e[1]), float(min(e[0], e[2])))
                     for k, e in zip(deformable, extents))
        still = held | ~np.isin(self.object_id, deformable)
        s.prescribed.assign(still.astype(np.int32))
        s.prescribed_velocity.zero_()
        dt = self._cfl_substep(0.0)  # even under a physics.dt: a dt that blows up is the run's to report
        s.hold_yield(True)  # the photographed solid stands on its elastic stress; where that is past yield, the run yields
        s.pin(True)
        bodies = [np.flatnonzero(self.object_id == k) for k in deformable]
        relaxation = QuasiStatic(s, rest_sim, bodies)
        # a held body cannot fall: only the free ones can be footless
        can_fall = [k for k in deformable if not np.any(held[self.object_id == k])]
        per_period = period / dt
        most = max(1, math.ceil(min(rest_state.SETTLE_PERIODS * per_period,
                                    rest_state.SETTLE_SHARE * self.substeps_at_rest)))
        g = float(np.linalg.norm(self.gravity_world))
        log.info("settling objects %s into their weight: at most %d substeps (%.2f s of relaxation, %.0f %% of the "
                 "run's %d)", deformable, most, most * dt, 100 * most / max(self.substeps_at_rest, 1),
                 self.substeps_at_rest)
        started = reported = time.perf_counter()
        steps, footless = 0, False
        relaxation_s = 0.0
        while steps < most:
            s.substep(dt)
            steps += 1
            relaxation_s += dt
            if relaxation.step(s, dt):
                break
            if s.hardening_followed:
                dt = self._cfl_substep(0.0)
            if can_fall and relaxation.peaks == 0 and relaxation_s > rest_state.FOOTLESS_PERIODS * period:
                footless = True  # still falling, pinned: its contact cannot carry it as photographed
                break
            if time.perf_counter() - reported > SETTLE_LOG_EVERY_S:
                reported = time.perf_counter()
                per_step = (reported - started) / steps
                log.info("settling: %d of at most %d substeps, %d kinetic peaks, the last %.1e of the first (stops "
                         "below %.0e), %.0f s elapsed, ~%.0f s left at the peaks' rate (at most %.0f)", steps, most,
                         relaxation.peaks, relaxation.residual, RELAXED, reported - started,
                         per_step * min(most - steps, relaxation.substeps_left()), per_step * (most - steps))
        s.pin(False)
        s.hold_yield(False)
        result.substeps, result.relaxation_s, result.wall_s = steps, relaxation_s, time.perf_counter() - started
        result.peaks, result.residual = relaxation.peaks, relaxation.residual
        if footless:
            s.reset(rest_sim, keep=np.zeros(len(rest_sim), bool))
            result.footless = can_fall
            for k in can_fall:
                rest_state.warn_footless(k, self.materials[k], rest_state.FOOTLESS_PERIODS, result.wall_s)
            return result
        settled = rest_sim + relaxation.displacement()  # the deflection the pinned particles were kept from
        result.bodies = deformable
        result.sag = float(np.max(rest_sim[:, 1] - settled[:, 1]))
        settled_F = s.F.numpy().astype(np.float64)
        for k in deformable:
            sel = self.object_id == k
            rest_state.warn_overstressed(k, self.materials[k], rest_sim[sel], settled_F[sel], self.masses[sel])
            if (relaxation.residual >= RELAXED and not np.any(held[sel])
                    and rest_state.warn_giving_way(k, self.materials[k], rest_sim[sel], settled[sel], self.masses[sel],
                                                   result.relaxation_s, g, self.grid.dx)):
                result.giving_way.append(k)
        s.reset(rest_sim, keep=np.isin(self.object_id, deformable))
        self._rest_F_inverse.assign(np.linalg.inv(s.F.numpy().astype(np.float64)).astype(np.float32))
        log.info("settled objects %s into their weight in the photographed shape: %d substeps (%.3f s, %d kinetic "
                 "peaks, the last %.1e of the first), a sag of up to %.2f mm held up (%.0f s)", deformable,
                 steps, result.relaxation_s, relaxation.peaks, relaxation.residual, 1e3 * result.sag, result.wall_s)
        log.info("the run: about %.0f s for its %d substeps at rest, at the settle's %.1f ms each",
                 self.substeps_at_rest * result.wall_s / steps, self.substeps_at_rest, 1e3 * result.wall_s / steps)
        return result

    def run(self) -> TrajectoriesArtifact:
        """Simulate the whole duration; returns the trajectories artifact (world frame)."""
        T, G, P = self.n_frames, self.n_gaussians, len(self.masses)
        positions = np.zeros((T, P, 3), np.float32)
        F = np.zeros((T, P, 3, 3), np.float32)
        diag = {k: np.zeros((T,) + s) for k, s in [("kinetic_energy", ()), ("potential_energy", ()), ("momentum", (3,)),
                                                   ("angular_momentum", (3,)), ("max_speed", ()), ("substeps", ())]}
        times = np.arange(T) / self.physics.fps
        self.settled = self.settle()
        self._record(0, positions, F, diag)
        t, started = 0.0, time.perf_counter()
        asleep = False
        for f in range(1, T):
            if self._at_rest(f - 1, positions, times):
                if not asleep:
                    log.info("frame %d/%d: at rest and nothing acts until t = %.3f s: frames copy the last one, no "
                             "substeps", f, T - 1, times[f])
                asleep = True
                positions[f], F[f] = positions[f - 1], F[f - 1]
                for k, values in diag.items():
                    values[f] = 0 if k == "substeps" else values[f - 1]
                t = times[f]
                continue
            if asleep:
                log.info("frame %d/%d: a condition acts, the simulation goes on", f, T - 1)
                asleep = False
            speed = float(diag["max_speed"][f - 1])

            def split(done: int, t: float) -> tuple[int, float, int]:
                """(frame f's substeps, `done` of them taken by t s; the length in s of those left; substeps
                between grid moves at that length). A frame of more than physics.max_substeps_per_frame
                is refused."""
                left = max(1, math.ceil((times[f] - t) / self.substep_size(speed, times[f - 1], times[f]) - 1e-9))
                if done + left > self.physics.max_substeps_per_frame:
                    raise InputError(self.scene_file, "physics.max_substeps_per_frame",
                                     f"frame {f} would take {done + left} substeps: particles reached {speed:.3g} "
                                     "m/s", "soften the conditions or the impact, or raise "
                                     "physics.max_substeps_per_frame if you mean it")
                h = (times[f] - t) / left
                return done + left, h, self._follow_every(speed, h)

            n, h, every = split(0, t)
            i, unmoved = 0, every  # unmoved: substeps since the grid last moved
            while i < n:
                if unmoved >= every:
                    self.solver.follow(FOLLOW_MARGIN_CELLS)
                    unmoved = 0
                self.conditions.before_substep(t, self.solver)
                self.solver.substep(h)
                t += h
                i, unmoved = i + 1, unmoved + 1
                if self.solver.hardening_followed and i < n:  # the rest of the frame at the snow's stiffness now
                    n, h, every = split(i, t)
            t = times[f]
            diag["substeps"][f] = n
            self._record(f, positions, F, diag)
            self._check(f, h, positions[f], diag["max_speed"][f])
            elapsed = time.perf_counter() - started
            log.info("frame %d/%d  t=%.3f s  %d substeps of %.2e s  max speed %.2f m/s  (%.0f s elapsed, ~%.0f s "
                     "left)", f, T - 1, t, n, h, diag["max_speed"][f], elapsed, elapsed / f * (T - 1 - f))
        self.solver.close()
        return TrajectoriesArtifact(
            rest_positions=self.rest_world, volumes=self.volumes, masses=self.masses, material_id=self.material_id,
            object_id=self.object_id, is_gaussian=np.arange(P) < G, positions=positions, F=F, time_s=times,
            lattice_spacing=float(self.spacing), fps=float(self.physics.fps),
            duration_s=float(self.physics.duration_s), **diag)

    def _at_rest(self, f: int, positions: np.ndarray, times: np.ndarray) -> bool:
        """Whether the world of frame f is at rest and stays so over the next frame: every object stands on the
        ground (within a cell of it) or is held by a fixed condition, or there is no gravity; over frame f no
        particle moved more than QUIET_CELLS of a cell, nor more than over the frame before (nothing is
        setting out), each object's fastest RESTLESS_SHARE of its particles set aside; and no condition acts,
        starts or ends between frame f - 1 and frame f + 1 (a fixed one holds still what it holds). A body
        slow at the top of its flight is not at rest: nothing carries it. The particles' speeds are not asked:
        a stiff body's surface particles jitter at centimetres a second over fractions of a millimetre. Only
        the particles that carry mass are asked how far they moved: the massless Gaussians push nothing and
        follow the grid's velocity about them, and a few of them at a contact, their stencils half below the
        ground, slide along it by a fit of the nodes beside them while the body stands
        (docs/decisions/0034-rest-judged-on-mass.md)."""
        if f < 2:
            return False
        if np.linalg.norm(self.gravity_world) > 0:
            carried = np.zeros(len(self.materials), bool)
            carried[self.object_id[self.conditions.fixed_at_start()]] = True
            if self.ground_y is not None:
                height = positions[f] @ self.Q[1] - self.ground_y  # simulation frame's y of each particle
                lowest = np.full(len(self.materials), np.inf)
                np.minimum.at(lowest, self.object_id, height)
                carried |= lowest <= self.grid.dx
            if not carried.all():
                return False
        since, until = times[f - 1], times[f + 1]
        for c in self.physics.conditions:
            edges = [c.start_s] + ([] if getattr(c, "end_s", None) is None else [c.end_s])
            if any(since < e <= until for e in edges):
                return False
            if c.type not in ("fixed", "impulse") and c.start_s <= until and (c.end_s is None or c.end_s > since):
                return False
        quiet = QUIET_CELLS * self.grid.dx
        moved = self._motion(positions[f] - positions[f - 1])
        before = self._motion(positions[f - 1] - positions[f - 2])
        return moved <= quiet and moved <= before

    def _motion(self, step: np.ndarray) -> float:
        """How far (m) the bodies moved by `step` (P,3) m: the largest move along an axis of a particle that
        carries mass, each object's fastest RESTLESS_SHARE of its particles set aside."""
        heavy = self._carries_mass
        along, objects = np.max(np.abs(step[heavy]), axis=1), self.object_id[heavy]
        largest = 0.0
        for k in np.unique(objects):
            moves = along[objects == k]
            aside = int(RESTLESS_SHARE * len(moves))
            largest = max(largest, float(np.partition(moves, len(moves) - 1 - aside)[len(moves) - 1 - aside]))
        return largest

    def _record(self, f: int, positions: np.ndarray, F: np.ndarray, diag: dict) -> None:
        """Store frame f: world positions, world F of every particle, and the diagnostics."""
        s = self.solver
        x_sim = s.x.numpy().astype(np.float64)
        v = s.v.numpy().astype(np.float64) @ self.Q  # world = Q^T sim, for row vectors
        x = x_sim @ self.Q
        positions[f] = x
        # the deformation since the photograph: the settled load's F is the rest state
        wp.launch(deformation_since_rest, dim=len(self.masses), device=self.device,
                  inputs=[s.F, self._rest_F_inverse, wp.mat33(self.Q.astype(np.float32)), self._world_F])
        F[f] = self._world_F.numpy()
        m = self.masses
        wp.launch(elastic_energy, dim=len(m), device=self.device,
                  inputs=[s.materials, s.object_id, s.volume, s.F, s.history, self._energy])
        height = x_sim[:, 1] - self._height_zero
        diag["kinetic_energy"][f] = 0.5 * np.sum(m * np.sum(v * v, axis=1))
        diag["potential_energy"][f] = (np.linalg.norm(self.gravity_world) * np.sum(m * height)
                                       + np.sum(self._energy.numpy(), dtype=np.float64))
        diag["momentum"][f] = m @ v
        diag["angular_momentum"][f] = m @ np.cross(x, v)
        diag["max_speed"][f] = np.sqrt(np.max(np.sum(v * v, axis=1))) if len(v) else 0.0
        self._log_free(f)
        self._log_outside_picture(f, x)

    def _log_outside_picture(self, f: int, x: np.ndarray) -> None:
        """Say when particles leave the photograph's view (behind the camera or past its borders), and how many."""
        if self._camera is None:
            return
        K, (height, width) = self._camera
        z = x[:, 2]
        uv = project_points(x, K)
        n = int(np.count_nonzero((z <= 0) | (uv[:, 0] < 0) | (uv[:, 1] < 0) | (uv[:, 0] > width)
                                 | (uv[:, 1] > height)))
        if n != self._outside_logged and (abs(n - self._outside_logged) >= 0.01 * len(self.masses) or n == 0
                                          or self._outside_logged == 0):
            log.info("frame %d: %d of %d particles are outside the picture", f, n, len(self.masses))
            self._outside_logged = n

    def _follow_every(self, max_speed: float, h: float) -> int:
        """Substeps between grid moves: no particle (up to the last frame's speed, what a condition may
        give, and a frame of free fall and of the conditions' forces) travels a cell in between."""
        speed = max(max_speed, self.speed_hint) + (float(np.linalg.norm(self.gravity_world))
                                                   + self.conditions.acceleration) / self.physics.fps
        return max(1, int(self.grid.dx / (speed * h))) if speed > 0 else 1 << 30

    def _log_free(self, f: int) -> None:
        """Say when particles leave the grid (they fly on freely, mpm.free_flight) and how many."""
        n = self.solver.n_free()
        if n != self._free_logged and (n == 0 or abs(n - self._free_logged) >= 0.01 * len(self.masses)
                                       or self._free_logged == 0):
            log.info("frame %d: %d of %d particles are off the simulation grid (%.2f m around the objects) and fly "
                     "freely: gravity, forces and the ground act on them, nothing else", f, n, len(self.masses),
                     2 * self._size)
            self._free_logged = n

    def _check(self, f: int, h: float, x: np.ndarray, max_speed: float) -> None:
        """Stop with a message naming the frame, the object and the likely fix when the run blew up."""
        v = self.solver.v.numpy()
        bad = ~(np.isfinite(x).all(axis=1) & np.isfinite(v).all(axis=1))
        limit = BLOW_UP_FACTOR * (self.wave_speed + self.speed_hint
                                  + (np.linalg.norm(self.gravity_world) + self.conditions.acceleration)
                                  * self.physics.duration_s)
        if not bad.any() and max_speed <= limit:
            return
        p = int(np.argmax(bad)) if bad.any() else int(np.argmax(np.sum(v * v, axis=1)))
        k = int(self.object_id[p])
        what = "non-finite positions (NaN)" if bad.any() else f"a particle at {max_speed:.3g} m/s (limit {limit:.3g})"
        # a rigid body has no stiffness to lower: what flings it is a far heavier body sharing its grid cells
        material = ("raise its density or lower its neighbours'" if self.materials[k].preset == "rigid"
                    else "lower its youngs_modulus or raise its density")
        raise InputError(self.scene_file, f"objects[{k}].material",
                         f"the simulation blew up at frame {f} (t = {f / self.physics.fps:.3f} s): object {k} "
                         f"({self.materials[k].preset}) has {what} with substeps of {h:.2e} s",
                         ("remove physics.dt (the CFL bound then follows the particles' speed), "
                          f"{material}, or soften the conditions acting on it")
                         if self.physics.dt is not None else
                         f"{material}, set physics.dt below {0.5 * h:.1e} s, or soften the conditions acting on it")
