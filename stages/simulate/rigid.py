"""Rigid objects: after G2P, each rigid object's particles take the one rigid motion
that has their total linear and angular momentum.

Per substep, per rigid body b with rest centre of mass, rest offsets r0_p and
rest inertia I0 (all in the simulation frame):
  P = sum m_p v_p,  L = sum m_p (R r0_p) x v_p          (momenta gathered from the grid)
  V = P / M,  omega = (R I0 R^T)^-1 L
  c += dt V,  R <- exp(dt omega) R
  x_p = c + R r0_p,  v_p = V + omega x (x_p - c),  C_p = [omega]x,  F_p = R
so the shape never changes (no strain), while contacts and conditions still
act through the grid momentum.
"""
from __future__ import annotations

import numpy as np
import warp as wp


@wp.kernel
def gather_rigid_momentum(
    members: wp.array(dtype=wp.int32),
    body: wp.array(dtype=wp.int32),
    rest_offset: wp.array(dtype=wp.vec3),
    orientation: wp.array(dtype=wp.quat),
    mass: wp.array(dtype=float),
    v: wp.array(dtype=wp.vec3),
    linear: wp.array(dtype=wp.vec3),
    angular: wp.array(dtype=wp.vec3),
    lowest: wp.array(dtype=float),
):
    """Sum each body's linear momentum (kg m/s), angular momentum about its centre (kg m^2/s)
    and find its lowest point below the centre (m)."""
    i = wp.tid()
    p = members[i]
    b = body[i]
    momentum = mass[p] * v[p]
    offset = wp.quat_rotate(orientation[b], rest_offset[i])
    wp.atomic_add(linear, b, momentum)
    wp.atomic_add(angular, b, wp.cross(offset, momentum))
    wp.atomic_min(lowest, b, offset[1])


@wp.kernel
def integrate_rigid_bodies(
    dt: float,
    ground_y: float,
    lowest: wp.array(dtype=float),
    total_mass: wp.array(dtype=float),
    rest_inertia: wp.array(dtype=wp.mat33),
    linear: wp.array(dtype=wp.vec3),
    angular: wp.array(dtype=wp.vec3),
    centre: wp.array(dtype=wp.vec3),
    orientation: wp.array(dtype=wp.quat),
    velocity: wp.array(dtype=wp.vec3),
    spin: wp.array(dtype=wp.vec3),
):
    """Velocities from momenta, then advance centre and orientation; clears the momentum sums.

    The ground zeroes only the grid nodes under the body, so the averaged
    velocity still sinks it a little each step; a body that would reach below
    ground_y (sim frame, m) is lifted back onto it instead.
    """
    b = wp.tid()
    R = wp.quat_to_matrix(orientation[b])
    V = linear[b] / total_mass[b]
    sink = ground_y - (centre[b][1] + lowest[b] + dt * V[1])
    if sink > 0.0:
        V = wp.vec3(V[0], wp.max(V[1], 0.0), V[2])
        centre[b] = centre[b] + wp.vec3(0.0, sink, 0.0)
    lowest[b] = 1.0e30
    omega = wp.inverse(R * rest_inertia[b] * wp.transpose(R)) * angular[b]
    angle = wp.length(omega) * dt
    if angle > 0.0:
        turn = wp.quat_from_axis_angle(wp.normalize(omega), angle)
        orientation[b] = wp.normalize(turn * orientation[b])
    centre[b] = centre[b] + dt * V
    velocity[b] = V
    spin[b] = omega
    linear[b] = wp.vec3(0.0)
    angular[b] = wp.vec3(0.0)


@wp.kernel
def apply_rigid_motion(
    members: wp.array(dtype=wp.int32),
    body: wp.array(dtype=wp.int32),
    rest_offset: wp.array(dtype=wp.vec3),
    centre: wp.array(dtype=wp.vec3),
    orientation: wp.array(dtype=wp.quat),
    velocity: wp.array(dtype=wp.vec3),
    spin: wp.array(dtype=wp.vec3),
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    C: wp.array(dtype=wp.mat33),
    F: wp.array(dtype=wp.mat33),
):
    """Place each member particle on its body's rigid motion."""
    i = wp.tid()
    p = members[i]
    b = body[i]
    q = orientation[b]
    offset = wp.quat_rotate(q, rest_offset[i])
    omega = spin[b]
    x[p] = centre[b] + offset
    v[p] = velocity[b] + wp.cross(omega, offset)
    C[p] = wp.skew(omega)
    F[p] = wp.quat_to_matrix(q)


class RigidBodies:
    """The rigid objects of a simulation (simulation frame).

    Args:
        rest_positions: (P,3) all particles at rest, m.
        masses: (P,) kg.
        object_id: (P,) object of each particle.
        rigid_objects: indices of the objects whose material is rigid.
        ground_y: height of the ground in the simulation frame, m (-inf: no ground).
    """

    def __init__(self, rest_positions: np.ndarray, masses: np.ndarray, object_id: np.ndarray,
                 rigid_objects: list[int], ground_y: float, device: str):
        members, bodies, offsets, centres, inertias, totals = [], [], [], [], [], []
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
        n = len(rigid_objects)
        self.n_members = int(sum(len(i) for i in members))
        self.members = wp.array(np.concatenate(members).astype(np.int32), dtype=wp.int32, device=device)
        self.body = wp.array(np.concatenate(bodies).astype(np.int32), dtype=wp.int32, device=device)
        self.rest_offset = wp.array(np.concatenate(offsets).astype(np.float32), dtype=wp.vec3, device=device)
        self.total_mass = wp.array(np.array(totals, np.float32), dtype=float, device=device)
        self.rest_inertia = wp.array(np.array(inertias, np.float32), dtype=wp.mat33, device=device)
        self.centre = wp.array(np.array(centres, np.float32), dtype=wp.vec3, device=device)
        self.orientation = wp.array(np.tile(np.array([0, 0, 0, 1], np.float32), (n, 1)), dtype=wp.quat, device=device)
        self.velocity = wp.zeros(n, dtype=wp.vec3, device=device)
        self.spin = wp.zeros(n, dtype=wp.vec3, device=device)
        self.linear = wp.zeros(n, dtype=wp.vec3, device=device)
        self.angular = wp.zeros(n, dtype=wp.vec3, device=device)
        self.lowest = wp.array(np.full(n, 1e30, np.float32), dtype=float, device=device)
        self.ground_y = max(float(ground_y), -1e30)
        self.device = device

    def project(self, solver, dt: float) -> None:
        """Replace the rigid objects' particle motion after G2P by their rigid motion."""
        n, dev = self.n_members, self.device
        wp.launch(gather_rigid_momentum, dim=n, device=dev, inputs=[
            self.members, self.body, self.rest_offset, self.orientation, solver.mass, solver.v,
            self.linear, self.angular, self.lowest])
        wp.launch(integrate_rigid_bodies, dim=len(self.total_mass), device=dev, inputs=[
            dt, self.ground_y, self.lowest, self.total_mass, self.rest_inertia, self.linear, self.angular,
            self.centre, self.orientation, self.velocity, self.spin])
        wp.launch(apply_rigid_motion, dim=n, device=dev, inputs=[
            self.members, self.body, self.rest_offset, self.centre, self.orientation, self.velocity, self.spin,
            solver.x, solver.v, solver.C, solver.F])
