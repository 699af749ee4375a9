"""The photographed world at rest: where the ground is, and the stress the objects stand under.

A photographed object is in equilibrium. Two things of its reconstruction
break that if taken as they are:

- Its lowest point is wherever the reconstruction's error put it (a ball's
  closed back ends in a keel), so a ground through that point can hold the
  centre of mass off its support and tip the body over. `support_height`
  puts the ground plane at the lowest height at which each object resting on
  it stands: the convex hull of its points at or below the plane (seen from
  above) holds its centre of mass with a margin and, for a deformable body,
  the area those points cover carries its weight below its bearing stress
  (`bearing_stress`: half the yield stress, and at most 5 % of E), within
  MAX_SINK of its height. The few points below the
  plane stay where they are, inside the ground (they are its contact patch);
  nothing is moved, so frame 0 is still the photograph.
- Its shape is the loaded shape, but a simulation that starts from it with no
  stress lets it fall into its own weight: it sags by twice its static
  deflection, rings and, on a narrow support, rocks or rolls away. The
  settle (simulation.Simulation.settle, `Relaxation`) finds the stress of the
  loaded state: dynamic relaxation under gravity and the ground with every
  particle pinned where the photograph has it (MPMSolver.pin), so that
  velocities and deformation gradients evolve but the geometry does not,
  the solids elastically (a photographed solid stands on its elastic stress;
  where that is past its yield stress, `von_mises_stress`, it yields in the
  run). It ends with the stress that holds the photographed shape itself in
  equilibrium, in the discretisation the run goes on with; the run starts
  from it at rest. A settle that let the bodies move found the equilibrium
  of the sagged body instead, which for a soft body on a narrow foot is a
  different pose: the example ball as jelly of E = 5e4 Pa rolled 5.3 degrees
  onto the keel of its closed back, and from the photograph with that load
  it rocked 12.6 degrees in the run (0.12 from the pinned settle).
"""
from __future__ import annotations

import math

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from .constitutive import MIN_STRETCH, lame_parameters

# A reconstruction's lowest points are a guess of a few percent of the object's height (the example
# ball's closed back ends in a keel that needs 3.8 %, the cup 1.4 %): the ground may rise this far into
# an object for it to stand. An object that needs more does not stand in the photograph (a capsule
# leaning 20 degrees on one end needs 11 %): it falls as it would.
MAX_SINK = 0.05
# The settle stops once a kinetic energy peak is below this fraction of the first (the sag's), and
# lasts at most this many periods of the slowest body's fundamental mode. The fraction is small because
# a round body's roll on its foot is far softer than its sag: on the example ball as jelly of E = 5e4 Pa,
# the roll the residual of 1e-4 left turned it 1.3 degrees in a 1 s run, that of 1e-7 0.12.
RELAXED = 1.0e-7
SETTLE_PERIODS = 10.0
# A photographed foot is not visibly squashed: its contact strain is at most this.
CONTACT_STRAIN = 0.05
# A contact's pressure peaks above its mean (at the rim of a flat foot; 1.5 times it at the centre of
# a Hertzian one): a foot bearing its yield stress on average yields where the pressure peaks and the
# body leans (the example cup as plasticine fell over so, 55 degrees); on this share of it the cup stands.
BEARING_YIELD_SHARE = 0.5
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


def _support(points_xz: np.ndarray, centre_xz: np.ndarray, spacing: float) -> tuple[bool, float]:
    """Whether the convex hull of points (N,2) holds centre (2,) at least one lattice `spacing` inside its
    edges, and the area (m^2) the points themselves cover: spacing^2 for each lattice column they occupy
    (a ring of contact bears the weight on the ring, not on the hull it encloses)."""
    inside = support_margin(points_xz, centre_xz) >= spacing
    columns = len(np.unique(np.floor(points_xz / spacing).astype(np.int64), axis=0))
    return inside, columns * spacing ** 2


def standing_height(positions: np.ndarray, masses: np.ndarray, spacing: float, bearing_area: float = 0.0) -> float:
    """Lowest plane height (m, +y up) at which one object (positions (N,3), masses (N,)) stands.

    It stands when its support (the points at or below the plane, seen from above) holds its centre
    of mass and, for a deformable body, is at least `bearing_area` (m^2) wide, so that its weight does
    not crush its foot; the plane rises at most MAX_SINK of its height above its lowest point, where
    a bearing area still short is left so. Binary search over the points' heights: the support only
    grows with the plane. An object whose centre of mass no support within MAX_SINK holds stands on
    its lowest point, and falls over as it would.
    """
    centre = (masses @ positions / masses.sum())[[0, 2]]
    order = np.argsort(positions[:, 1])
    heights, xz = positions[order, 1], positions[order][:, [0, 2]]
    cap = int(np.searchsorted(heights, heights[0] + MAX_SINK * (heights[-1] - heights[0]), side="right")) - 1

    def stands(i: int) -> bool:
        holds, area = _support(xz[: i + 1], centre, spacing)
        return holds and (area >= bearing_area or i == cap)

    if not stands(cap):
        return float(heights[0])
    lo, hi = 0, cap
    while lo < hi:  # the smallest i at which the lowest i + 1 points stand
        mid = (lo + hi) // 2
        if stands(mid):
            hi = mid
        else:
            lo = mid + 1
    return float(heights[lo])


def support_height(positions: np.ndarray, masses: np.ndarray, object_id: np.ndarray, spacing: float,
                   bearing_areas: dict | None = None) -> float:
    """Height of the ground plane (simulation frame, m): the lowest at which every object it touches stands.

    Args:
        positions: (P,3) rest positions, simulation frame (+y up), m.
        masses: (P,) kg.
        object_id: (P,) object of each particle.
        spacing: the fill's lattice spacing, m: a centre of mass must lie this far inside its support,
            and each lattice column of the support bears spacing^2 of the weight.
        bearing_areas: object -> the support (m^2) it needs not to crush its foot under its weight
            (M g / bearing_stress); none for rigid objects.

    The object with the lowest point touches the ground; any other object reaching below the
    plane it needs touches it too, and the plane rises to what that one needs.
    """
    bearing_areas = bearing_areas or {}
    objects = np.unique(object_id)
    lowest = {k: float(positions[object_id == k, 1].min()) for k in objects}
    plane = min(lowest.values())
    touching: set = set()
    while True:
        reach = {k for k in objects if lowest[k] <= plane} - touching
        if not reach:
            return plane
        touching |= reach
        plane = max([plane] + [standing_height(positions[object_id == k], masses[object_id == k], spacing,
                                               bearing_areas.get(int(k), 0.0)) for k in reach])


def bearing_stress(material) -> float:
    """Contact pressure in Pa a deformable body's foot carries as photographed: at most CONTACT_STRAIN
    of its Young's modulus (a softer foot is crushed, and a body on a crushed foot tips over: the
    example ball as jelly on a 1.7 mm keel turned 29 degrees) and BEARING_YIELD_SHARE of its yield
    stress."""
    stress = CONTACT_STRAIN * material.youngs_modulus
    yield_stress = getattr(material, "yield_stress", None)
    return min(stress, BEARING_YIELD_SHARE * yield_stress) if yield_stress else stress


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

    `step(solver, dt)` after each substep of dt seconds returns True once a peak's energy is below RELAXED
    of the first. `displacement` (P,3) m sums v dt: where the particles would have gone, had they not been
    pinned (MPMSolver.pin), to first order the body's static deflection.
    """

    def __init__(self, masses: np.ndarray):
        self.masses = np.asarray(masses, np.float64)
        self.displacement = np.zeros((len(self.masses), 3))
        self.first = self.previous = 0.0
        self.rising = True
        self.peaks = 0
        self.residual = 1.0

    def step(self, solver, dt: float) -> bool:
        v = solver.v.numpy().astype(np.float64)
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
