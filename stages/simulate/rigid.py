"""Rigid objects: after G2P, each rigid object's particles take the one rigid motion
that has their total linear and angular momentum, and the ground pushes on the
body as a whole.

Per substep, per rigid body b with rest centre of mass, rest offsets r0_p and
rest inertia I0 (all in the simulation frame):
  P = sum m_p v_p,  L = sum m_p (R r0_p) x v_p + S     (momenta gathered from the grid; S what
                                                        its forces added to the APIC spin in C_p)
  V = P / M,  omega = (R I0 R^T)^-1 L
  ground: an impulse at the centre of pressure (below)
  held particles (below)
  c += dt V,  R <- exp(dt omega) R
  x_p = c + R r0_p,  v_p = V + omega x (x_p - c),  C_p = [omega]x,  F_p = R
so the shape never changes (no strain), while contacts with other objects and
the conditions act through the grid momentum.

The ground is not applied node by node to rigid particles (mpm.grid_update
keeps their velocities from before it): zeroing the nodes under the contact
patch puts the reaction at the patch's centroid, not under the centre of mass,
and rocks a body that stands still. A plane's pressure on a body sums to one
force at the centre of pressure, which lies in the support (the contact
points' extent on the ground) as near as it can to below the centre of mass.
When the body's lowest point would reach its floor within the substep, the
impulse there reverses the approach at that point to e times its speed (e the
material's restitution; 0 stops it), and the body is moved as if it had met
the floor at the moment it reached it and left it at the new speed, not from
wherever in the contact layer it was found; so a ball dropped from h rebounds
to e^2 h (to the accuracy of its flight's integration, tests/simulate), a body
at rest stays at rest, and one whose centre of mass is beyond its support tips
over its edge.
An approach slower than two substeps of gravity is a body resting on the
ground, which is pressed into it every substep and does not hop. Friction acts
at the same point by Coulomb's law (sticky: no sliding; slip: none), so a ball
rolls.

Particles held by a `fixed` or `velocity` condition (mpm's `prescribed`) hold
the whole body: it takes the rigid motion that best gives them their
prescribed velocities (mass-weighted least squares), and where they leave it
free, at one point (a pin) or along one line of points (a hinge), it keeps its
own angular momentum about their centre of mass. Held over an area or a
volume, it follows them and nothing else moves it.
"""
from __future__ import annotations

import numpy as np
import warp as wp

from .mpm import GROUND_FRICTION, GROUND_NONE, GROUND_SLIP
from .state import Particles


@wp.struct
class Members:
    """The rigid objects' particles, M of them."""

    particle: wp.array(dtype=wp.int32)  # (M,) index among the solver's particles
    body: wp.array(dtype=wp.int32)  # (M,) index of its body
    rest_offset: wp.array(dtype=wp.vec3)  # (M,) from its body's centre of mass at rest, m


@wp.struct
class Bodies:
    """The rigid bodies' state, B of them (simulation frame)."""

    total_mass: wp.array(dtype=float)  # (B,) kg
    rest_inertia: wp.array(dtype=wp.mat33)  # (B,) about the centre of mass at rest, kg m^2
    floor: wp.array(dtype=float)  # (B,) the ground, or the lowest rest point where that lies below it, m
    restitution: wp.array(dtype=float)  # (B,) of the material
    centre: wp.array(dtype=wp.vec3)  # (B,) centre of mass, m
    orientation: wp.array(dtype=wp.quat)  # (B,) rotation from rest
    velocity: wp.array(dtype=wp.vec3)  # (B,) of the centre, m/s
    spin: wp.array(dtype=wp.vec3)  # (B,) angular velocity, rad/s


@wp.struct
class BodySums:
    """What gather_rigid_momentum sums per body in a substep and integrate_rigid_bodies clears."""

    linear: wp.array(dtype=wp.vec3)  # (B,) momentum, kg m/s
    angular: wp.array(dtype=wp.vec3)  # (B,) angular momentum about the centre, kg m^2/s
    lowest: wp.array(dtype=float)  # (B,) lowest point's height below the centre (offset y), m
    support: wp.array2d(dtype=float)  # (B, 4) min x, min z, -max x, -max z of the points on the ground, m
    held_mass: wp.array(dtype=float)  # (B,) of the particles a condition holds, kg
    held_first: wp.array(dtype=wp.vec3)  # (B,) their first moment about the centre, kg m
    held_second: wp.array(dtype=wp.mat33)  # (B,) their second moment, kg m^2
    held_linear: wp.array(dtype=wp.vec3)  # (B,) their momentum, kg m/s
    held_angular: wp.array(dtype=wp.vec3)  # (B,) their angular momentum about the centre, kg m^2/s


@wp.struct
class RigidStep:
    """One substep's length and the ground the bodies meet."""

    dt: float  # s
    dx: float  # the grid's cell size, m (APIC's spin term)
    ground_kind: int  # mpm.GROUND_NONE ... GROUND_FRICTION
    friction: float  # Coulomb coefficient
    ground_y: float  # the ground's height, m (-1e30: none)
    contact_height: float  # points this close above the ground touch it, m
    resting_speed: float  # an approach slower than this (m/s) is a body resting on the ground


@wp.kernel
def gather_rigid_momentum(step: RigidStep, members: Members, bodies: Bodies, particles: Particles, sums: BodySums):
    """Sum each body's linear momentum (kg m/s), angular momentum about its centre (kg m^2/s), find its
    lowest point below the centre (m) and the extent of its points within contact_height of the
    ground (support[b] = min x, min z, -max x, -max z, m); and of its particles a condition holds
    (prescribed, their velocity v set by G2P): mass (kg), first (kg m) and second (kg m^2) moments of
    their offsets from the centre, linear and angular momentum.

    APIC keeps part of a particle's angular momentum in its affine velocity C: m_p (dx^2 / 4) times the
    axial vector of C_p - C_p^T (the quadratic kernel's second moment is dx^2 / 4), which for the body's
    own spin omega (C_p = [omega]x, apply_rigid_motion) is m_p (dx^2 / 2) omega. The body takes what
    the grid's forces and contacts added to that spin (on the particles on the grid, which carried it
    through P2G and G2P): counting only m r x v would give it an inertia of I + M dx^2 / 2 toward the grid
    (a torque would turn a box 16 cells across 6-15 % short of I^-1 tau), and counting the whole spin
    would make a free spin grow every substep.
    """
    i = wp.tid()
    p = members.particle[i]
    b = members.body[i]
    m = particles.mass[p]
    if m <= 0.0:
        return  # a Gaussian riding on the body: no momentum, and not what meets the ground
    momentum = m * particles.v[p]
    offset = wp.quat_rotate(bodies.orientation[b], members.rest_offset[i])
    turning = wp.cross(offset, momentum)
    if particles.free[p] == 0:
        c = particles.C[p]
        affine = wp.vec3(c[2, 1] - c[1, 2], c[0, 2] - c[2, 0], c[1, 0] - c[0, 1])
        turning += (0.25 * step.dx * step.dx * m) * (affine - 2.0 * bodies.spin[b])
    wp.atomic_add(sums.linear, b, momentum)
    wp.atomic_add(sums.angular, b, turning)
    wp.atomic_min(sums.lowest, b, offset[1])
    if particles.prescribed[p] != 0:
        wp.atomic_add(sums.held_mass, b, m)
        wp.atomic_add(sums.held_first, b, m * offset)
        wp.atomic_add(sums.held_second, b, m * wp.outer(offset, offset))
        wp.atomic_add(sums.held_linear, b, momentum)
        wp.atomic_add(sums.held_angular, b, wp.cross(offset, momentum))
    x = particles.x[p]
    if x[1] <= step.ground_y + step.contact_height:
        wp.atomic_min(sums.support, b, 0, x[0])
        wp.atomic_min(sums.support, b, 1, x[2])
        wp.atomic_min(sums.support, b, 2, -x[0])
        wp.atomic_min(sums.support, b, 3, -x[2])


@wp.func
def impulse_response(r: wp.vec3, d: wp.vec3, inv_mass: float, inv_inertia: wp.mat33):
    """Velocity change along d at offset r from the centre per unit impulse along d (1/kg)."""
    return inv_mass + wp.dot(d, wp.cross(inv_inertia * wp.cross(r, d), r))


@wp.func
def push_at(r: wp.vec3, j: wp.vec3, inv_mass: float, inv_inertia: wp.mat33, V: wp.vec3, omega: wp.vec3):
    """Linear and angular velocity after an impulse j (kg m/s) at offset r from the centre."""
    return V + inv_mass * j, omega + inv_inertia * wp.cross(r, j)


@wp.func
def held_motion(total_mass: float, inertia: wp.mat33, V: wp.vec3, omega: wp.vec3, held: float, first: wp.vec3,
                second: wp.mat33, linear: wp.vec3, angular: wp.vec3):
    """Linear and angular velocity of a body (total_mass kg, inertia kg m^2 about its centre, its own motion
    V m/s and omega rad/s) whose held particles (mass held kg, moments first kg m and second kg m^2 of their
    offsets from the centre, momentum linear kg m/s and angular kg m^2/s about the centre of their
    prescribed velocities) move as prescribed.

    Their centre of mass, the pivot, moves at their mean velocity and the body turns as the best fit of
    their angular momentum about it; about axes along which they have no extent (all of them at one point,
    one along a line of points) that fit says nothing, and the body keeps its own angular momentum about
    the pivot, as a pin or a hinge lets it.
    """
    s = first / held  # the pivot, from the centre
    pivot_velocity = linear / held
    spread = second - held * wp.outer(s, s)  # second moment about the pivot
    held_inertia = wp.diag(wp.vec3(wp.trace(spread))) - spread
    held_spin = angular - wp.cross(s, linear)  # their angular momentum about the pivot
    # extent below 1 % of the body's radius of gyration is none (float32 leaves about 1e-7 of it)
    none = 1.0e-4 * held * wp.trace(inertia) / total_mass
    axes, moments = wp.eig3(held_inertia)
    fitted = wp.vec3(0.0)
    free = wp.mat33(0.0)  # projector onto the axes the held particles leave free
    for k in range(3):
        axis = wp.vec3(axes[0, k], axes[1, k], axes[2, k])
        if moments[k] > none:
            fitted += axis * (wp.dot(axis, held_spin) / moments[k])
        else:
            free += wp.outer(axis, axis)
    # about the free axes: the rotation w closest to the body's own motion in kinetic energy, i.e. that keeps
    # its angular momentum about the pivot (P I_pivot P) w = P L_pivot; the held axes get a unit block
    pivot_inertia = inertia + total_mass * (wp.diag(wp.vec3(wp.dot(s, s))) - wp.outer(s, s))
    own = inertia * (omega - fitted) - total_mass * wp.cross(s, V - (pivot_velocity - wp.cross(fitted, s)))
    held_axes = wp.identity(n=3, dtype=float) - free
    w = wp.inverse(free * pivot_inertia * free + wp.trace(pivot_inertia) * held_axes) * (free * own)
    spin = fitted + free * w
    return pivot_velocity - wp.cross(spin, s), spin


@wp.kernel
def integrate_rigid_bodies(step: RigidStep, bodies: Bodies, sums: BodySums):
    """Velocities from momenta, the ground's impulse, the held particles (held_motion), then advance centre
    and orientation; clears the sums.

    The ground acts when the body's lowest point would reach its floor (sim frame, m: the ground, or
    its lowest rest point where that lies below the ground) within dt:
    the approach (m/s) at the centre of pressure turns into restitution times it away from the
    ground, unless it is below resting_speed (m/s, a body resting on the ground), and the centre
    moves as if the body had turned at the floor. A body whose lowest point would still reach below
    its floor is lifted back onto it.
    """
    b = wp.tid()
    dt = step.dt
    support = sums.support
    R = wp.quat_to_matrix(bodies.orientation[b])
    inv_mass = 1.0 / bodies.total_mass[b]
    inertia = R * bodies.rest_inertia[b] * wp.transpose(R)
    inv_inertia = wp.inverse(inertia)
    V = sums.linear[b] * inv_mass
    omega = inv_inertia * sums.angular[b]
    c = bodies.centre[b]
    if step.ground_kind != GROUND_NONE and support[b, 0] < 1.0e29:
        # centre of pressure: below the centre of mass, clamped into the support's extent
        pressure = wp.vec3(wp.clamp(c[0], support[b, 0], -support[b, 2]), step.ground_y,
                           wp.clamp(c[2], support[b, 1], -support[b, 3]))
        r = pressure - c
        up = wp.vec3(0.0, 1.0, 0.0)
        approach = -wp.dot(V + wp.cross(omega, r), up)  # speed toward the ground, m/s
        gap = wp.max(c[1] + sums.lowest[b] - bodies.floor[b], 0.0)  # how far the lowest point is above its floor, m
        if approach > 0.0 and approach * dt >= gap:  # it reaches the floor within this substep
            rebound = float(0.0)
            if approach > step.resting_speed:
                rebound = bodies.restitution[b] * approach
            normal = (approach + rebound) / impulse_response(r, up, inv_mass, inv_inertia)
            V, omega = push_at(r, normal * up, inv_mass, inv_inertia, V, omega)
            # it reached the floor after gap / approach of dt and left it at the rebound speed since: the
            # advance by dt V below puts it gap (1 + rebound / approach) too high
            c = c - gap * (1.0 + rebound / approach) * up
            slide = V + wp.cross(omega, r)
            slide = wp.vec3(slide[0], 0.0, slide[2])
            speed = wp.length(slide)
            if step.ground_kind != GROUND_SLIP and speed > 0.0:
                along = slide / speed
                stop = speed / impulse_response(r, along, inv_mass, inv_inertia)  # impulse that stops sliding
                if step.ground_kind == GROUND_FRICTION:
                    stop = wp.min(stop, step.friction * normal)
                V, omega = push_at(r, -stop * along, inv_mass, inv_inertia, V, omega)
    if sums.held_mass[b] > 0.0:
        V, omega = held_motion(bodies.total_mass[b], inertia, V, omega, sums.held_mass[b], sums.held_first[b],
                               sums.held_second[b], sums.held_linear[b], sums.held_angular[b])
    sink = bodies.floor[b] - (c[1] + sums.lowest[b] + dt * V[1])
    if sink > 0.0:
        V = wp.vec3(V[0], wp.max(V[1], 0.0), V[2])
        c = c + wp.vec3(0.0, sink, 0.0)
    sums.lowest[b] = 1.0e30
    for a in range(4):
        support[b, a] = 1.0e30
    angle = wp.length(omega) * dt
    if angle > 0.0:
        turn = wp.quat_from_axis_angle(wp.normalize(omega), angle)
        bodies.orientation[b] = wp.normalize(turn * bodies.orientation[b])
    bodies.centre[b] = c + dt * V
    bodies.velocity[b] = V
    bodies.spin[b] = omega
    sums.linear[b] = wp.vec3(0.0)
    sums.angular[b] = wp.vec3(0.0)
    sums.held_mass[b] = 0.0
    sums.held_first[b] = wp.vec3(0.0)
    sums.held_second[b] = wp.mat33(0.0)
    sums.held_linear[b] = wp.vec3(0.0)
    sums.held_angular[b] = wp.vec3(0.0)


@wp.kernel
def apply_rigid_motion(members: Members, bodies: Bodies, particles: Particles):
    """Place each member particle on its body's rigid motion."""
    i = wp.tid()
    p = members.particle[i]
    b = members.body[i]
    q = bodies.orientation[b]
    offset = wp.quat_rotate(q, members.rest_offset[i])
    omega = bodies.spin[b]
    particles.x[p] = bodies.centre[b] + offset
    particles.v[p] = bodies.velocity[b] + wp.cross(omega, offset)
    particles.C[p] = wp.skew(omega)
    particles.F[p] = wp.quat_to_matrix(q)


class RigidBodies:
    """The rigid objects of a simulation (simulation frame).

    Args:
        rest_positions: (P,3) all particles at rest, m.
        masses: (P,) kg.
        object_id: (P,) object of each particle.
        rigid_objects: {object index: its material (schemas.materials.Rigid)} of the rigid objects.
        ground: the mpm.Ground (contact law, friction, and its height: None, no ground).
        contact_height: points this close above the ground (m) are in contact with it.
    """

    def __init__(self, rest_positions: np.ndarray, masses: np.ndarray, object_id: np.ndarray,
                 rigid_objects: dict, ground, contact_height: float, device: str):
        self.ground, self.contact_height = ground, float(contact_height)
        ground_y = ground.height if ground.kind != GROUND_NONE and ground.height is not None else -1e30
        members, bodies, offsets, centres, inertias, totals, floors = [], [], [], [], [], [], []
        for b, k in enumerate(rigid_objects):
            idx = np.flatnonzero(object_id == k)
            m = masses[idx].astype(np.float64)
            c = (m[:, None] * rest_positions[idx]).sum(0) / m.sum()
            r = rest_positions[idx] - c
            inertia = np.eye(3) * (m * (r * r).sum(1)).sum() - (m[:, None, None] * r[:, :, None] * r[:, None, :]).sum(0)
            members.append(idx)
            bodies.append(np.full(len(idx), b))
            offsets.append(r)
            centres.append(c)
            inertias.append(inertia)
            totals.append(m.sum())
            floors.append(min(float(ground_y), float(rest_positions[idx, 1].min())))
        n = len(rigid_objects)
        self.n_members, self.n_bodies = int(sum(len(i) for i in members)), n
        self.members = wp.array(np.concatenate(members).astype(np.int32), dtype=wp.int32, device=device)
        self.member_state = Members()
        self.member_state.particle = self.members
        self.member_state.body = wp.array(np.concatenate(bodies).astype(np.int32), dtype=wp.int32, device=device)
        self.member_state.rest_offset = wp.array(np.concatenate(offsets).astype(np.float32), dtype=wp.vec3,
                                                 device=device)
        self.bodies = Bodies()
        self.bodies.total_mass = wp.array(np.array(totals, np.float32), dtype=float, device=device)
        self.bodies.rest_inertia = wp.array(np.array(inertias, np.float32), dtype=wp.mat33, device=device)
        self.bodies.floor = wp.array(np.array(floors, np.float32), dtype=float, device=device)
        self.bodies.restitution = wp.array(np.array([m.restitution for m in rigid_objects.values()], np.float32),
                                           dtype=float, device=device)
        self.bodies.centre = wp.array(np.array(centres, np.float32), dtype=wp.vec3, device=device)
        self.bodies.orientation = wp.array(np.tile(np.array([0, 0, 0, 1], np.float32), (n, 1)), dtype=wp.quat,
                                           device=device)
        self.bodies.velocity = wp.zeros(n, dtype=wp.vec3, device=device)
        self.bodies.spin = wp.zeros(n, dtype=wp.vec3, device=device)
        self.sums = BodySums()
        self.sums.linear = wp.zeros(n, dtype=wp.vec3, device=device)
        self.sums.angular = wp.zeros(n, dtype=wp.vec3, device=device)
        self.sums.lowest = wp.array(np.full(n, 1e30, np.float32), dtype=float, device=device)
        self.sums.support = wp.array(np.full((n, 4), 1e30, np.float32), dtype=float, device=device)
        self.sums.held_mass = wp.zeros(n, dtype=float, device=device)
        self.sums.held_first = wp.zeros(n, dtype=wp.vec3, device=device)
        self.sums.held_second = wp.zeros(n, dtype=wp.mat33, device=device)
        self.sums.held_linear = wp.zeros(n, dtype=wp.vec3, device=device)
        self.sums.held_angular = wp.zeros(n, dtype=wp.vec3, device=device)
        self.step = RigidStep()
        self.step.ground_kind = ground.kind
        self.step.friction = ground.friction
        self.step.ground_y = float(ground_y)
        self.step.contact_height = self.contact_height
        self.device = device

    def project(self, solver, dt: float) -> None:
        """Replace the rigid objects' particle motion after G2P by their rigid motion."""
        step, members, bodies, sums, particles = self.step, self.member_state, self.bodies, self.sums, solver.particles
        step.dt, step.dx = dt, solver.grid.dx
        # a body resting on the ground approaches it at what one substep of gravity gives it
        step.resting_speed = 2.0 * dt * float(np.linalg.norm(solver.gravity))
        wp.launch(gather_rigid_momentum, dim=self.n_members, device=self.device,
                  inputs=[step, members, bodies, particles, sums])
        wp.launch(integrate_rigid_bodies, dim=self.n_bodies, device=self.device, inputs=[step, bodies, sums])
        wp.launch(apply_rigid_motion, dim=self.n_members, device=self.device, inputs=[members, bodies, particles])
