"""The photographed world at rest: the stress the objects stand under.

A photographed object is in equilibrium. Its shape is the loaded shape, but a
simulation that starts from it with no stress lets it fall into its own
weight: it sags by twice its static deflection, rings and, on a narrow
support, rocks. The settle (simulation.Simulation.settle, `Relaxation`) finds
the stress of the loaded state: dynamic relaxation under gravity and the
ground with every particle pinned where the photograph has it
(MPMSolver.pin), so that velocities and deformation gradients evolve but the
geometry does not, the solids elastically (a photographed solid stands on its
elastic stress; where that is past its yield stress, `von_mises_stress`, it
yields in the run). It ends with the stress that holds the photographed shape
itself in equilibrium, in the discretisation the run goes on with; the run
starts from it at rest. A settle that lets the bodies move finds the
equilibrium of the sagged body instead, which on a narrow foot is another pose
(docs/decisions/0002-settle.md).

The ground lies through the objects' lowest point (simulation.py): a body
stands because its base carries it, and `support_margin` says whether it does.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from .conditions import inertia_about_centre
from .constitutive import MIN_STRETCH, lame_parameters

# The settle stops once a kinetic energy peak is below this fraction of the first (the sag's), and
# lasts at most this many periods of the slowest body's fundamental mode. The fraction is small because
# a round body's roll on its foot is far softer than its sag (docs/decisions/0002-settle.md).
RELAXED = 1.0e-7
SETTLE_PERIODS = 10.0
# A settle whose kinetic energy has not peaked once in this many periods is still falling: the body
# touches the ground on too small a contact (a soft ball on its lowest point) to stand as photographed.
FOOTLESS_PERIODS = 2.0
# Substeps between takings out of the bodies' drift and spin: it costs about a substep's time (22 ms for
# 70k particles), and a neutral roll gathers little in this many.
RIGID_MOTION_EVERY = 10
# A body whose settled stress is past its yield stress in more than this share of its mass is named:
# it will yield there in the run (a few particles at the rim of a contact patch do not show).
OVERSTRESSED_SHARE = 0.01


def support_margin(points_xz: np.ndarray, centre_xz: np.ndarray) -> float:
    """How far (m) centre (2,) lies inside the convex hull of points (N,2), its support seen from above;
    negative outside, -inf without an area to stand on."""
    if len(points_xz) < 3:
        return -math.inf
    try:
        hull = ConvexHull(points_xz)
    except QhullError:  # all on one line: no area to stand on
        return -math.inf
    # equations: n . p + offset <= 0 inside, unit n
    return float(-np.max(hull.equations[:, :2] @ centre_xz + hull.equations[:, 2]))


def turn_deg(rest: np.ndarray, now: np.ndarray, weights: np.ndarray) -> float:
    """Angle in degrees of the best rotation (weighted Kabsch) taking the points rest (N,3) onto now (N,3)."""
    a = rest - weights @ rest / weights.sum()
    b = now - weights @ now / weights.sum()
    U, _, Vt = np.linalg.svd((b * weights[:, None]).T @ a)
    R = U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))]) @ Vt
    return math.degrees(math.acos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)))


def column_sag(material, height: float, gravity: float) -> float:
    """Static sag in m of the top of an elastic column of `height` m under its own weight (gravity in
    m/s^2): rho g h^2 / (2 E)."""
    return material.density * gravity * height ** 2 / (2.0 * material.youngs_modulus)


def von_mises_stress(F: np.ndarray, material) -> np.ndarray:
    """Von Mises equivalent stress in Pa of elastic deformation gradients F (N,3,3) under the Hencky law of
    the yielding presets (constitutive.hencky_kirchhoff): sqrt(3/2) 2 mu |dev log(sigma)|, the quantity
    their return mapping holds at or below the yield stress."""
    eps = np.log(np.maximum(np.linalg.svd(F, compute_uv=False), MIN_STRETCH))
    mu, _ = lame_parameters(material.youngs_modulus, material.poisson_ratio)
    return math.sqrt(1.5) * 2.0 * mu * np.linalg.norm(eps - eps.mean(axis=1, keepdims=True), axis=1)


def fundamental_period(material, height: float, thickness: float) -> float:
    """Period in s of a body's slowest elastic mode, as a column on the ground (fixed below, free
    above) `height` m tall and `thickness` m across: the slower of a shear wave crossing its height
    four times and a cantilever's first bending mode, 2 pi / 1.875^2 H^2 / (c r), c = sqrt(E / rho)
    and r = thickness / sqrt(12) the radius of gyration of its section (for the slender rocket of
    benchmarks/scenes, 0.34 s against the shear wave's 0.027)."""
    mu, _ = lame_parameters(material.youngs_modulus, material.poisson_ratio)
    shear = 4.0 * height / math.sqrt(mu / material.density)
    bending = 2.0 * math.pi / 1.875 ** 2 * height ** 2 * math.sqrt(12.0) / (
        thickness * math.sqrt(material.youngs_modulus / material.density))
    return max(shear, bending)


class Relaxation:
    """Dynamic relaxation by kinetic damping: run undamped, and whenever the kinetic energy has passed a
    peak, stop every particle. At a peak each mode passes its equilibrium, so stopping there leaves it
    at rest where it should be, whatever its period (the slow rocking of a soft body on a narrow
    support included, which no one damping rate reaches in time).

    The load is the deformation's: every RIGID_MOTION_EVERY substeps each body's rigid motion but its
    fall (its horizontal drift and its spin about its centre of mass) is taken out. A ball on a point of slip
    ground is in neutral balance, and the roll its settle would gather is the run's to show, not the
    stress's.

    `step(solver, dt)` after each substep of dt seconds returns True once a peak's energy is below RELAXED
    of the first. `displacement` (P,3) m sums v dt: where the particles would have gone, had they not been
    pinned (MPMSolver.pin), to first order the body's static deflection.

    Args:
        masses: (P,) kg; positions: (P,3) rest positions, simulation frame (+y up), m; bodies: the particle
            indices of each body that settles.
    """

    def __init__(self, masses: np.ndarray, positions: np.ndarray, bodies: list[np.ndarray]):
        self.masses = np.asarray(masses, np.float64)
        self.bodies = bodies
        self.offsets, self.inverse_inertia = [], []
        for members in self.bodies:
            centre, inertia = inertia_about_centre(positions[members], self.masses[members])
            self.offsets.append(positions[members] - centre)
            self.inverse_inertia.append(np.linalg.pinv(inertia))
        self.displacement = np.zeros((len(self.masses), 3))
        self.steps = 0
        self.first = self.previous = 0.0
        self.rising = True
        self.peaks = 0
        self.residual = 1.0

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
        v = solver.v.numpy().astype(np.float64)
        self.steps += 1
        if self.steps % RIGID_MOTION_EVERY == 0:
            v = self._without_drift_and_spin(v)
            solver.v.assign(v.astype(np.float32))
        self.displacement += dt * v
        energy = 0.5 * float(self.masses @ np.sum(v * v, axis=1))
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
