"""The scene's conditions (impulse, velocity, force, torque, fixed) acting on particles.

Regions are decided once, at rest, in the object's normalised box [0,1]^3
over its rest bounding box in the condition's frame: the gravity-aligned one
(x the picture's right made horizontal, y down along gravity, z horizontal
away from the camera; domain.gravity_frame) unless the condition says
`frame: camera` (x right, y down, z away from the camera). Vectors are read in
the same frame and turned into the simulation frame. Semantics (DESIGN.md):
  impulse   v_p += dv once, at the first substep starting at or after start_s
  velocity  v_p = v during [start_s, end_s) (mpm.grid_to_particle's override)
  fixed     v_p = 0 during the window (a rigid body is held by those particles as a whole: rigid.py)
  force     f_p = F m_p / M_region
  torque    f_p = m_p (I^-1 tau) x (x_p - c), c and I of the region's current
            positions, so the forces sum to zero and their moment about c is tau
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from schemas import InputError

from .domain import condition_frame
from .state import Particles


def region_members(region, positions: np.ndarray) -> np.ndarray:
    """Boolean (N,) membership of an object's rest positions (N,3, in the condition's frame) in a scene region."""
    lo, hi = positions.min(axis=0), positions.max(axis=0)
    u = (positions - lo) / np.maximum(hi - lo, 1e-12)  # normalised box coordinates
    if region == "all":
        return np.ones(len(positions), dtype=bool)
    if hasattr(region, "box"):
        b = np.asarray(region.box)
        return np.all((u >= b[:3]) & (u <= b[3:]), axis=1)
    c, r = np.asarray(region.sphere[:3]), region.sphere[3]
    return np.linalg.norm(u - c, axis=1) <= r


@wp.kernel
def add_velocity(members: wp.array(dtype=wp.int32), dv: wp.vec3, particles: Particles):
    """v_p += dv (m/s) for the region's particles (members, indices)."""
    p = members[wp.tid()]
    particles.v[p] = particles.v[p] + dv


@wp.kernel
def region_moments(members: wp.array(dtype=wp.int32), particles: Particles, ref: wp.vec3,
                   moments: wp.array(dtype=float)):
    """Accumulate M, sum m r (3) and sum m r r^T (6) with r = x - ref into moments[0:10]."""
    p = members[wp.tid()]
    m = particles.mass[p]
    r = particles.x[p] - ref
    wp.atomic_add(moments, 0, m)
    for a in range(3):
        wp.atomic_add(moments, 1 + a, m * r[a])
    wp.atomic_add(moments, 4, m * r[0] * r[0])
    wp.atomic_add(moments, 5, m * r[1] * r[1])
    wp.atomic_add(moments, 6, m * r[2] * r[2])
    wp.atomic_add(moments, 7, m * r[0] * r[1])
    wp.atomic_add(moments, 8, m * r[0] * r[2])
    wp.atomic_add(moments, 9, m * r[1] * r[2])


@wp.kernel
def add_torque_forces(members: wp.array(dtype=wp.int32), particles: Particles, ref: wp.vec3,
                      moments: wp.array(dtype=float), torque: wp.vec3):
    """f_p += m_p alpha x (x_p - c) with alpha = I_c^-1 tau, I_c the region's inertia about its centre c."""
    p = members[wp.tid()]
    M = moments[0]
    s = wp.vec3(moments[1], moments[2], moments[3]) / M  # centre relative to ref
    # second moment about the centre: S_c = S_ref - M s s^T
    S = wp.mat33(moments[4], moments[7], moments[8], moments[7], moments[5], moments[9], moments[8], moments[9],
                 moments[6]) - M * wp.outer(s, s)
    inertia = wp.diag(wp.vec3(wp.trace(S))) - S
    alpha = wp.inverse(inertia) * torque
    particles.force[p] = particles.force[p] + particles.mass[p] * wp.cross(alpha, particles.x[p] - (ref + s))


def inertia_about_centre(points: np.ndarray, masses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(centre of mass (3,) m, inertia tensor (3,3) kg m^2 about it) of point masses (N,) kg at points (N,3) m."""
    centre = masses @ points / masses.sum()
    r = points - centre
    return centre, np.eye(3) * np.sum(masses * np.sum(r * r, axis=1)) - np.einsum("p,pi,pj->ij", masses, r, r)


def largest_acceleration(condition, to_world: np.ndarray, region: np.ndarray, masses: np.ndarray,
                         body: np.ndarray) -> float:
    """The largest acceleration in m/s^2 a force or torque condition gives a particle at rest: F / M of
    its region, or |I^-1 tau| (I the region's inertia about its centre) times the farthest particle of
    its object from that centre, the lever of a body that turns as one; 0 for the other conditions.

    Args:
        condition: one of scene.physics.conditions.
        to_world: (3,3) the condition's frame -> world.
        region: (N,3) the region's rest positions, world frame, m.
        masses: (N,) their masses, kg.
        body: (B,3) the rest positions of the region's object, world frame, m.
    """
    if condition.type == "force":
        return float(np.linalg.norm(condition.force)) / float(masses.sum())
    if condition.type != "torque":
        return 0.0
    centre, inertia = inertia_about_centre(region, masses)
    alpha = np.linalg.solve(inertia, to_world @ np.asarray(condition.torque, np.float64))
    return float(np.linalg.norm(alpha) * np.max(np.linalg.norm(body - centre, axis=1)))


@dataclass
class _Active:
    condition: object
    members: np.ndarray  # particle indices
    members_wp: wp.array
    mass: float  # region mass, kg
    rest_centre: wp.vec3  # region centre of mass at rest, simulation frame: a well-conditioned reference point
    to_sim: np.ndarray  # (3,3) the condition's frame -> simulation frame

    def sim(self, vector) -> wp.vec3:
        """A vector of the condition (in its frame) in the simulation frame."""
        return wp.vec3(*(self.to_sim @ np.asarray(vector, np.float64)).astype(np.float32))


class Conditions:
    """Applies the scene's conditions to an MPMSolver before each substep.

    Args:
        conditions: scene.physics.conditions.
        rest_world: (P,3) rest positions in the world frame, m.
        object_id: (P,) object of each particle.
        masses: (P,) kg.
        Q: (3,3) world -> simulation rotation.
        gravity_frame: (3,3) rows: the gravity-aligned axes in the world frame (domain.gravity_frame).
        scene_file: named in the error when a region holds no material.

    `acceleration` is the largest acceleration in m/s^2 a force or torque condition gives a particle
    (largest_acceleration): the substep must follow what they set moving, as it does a fall.

    Raises:
        InputError: a region that holds no particle with mass of its object, or a torque's region with no
            extent about some axis (one point, one line of particles), which no forces on it can turn.
    """

    def __init__(self, conditions, rest_world: np.ndarray, object_id: np.ndarray, masses: np.ndarray,
                 Q: np.ndarray, gravity_frame: np.ndarray, device: str, scene_file="scene.yaml"):
        self.device, self.n = device, len(masses)
        self.masses = masses
        self.items: list[_Active] = []
        self.acceleration = 0.0
        for i, c in enumerate(conditions):
            to_frame = condition_frame(c, gravity_frame)  # world -> the condition's frame
            obj = np.flatnonzero(object_id == c.object)
            idx = obj[region_members(c.region, rest_world[obj] @ to_frame.T)]
            if masses[idx].sum() <= 0:  # none, or only its massless Gaussians
                raise InputError(scene_file, f"physics.conditions[{i}].region",
                                 f"the region holds none of object {c.object}'s material, only its surface",
                                 "enlarge it; regions are in the object's own [0,1]^3 box (see setup.png)")
            m = masses[idx].astype(np.float64)
            if c.type == "torque":
                moments = np.linalg.eigvalsh(inertia_about_centre(rest_world[idx], m)[1])
                if moments[0] <= 1e-9 * moments[2]:  # one point or one line: no moment about some axis
                    raise InputError(scene_file, f"physics.conditions[{i}].region",
                                     f"the torque's region holds {len(idx)} particle(s) of object {c.object} on "
                                     "one point or one line, which forces on them cannot turn about every axis",
                                     "enlarge it; regions are in the object's own [0,1]^3 box (see setup.png)")
            self.acceleration = max(self.acceleration, largest_acceleration(
                c, to_frame.T, rest_world[idx], m, rest_world[obj]))
            centre = Q @ (m @ rest_world[idx] / m.sum())
            self.items.append(_Active(c, idx, wp.array(idx.astype(np.int32), dtype=wp.int32, device=device),
                                      float(m.sum()), wp.vec3(*centre.astype(np.float32)), Q @ to_frame.T))
        self._applied_impulses: set[int] = set()
        self._active_key: tuple | None = None
        self._base_force = wp.zeros(self.n, dtype=wp.vec3, device=device)
        self._moments = wp.zeros(10, dtype=float, device=device)

    @staticmethod
    def _in_window(c, t: float) -> bool:
        return c.start_s <= t and (c.end_s is None or t < c.end_s)

    def fixed_at_start(self) -> np.ndarray:
        """Boolean (P,) of the particles a `fixed` condition holds at t = 0."""
        held = np.zeros(self.n, bool)
        for item in self.items:
            if item.condition.type == "fixed" and self._in_window(item.condition, 0.0):
                held[item.members] = True
        return held

    def before_substep(self, t: float, solver) -> None:
        """Apply what is due at time t (s), the start of the next substep."""
        for i, item in enumerate(self.items):
            c = item.condition
            if c.type == "impulse" and i not in self._applied_impulses and t >= c.start_s:
                wp.launch(add_velocity, dim=len(item.members), device=self.device,
                          inputs=[item.members_wp, item.sim(c.velocity), solver.particles])
                self._applied_impulses.add(i)
        active = tuple(i for i, item in enumerate(self.items)
                       if item.condition.type != "impulse" and self._in_window(item.condition, t))
        if active != self._active_key:
            self._active_key = active
            self._upload_windows(active, solver)
        torques = [self.items[i] for i in active if self.items[i].condition.type == "torque"]
        if torques:
            wp.copy(solver.force, self._base_force)
            for item in torques:
                self._moments.zero_()
                wp.launch(region_moments, dim=len(item.members), device=self.device,
                          inputs=[item.members_wp, solver.particles, item.rest_centre, self._moments])
                wp.launch(add_torque_forces, dim=len(item.members), device=self.device,
                          inputs=[item.members_wp, solver.particles, item.rest_centre, self._moments,
                                  item.sim(item.condition.torque)])

    def _upload_windows(self, active: tuple, solver) -> None:
        """Rebuild prescribed velocities and constant forces when a window opens or closes."""
        prescribed = np.zeros(self.n, np.int32)
        velocity = np.zeros((self.n, 3), np.float32)
        force = np.zeros((self.n, 3), np.float32)
        for i in active:
            item = self.items[i]
            c = item.condition
            if c.type in ("velocity", "fixed"):
                prescribed[item.members] = 1
                velocity[item.members] = item.to_sim @ np.asarray(c.velocity) if c.type == "velocity" else 0.0
            elif c.type == "force":
                share = self.masses[item.members, None] / item.mass
                force[item.members] += share * (item.to_sim @ np.asarray(c.force))[None, :]
        solver.prescribed.assign(prescribed)
        solver.prescribed_velocity.assign(velocity)
        self._base_force.assign(force)
        wp.copy(solver.force, self._base_force)
