"""The settle's quasi-static step: relaxation of the pinned bodies to their equilibrium.

The settle (simulation.Simulation.settle, rest_state.py) wants only an end state, the stress under
which the pinned photographed geometry stands, not the motion that leads there. It steps the explicit
solver with every particle pinned, by dynamic relaxation with kinetic damping: whenever the kinetic
energy has passed a peak every particle is stopped. At a peak the dominant mode passes its
equilibrium, so stopping there leaves it at rest where it should be, whatever its period (the slow
rocking of a soft body on a narrow support included, docs/decisions/0002-settle.md).

It stops once the motion left is small, measured as an amplitude: the last peak's kinetic energy over
the first's is the square of the remaining amplitude's share of the first swing, and under RELAXED
(1e-4: a hundredth of the deflection) the bodies ring in the run by less than that. A stiff body's
higher modes peak every few substeps once the slow one has settled, each peak stopping the whole
body, so its energy ratio creeps: the 23 cm metal ball of benchmarks/examples.py reached 2e-5 after
227 substeps (4 peaks) and 5.5e-6 after 1508 (132 peaks); asked for 1e-7 it ran to its cap.

Stability: a step is the explicit CFL substep; the stops take energy out and add none. A larger step
is not taken: on the frozen geometry the stiffness, not the motion, bounds it, and scaling the masses
up to lengthen it lengthens every period alike, leaving the substeps per period, H / (CFL dx) times a
constant, as they are (docs/decisions/0028-quasi-static-settle.md). Where nothing moves afterwards
the run takes a whole frame as one step (simulation.Simulation.run).
"""
from __future__ import annotations

import numpy as np
import warp as wp

from .conditions import inertia_about_centre
from .state import Particles

# The settle has converged once a kinetic energy peak is under this share of the first: the motion
# left is a hundredth of the first swing (the jelly column of tests/simulate: 3 % of its sag allowed
# over the run).
RELAXED = 1.0e-4
# Substeps between takings out of the bodies' drift and spin: it costs about a substep's time (22 ms for
# 70k particles), and a neutral roll gathers little in this many.
RIGID_MOTION_EVERY = 10


@wp.struct
class RelaxationSums:
    """What the settle sums over the particles each substep."""

    displacement: wp.array(dtype=wp.vec3)  # (P,) summed v dt, m
    kinetic: wp.array(dtype=wp.float64)  # (1,) this substep's sum of m |v|^2 / 2, J


@wp.kernel
def relaxation_sums(particles: Particles, dt: float, sums: RelaxationSums):
    """displacement_p += dt v_p, and the kinetic energy sum m_p |v_p|^2 / 2 into kinetic[0] (J)."""
    p = wp.tid()
    u = particles.v[p]
    sums.displacement[p] = sums.displacement[p] + dt * u
    wp.atomic_add(sums.kinetic, 0, wp.float64(0.5 * particles.mass[p] * wp.dot(u, u)))


class QuasiStatic:
    """The relaxation of pinned bodies to their equilibrium by kinetic damping (the module's docstring).

    The load is the deformation's: every RIGID_MOTION_EVERY substeps each body's rigid motion but its
    fall (its horizontal drift and its spin about its centre of mass) is taken out. A ball on a point of
    slip ground is in neutral balance, and the roll its settle would gather is the run's to show, not the
    stress's.

    `step(solver, dt)` after each substep of dt seconds returns True once a peak's energy is under
    RELAXED of the first; `peaks` counts the peaks (a body whose energy never peaks is still falling),
    `residual` is the last one's energy over the first's. `displacement()` (P,3) m sums v dt: where the
    particles would have gone, had they not been pinned (MPMSolver.pin), to first order the bodies'
    static deflection. The sums run where the solver's arrays live; one number a substep comes back.

    Args:
        solver: the MPMSolver, whose masses and device are used; positions: (P,3) rest positions,
            simulation frame (+y up), m; bodies: the particle indices of each body that settles.
    """

    def __init__(self, solver, positions: np.ndarray, bodies: list[np.ndarray]):
        self.masses = solver.mass.numpy().astype(np.float64)
        self.bodies = bodies
        self.offsets, self.inverse_inertia = [], []
        for members in self.bodies:
            centre, inertia = inertia_about_centre(positions[members], self.masses[members])
            self.offsets.append(positions[members] - centre)
            self.inverse_inertia.append(np.linalg.pinv(inertia))
        self._sums = RelaxationSums()
        self._sums.displacement = wp.zeros(len(self.masses), dtype=wp.vec3, device=solver.device)
        self._sums.kinetic = wp.zeros(1, dtype=wp.float64, device=solver.device)
        self.steps = self.peaks = 0
        self.first = self.previous = 0.0
        self.rising = True
        self.residual = 1.0

    def displacement(self) -> np.ndarray:
        """(P,3) m: the summed v dt of every particle."""
        return self._sums.displacement.numpy().astype(np.float64)

    def substeps_left(self) -> float:
        """An estimate of the substeps until RELAXED, at the rate the peaks' energy has fallen so far (inf
        before it has fallen)."""
        if not 0.0 < self.residual < 1.0:
            return float("inf")
        return max(0.0, self.steps * np.log(self.residual / RELAXED) / -np.log(self.residual))

    def _without_drift_and_spin(self, v: np.ndarray) -> np.ndarray:
        """v (P,3) less each body's horizontal mean velocity and its rigid rotation about its centre of mass."""
        for members, r, inverse in zip(self.bodies, self.offsets, self.inverse_inertia):
            m, u = self.masses[members], v[members]
            drift = m @ u / m.sum()
            drift[1] = 0.0
            omega = inverse @ np.sum(m[:, None] * np.cross(r, u), axis=0)
            v[members] = u - drift - np.cross(omega, r)
        return v

    def step(self, solver, dt: float) -> bool:
        self.steps += 1
        if self.steps % RIGID_MOTION_EVERY == 0:
            v = self._without_drift_and_spin(solver.v.numpy().astype(np.float64))
            solver.v.assign(v.astype(np.float32))
        self._sums.kinetic.zero_()
        wp.launch(relaxation_sums, dim=len(self.masses), device=solver.device,
                  inputs=[solver.particles, dt, self._sums])
        energy = float(self._sums.kinetic.numpy()[0])
        if energy < self.previous and self.rising:  # just past a peak
            self.peaks += 1
            self.first = self.first or self.previous
            self.residual = self.previous / self.first if self.first > 0 else 0.0
            solver.v.zero_()
            solver.C.zero_()
            self.previous, self.rising = 0.0, True
            return self.residual < RELAXED
        self.rising = energy >= self.previous
        self.previous = energy
        return False
