"""MLS-MPM with APIC transfer and quadratic B-splines (Hu et al. 2018), in Warp.

All quantities live in the *simulation frame*: metres, with gravity along -y
(see domain.py), so the ground is the grid plane y = ground_node * dx.

One substep, one kernel per physical step:
  crack fields       (crack_fields.py, scenes that can tear) each node's crack direction
  particle_to_grid   scatter mass and APIC momentum plus stress and external forces,
                     each side of a crack into its own field
  grid_update        momentum -> velocity, gravity, contact across cracks, ground and walls
  grid_to_particle   gather velocity and its gradient C, advect, F <- (I + dt C) F;
                     massless particles ride with the material they belong to (mark_riders
                     beside P2G, ride beside G2P);
                     particles off the grid fly freely (ballistic, ground contact only)
  rigid projection   (rigid.py) rigid objects follow one rigid motion
  update_stress      (constitutive.py) return mapping and Kirchhoff stress

On the CPU each particle kernel is split into `n_parts` ranges launched from
their own Python threads (a Warp CPU launch runs on one thread); P2G scatters
each range into its own grid copy (momentum and mass together, one vec4 per
node) so the copies never race, and the grid update sums them. The grid
update visits only the box of nodes that the particles' stencils touch
(`stencil_node_box`), which is also all it needs to clear for the next P2G.

The grid is no wall. Between frames it moves by whole cells to keep the
particles inside it (`follow`): MLS-MPM keeps no state on the grid from one
substep to the next, so only the origin changes. A particle that still leaves
it (the bodies spread wider than the grid, or `walls` is off and one outruns
a frame) is `free`: it stops scattering to the grid and moves under gravity,
its forces and the ground alone, with its deformation frozen, until it comes
back onto the grid. Only the ground and the walls a scene asks for stop
anything; with walls the grid stays where it is and its faces are the walls.
"""
from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import warp as wp
from scipy.spatial import cKDTree

from .constitutive import (SNOW_HARDENING_GROWTH, SNOW_HARDENING_MAX, initial_history, params_array, snow_hardening,
                           update_stress)
from .crack_fields import CrackFields, breaks, crack_contact, crack_field
from .state import Cracks, GridNodes, Particles, Riders, Step
from .stencil import stencil_base, stencil_weights

# Nodes this close to a domain face form the wall layer; particles are kept
# this far inside, so a quadratic stencil never leaves the grid.
BOUNDARY_NODES = 3
# A massless particle's velocity fit on a partial stencil adds this share of a whole stencil's moment
# matrix (dx^2/4 I): a plane of nodes gets no gradient across it, and C stays within ~10x APIC's bound.
REGULARISATION = 0.1

GROUND_NONE, GROUND_STICKY, GROUND_SLIP, GROUND_FRICTION = range(4)
GROUND_TYPES = {"sticky": GROUND_STICKY, "slip": GROUND_SLIP, "friction": GROUND_FRICTION}


@dataclass(frozen=True)
class Grid:
    """Background grid: node (i, j, k) sits at origin + dx * (i, j, k) (simulation frame, metres)."""

    origin: tuple[float, float, float]
    dx: float
    shape: tuple[int, int, int]


@dataclass(frozen=True)
class Ground:
    """Ground plane y = height (simulation frame, m; on a node plane of the grid) with its contact law."""

    kind: int = GROUND_NONE  # GROUND_NONE | GROUND_STICKY | GROUND_SLIP | GROUND_FRICTION
    friction: float = 0.0  # Coulomb coefficient (GROUND_FRICTION)
    height: float | None = None  # None: node plane BOUNDARY_NODES of the grid the solver starts on


@wp.func
def stencil_fields(cracks: Cracks, base: wp.vec3i, gradient: wp.vec3):
    """Bit 9 i + 3 j + k: the field (crack_fields.crack_field) in which a particle of damage gradient
    `gradient` meets node (i, j, k) of its stencil (corner node `base`)."""
    bits = int(0)
    for i in range(3):
        for j in range(3):
            for k in range(3):
                node = wp.vec3i(base[0] + i, base[1] + j, base[2] + k)
                field = crack_field(cracks.node_max_damage[node[0], node[1], node[2]],
                                    cracks.node_direction[node[0], node[1], node[2]], gradient)
                bits = bits | (field << (9 * i + 3 * j + k))
    return bits


def particle_to_grid_kernels(n_fields: int) -> tuple[wp.Kernel, wp.Kernel]:
    """P2G compiled for n_fields (1, or 2 where a body can tear, crack_fields.py) velocity fields per
    node: (particle_to_grid, of the particles with mass, mark_riders, of the massless ones). The one-field
    kernels, every scene without fracture, carry no per-node crack test."""

    @wp.kernel(module="unique")
    def particle_to_grid(start: int, part: int, substep: Step, particles: Particles, cracks: Cracks,
                         grid: GridNodes):
        """Scatter m_p, APIC momentum m_p (v_p + C_p (x_i - x_p)), stress force and external force to the grid.

        Node i of the stencil receives w_ip (m_p v_p + dt f_p + A_p (x_i - x_p), m_p) as one vec4, in
        copy part * n_fields + field of grid.momentum_mass. With two fields (crack_fields.py) the field
        of each of the 27 nodes is bit 9 i + 3 j + k of cracks.field_bits[p], which G2P reads back.
        Free particles (off the grid) scatter nothing; one coming back (free = 2) joins the grid here.
        A massless particle has no volume either (mass = density x volume): it scatters nothing, and
        mark_riders takes it.
        """
        p = wp.tid() + start
        m = particles.mass[p]
        if particles.free[p] == 1 or m <= 0.0:
            return
        if particles.free[p] == 2:
            particles.free[p] = 0
        dx = grid.dx
        dt = substep.dt
        inv_dx = 1.0 / dx
        base, fx = stencil_base(particles.x[p], grid.origin, inv_dx, grid.shape)
        bits = int(0)
        if wp.static(n_fields == 2):
            bits = stencil_fields(cracks, base, cracks.gradient[p])
            cracks.field_bits[p] = bits
        weights = stencil_weights(fx)
        # MLS-MPM: the stress force enters as an affine term, -dt V tau M^-1 with M^-1 = 4 / dx^2
        affine = m * particles.C[p] - (4.0 * dt * inv_dx * inv_dx) * particles.volume_stress[p]
        # x_i - x_p = dx ((i, j, k) - fx), so the node momentum is linear in (i, j, k): start from the
        # stencil corner and add one column of dx A_p per node step along each axis (3 adds, not a mat-vec)
        step = wp.transpose(dx * affine)  # row a: momentum change per node step along axis a
        corner = m * particles.v[p] + dt * particles.force[p] - dx * (affine * fx)
        for i in range(3):
            momentum_i = corner + float(i) * step[0]
            for j in range(3):
                momentum_ij = momentum_i + float(j) * step[1]
                w_ij = weights[0, i] * weights[1, j]
                for k in range(3):
                    momentum = momentum_ij + float(k) * step[2]
                    w = w_ij * weights[2, k]
                    field = int(0)
                    if wp.static(n_fields == 2):
                        field = (bits >> (9 * i + 3 * j + k)) & 1
                    copy = part * wp.static(n_fields) + field
                    wp.atomic_add(grid.momentum_mass, copy, base[0] + i, base[1] + j, base[2] + k,
                                  w * wp.vec4(momentum[0], momentum[1], momentum[2], m))

    @wp.kernel(module="unique")
    def mark_riders(start: int, particles: Particles, riders: Riders, cracks: Cracks, grid: GridNodes):
        """Beside P2G, for each massless particle (a Gaussian riding on its body's solid): where its anchor
        is now (riders.anchor_position: G2P moves positions, so ride finds the anchor's here) and, with two
        fields, its stencil's fields on its anchor's side of a crack. One coming back (free = 2) joins the grid."""
        p = wp.tid() + start
        if particles.free[p] == 1 or particles.mass[p] > 0.0:
            return
        if particles.free[p] == 2:
            particles.free[p] = 0
        anchor = riders.anchor[p]
        if anchor >= 0:
            riders.anchor_position[p] = particles.x[anchor]
        if wp.static(n_fields == 2):
            side = p
            if anchor >= 0:
                side = anchor
            base, fx = stencil_base(particles.x[p], grid.origin, 1.0 / grid.dx, grid.shape)
            cracks.field_bits[p] = stencil_fields(cracks, base, cracks.gradient[side])

    return particle_to_grid, mark_riders


PARTICLE_TO_GRID, MARK_RIDERS = {}, {}  # per number of fields: P2G of the particles with mass, and its massless twin
for _n_fields in (1, 2):
    PARTICLE_TO_GRID[_n_fields], MARK_RIDERS[_n_fields] = particle_to_grid_kernels(_n_fields)


@wp.kernel
def stencil_node_box(particles: Particles, grid: GridNodes, corners: wp.array(dtype=wp.int32)):
    """Smallest (corners[0:3]) and largest (corners[3:6]) stencil corner node of the particles on the grid."""
    p = wp.tid()
    if particles.free[p] != 0:
        return
    base, fx = stencil_base(particles.x[p], grid.origin, 1.0 / grid.dx, grid.shape)
    for a in range(3):
        wp.atomic_min(corners, a, base[a])
        wp.atomic_max(corners, 3 + a, base[a])


@wp.kernel
def smallest_history(object_id: wp.array(dtype=wp.int32), history: wp.array(dtype=float),
                     smallest: wp.array(dtype=float)):
    """Each object's smallest history scalar (smallest[k], for snow its most compacted J_p)."""
    p = wp.tid()
    wp.atomic_min(smallest, object_id[p], history[p])


@wp.func
def wall_slip(v: wp.vec3, node: wp.vec3i, shape: wp.vec3i):
    """Stop the velocity component that points out of the domain in the wall layer."""
    out = v
    for a in range(3):
        if node[a] < BOUNDARY_NODES and out[a] < 0.0:
            out[a] = 0.0
        if node[a] >= shape[a] - BOUNDARY_NODES and out[a] > 0.0:
            out[a] = 0.0
    return out


@wp.func
def ground_contact(v: wp.vec3, kind: int, friction: float):
    """Velocity of a grid node on or below the ground (normal +y) under the ground's contact law."""
    if kind == GROUND_STICKY:
        return wp.vec3(0.0)
    if v[1] >= 0.0:
        return v  # separating: no contact
    if kind == GROUND_SLIP:
        return wp.vec3(v[0], 0.0, v[2])
    # Coulomb: removing the normal approach speed vn removes at most friction * vn of sliding speed
    tangential = wp.vec3(v[0], 0.0, v[2])
    speed = wp.length(tangential)
    if speed <= friction * (-v[1]):
        return wp.vec3(0.0)
    return tangential * (1.0 - friction * (-v[1]) / speed)


@wp.func
def node_velocity(total: wp.vec4, gravity: wp.vec3, dt: float, node: wp.vec3i, shape: wp.vec3i, walls: int):
    """v = momentum / mass + dt g of one field's (momentum, mass), then the walls (walls != 0); 0 where it has no mass."""
    if total[3] <= 0.0:
        return wp.vec3(0.0)
    v = wp.vec3(total[0], total[1], total[2]) / total[3] + dt * gravity
    if walls != 0:
        v = wall_slip(v, node, shape)
    return v


def grid_update_kernel(n_fields: int) -> wp.Kernel:
    """The grid update compiled for n_fields velocity fields per node, as particle_to_grid_kernels."""

    @wp.kernel(module="unique")
    def grid_update(offset: wp.vec3i, substep: Step, cracks: Cracks, grid: GridNodes):
        """Per field, v_i = (sum of momenta) / (sum of masses) + dt g; the two fields of a crack in
        contact (crack_fields.crack_contact); then walls (substep.walls != 0) and ground. Clears the P2G
        copies and, with two fields, the crack arrays. Node (0, 0, 0) of the launch is node `offset`.

        With substep.keep_unsupported, the velocity before the ground's contact law is kept as well:
        rigid bodies meet the ground as whole bodies (rigid.py), not node by node."""
        i, j, k = wp.tid()
        i += offset[0]
        j += offset[1]
        k += offset[2]
        node = wp.vec3i(i, j, k)
        total0 = wp.vec4(0.0)
        total1 = wp.vec4(0.0)
        for part in range(grid.n_parts):
            total0 += grid.momentum_mass[part * wp.static(n_fields), i, j, k]
            grid.momentum_mass[part * wp.static(n_fields), i, j, k] = wp.vec4(0.0)
            if wp.static(n_fields == 2):
                total1 += grid.momentum_mass[part * 2 + 1, i, j, k]
                grid.momentum_mass[part * 2 + 1, i, j, k] = wp.vec4(0.0)
        v0 = node_velocity(total0, substep.gravity, substep.dt, node, grid.shape, substep.walls)
        v1 = wp.vec3(0.0)
        if wp.static(n_fields == 2):
            v1 = node_velocity(total1, substep.gravity, substep.dt, node, grid.shape, substep.walls)
            if total0[3] > 0.0 and total1[3] > 0.0:
                v0, v1 = crack_contact(v0, total0[3], v1, total1[3], cracks.node_direction[i, j, k],
                                       cracks.node_max_damage[i, j, k])
            cracks.node_damage_mass[i, j, k] = wp.vec2(0.0)
            cracks.node_max_damage[i, j, k] = 0.0
            cracks.node_gradient_norm[i, j, k] = 0.0
            cracks.node_direction[i, j, k] = wp.vec3(0.0)
        for field in range(wp.static(n_fields)):
            v = v0
            if field == 1:
                v = v1
            if substep.keep_unsupported != 0:
                grid.unsupported_velocity[field, i, j, k] = v
            if field == 0:
                grid.mass[field, i, j, k] = total0[3]
            else:
                grid.mass[field, i, j, k] = total1[3]
            if substep.ground_kind != GROUND_NONE and j <= grid.ground_node:
                v = ground_contact(v, substep.ground_kind, substep.friction)
            grid.velocity[field, i, j, k] = v

    return grid_update


GRID_UPDATE = {n_fields: grid_update_kernel(n_fields) for n_fields in (1, 2)}


@wp.func
def on_grid(x: wp.vec3, origin: wp.vec3, dx: float, shape: wp.vec3i, closed_faces: wp.vec3i, margin: float):
    """Whether x lies at least `margin` cells inside the wall layer of every open face (closed faces
    keep particles in by themselves), so that its stencil is on the grid."""
    xg = (x - origin) / dx
    inside = True
    for a in range(3):
        if closed_faces[a] == 0 and xg[a] < float(BOUNDARY_NODES) + margin:
            inside = False
        if closed_faces[a] < 2 and xg[a] > float(shape[a] - 1 - BOUNDARY_NODES) - margin:
            inside = False
    return inside


def grid_to_particle_kernels(n_fields: int) -> tuple[wp.Kernel, wp.Kernel]:
    """G2P compiled for n_fields velocity fields per node, as particle_to_grid_kernels: (grid_to_particle, of the
    particles with mass, ride, of the massless ones); each leaves the others alone, so the particles with mass
    pay nothing for the way the massless ones ride."""

    @wp.func
    def gather(velocity: wp.array4d(dtype=wp.vec3), field_bits: int, base: wp.vec3i, fx: wp.vec3, dx: float):
        """(v_p, C_p) of APIC on the whole stencil: v_p = sum w_i v_i, C_p = 4/dx^2 sum w_i v_i (x_i - x_p)^T.
        With two fields node (i, j, k) is read in field bit 9 i + 3 j + k of `field_bits`."""
        weights = stencil_weights(fx)
        # node offsets times weights, o_a = w_a (node - fx_a) dx, per axis
        ox = wp.cw_mul(weights[0], wp.vec3(0.0, 1.0, 2.0) - wp.vec3(fx[0])) * dx
        oy = wp.cw_mul(weights[1], wp.vec3(0.0, 1.0, 2.0) - wp.vec3(fx[1])) * dx
        oz = wp.cw_mul(weights[2], wp.vec3(0.0, 1.0, 2.0) - wp.vec3(fx[2])) * dx
        # v_p = sum w v_i and column a of B = sum w v_i (x_i - x_p)_a; the weights are products
        # weights[0, i] weights[1, j] weights[2, k], so both sums are taken one axis at a time (k, then j, then i)
        vp = wp.vec3(0.0)
        Bx = wp.vec3(0.0)
        By = wp.vec3(0.0)
        Bz = wp.vec3(0.0)
        for i in range(3):
            v_i = wp.vec3(0.0)  # sum over j, k of wy wz v
            vy_i = wp.vec3(0.0)  # ... of oy wz v
            vz_i = wp.vec3(0.0)  # ... of wy oz v
            for j in range(3):
                v_ij = wp.vec3(0.0)  # sum over k of wz v
                vz_ij = wp.vec3(0.0)  # ... of oz v
                for k in range(3):
                    field = int(0)
                    if wp.static(n_fields == 2):
                        field = (field_bits >> (9 * i + 3 * j + k)) & 1
                    vi = velocity[field, base[0] + i, base[1] + j, base[2] + k]
                    v_ij += weights[2, k] * vi
                    vz_ij += oz[k] * vi
                v_i += weights[1, j] * v_ij
                vy_i += oy[j] * v_ij
                vz_i += weights[1, j] * vz_ij
            vp += weights[0, i] * v_i
            Bx += ox[i] * v_i
            By += weights[0, i] * vy_i
            Bz += weights[0, i] * vz_i
        return vp, (4.0 / (dx * dx)) * wp.matrix_from_cols(Bx, By, Bz)

    @wp.func
    def gather_massless(velocity: wp.array4d(dtype=wp.vec3), mass: wp.array4d(dtype=float), field_bits: int,
                        base: wp.vec3i, fx: wp.vec3, dx: float):
        """(v_p, C_p, weight) of a massless particle: the linear velocity field v_p + C_p (x - x_p) that fits, in
        least squares weighted by w_i, the nodes of its stencil that carry mass after the grid update, and the
        weight sum w_i of those nodes (0: none, and v_p = 0, C_p = 0).

        APIC's C = 4/dx^2 sum w v (x_i - x_p)^T assumes the whole stencil, where sum w (x_i - x_p) = 0 and
        sum w (x_i - x_p)(x_i - x_p)^T = dx^2/4 I. At a body's surface part of the stencil is empty, and
        with the empty nodes left out neither holds: a body in free flight would shear its surface
        Gaussians. The fit's moment matrix is that of the nodes with mass about their centre, plus
        REGULARISATION of the whole stencil's, so it stays invertible (and C bounded) where those nodes
        lie in a plane; on a whole stencil the fit is APIC's. v_p is the nodes' weighted mean velocity.
        """
        weight = float(0.0)
        v_sum = wp.vec3(0.0)
        d_sum = wp.vec3(0.0)
        vd = wp.mat33(0.0)  # sum of w m v (x_i - x_p)^T
        dd = wp.mat33(0.0)  # sum of w m (x_i - x_p)(x_i - x_p)^T
        weights = stencil_weights(fx)
        for i in range(3):
            for j in range(3):
                for k in range(3):
                    field = int(0)
                    if wp.static(n_fields == 2):
                        field = (field_bits >> (9 * i + 3 * j + k)) & 1
                    a = float(0.0)
                    if mass[field, base[0] + i, base[1] + j, base[2] + k] > 0.0:
                        a = weights[0, i] * weights[1, j] * weights[2, k]
                    v = velocity[field, base[0] + i, base[1] + j, base[2] + k]
                    d = (wp.vec3(float(i), float(j), float(k)) - fx) * dx
                    weight += a
                    v_sum += a * v
                    d_sum += a * d
                    vd += a * wp.outer(v, d)
                    dd += a * wp.outer(d, d)
        if weight <= 0.0:
            return wp.vec3(0.0), wp.mat33(0.0), weight
        v_mean = v_sum / weight
        d_mean = d_sum / weight
        if weight >= 1.0 - 1e-6:  # the whole stencil: APIC's C
            return v_mean, (4.0 / (dx * dx)) * vd, weight
        moments = dd - weight * wp.outer(d_mean, d_mean) \
            + (REGULARISATION * 0.25 * dx * dx) * wp.identity(n=3, dtype=float)
        return v_mean, (vd - weight * wp.outer(v_mean, d_mean)) * wp.inverse(moments), weight

    @wp.func
    def advect(p: int, vp: wp.vec3, Cp: wp.mat33, substep: Step, grid: GridNodes, particles: Particles):
        """Set v_p, C_p (a condition's velocity overrides v_p), advect x_p and update the trial F_p = (I + dt C_p)
        F_p. A closed face keeps particles off its wall layer; through an open one they leave the grid (free)."""
        if particles.prescribed[p] != 0:
            vp = particles.prescribed_velocity[p]  # velocity and fixed conditions override the grid
        dx = grid.dx
        dt = substep.dt
        lo = float(BOUNDARY_NODES) * dx
        xp = particles.x[p] + dt * vp - grid.origin
        for a in range(3):
            if grid.closed_faces[a] >= 1:
                xp[a] = wp.max(xp[a], lo)
            if grid.closed_faces[a] == 2:
                xp[a] = wp.min(xp[a], float(grid.shape[a] - 1) * dx - lo)
        particles.x[p] = xp + grid.origin
        particles.v[p] = vp
        particles.C[p] = Cp
        particles.F[p] = (wp.identity(n=3, dtype=float) + dt * Cp) * particles.F[p]
        if not on_grid(particles.x[p], grid.origin, dx, grid.shape, grid.closed_faces, 0.0):
            particles.free[p] = 1
            particles.C[p] = wp.mat33(0.0)

    @wp.kernel(module="unique")
    def grid_to_particle(start: int, substep: Step, cracks: Cracks, grid: GridNodes, particles: Particles):
        """Gather v_p and the APIC affine velocity C_p of the particles with mass, advect x_p, and update the
        trial F_p = (I + dt C_p) F_p (advect).

        grid.closed_faces per axis: 0 open (a particle that leaves becomes free), 1 the low face is
        closed (the ground), 2 both faces are closed (walls). Particles of bodies that meet the ground
        themselves (own_ground, rigid) gather the velocity before the ground's contact law. With two
        fields each node is read in the particle's own field there (cracks.field_bits, written by P2G).
        The massless particles are `ride`'s.
        """
        p = wp.tid() + start
        if particles.free[p] != 0 or particles.mass[p] <= 0.0:
            return  # free_flight moves it, or it joins the grid at the next P2G; or it rides
        velocity = grid.velocity
        if particles.own_ground[p] != 0:
            velocity = grid.unsupported_velocity
        base, fx = stencil_base(particles.x[p], grid.origin, 1.0 / grid.dx, grid.shape)
        field_bits = int(0)
        if wp.static(n_fields == 2):
            field_bits = cracks.field_bits[p]
        vp, Cp = gather(velocity, field_bits, base, fx, grid.dx)
        advect(p, vp, Cp, substep, grid, particles)

    @wp.kernel(module="unique")
    def ride(start: int, substep: Step, cracks: Cracks, grid: GridNodes, particles: Particles, riders: Riders):
        """G2P of the massless particles (Gaussians riding on their body's solid): v_p and C_p are the fit to
        the stencil's nodes with mass (gather_massless) while the particle lies within a cell of its anchor;
        else, or where no node about it carries mass, it moves rigidly with its anchor, v_p = v_a + W_a
        (x_p - x_a), W_a the spin (skew part) of the anchor's APIC C_a, gathered where the anchor was at this
        substep's P2G (mark_riders), and C_p = C_a. Beyond a cell its stencil barely holds its anchor's
        material and may hold another piece's (at a tear) or none (a piece flung away); the strain part of C_a
        would carry it on ahead of a spreading front (a sand heap's). Without an anchor on the grid: the fit,
        or its own velocity where no node about it carries mass. It reads no state of another particle that
        G2P writes: the two run side by side.
        """
        p = wp.tid() + start
        if particles.free[p] != 0 or particles.mass[p] > 0.0:
            return
        velocity = grid.velocity
        if particles.own_ground[p] != 0:
            velocity = grid.unsupported_velocity
        dx = grid.dx
        base, fx = stencil_base(particles.x[p], grid.origin, 1.0 / dx, grid.shape)
        field_bits = int(0)
        if wp.static(n_fields == 2):
            field_bits = cracks.field_bits[p]
        anchor = riders.anchor[p]
        at = riders.anchor_position[p]
        offset = particles.x[p] - at
        follows = anchor >= 0 and on_grid(at, grid.origin, dx, grid.shape, grid.closed_faces, 0.0)
        vp = particles.v[p]
        Cp = wp.mat33(0.0)
        weight = float(0.0)
        if not follows or wp.length(offset) <= dx:
            vp_fit, Cp_fit, weight = gather_massless(velocity, grid.mass, field_bits, base, fx, dx)
            if weight > 0.0:
                vp = vp_fit
                Cp = Cp_fit
        if follows and weight <= 0.0:
            anchor_bits = int(0)
            if wp.static(n_fields == 2):
                anchor_bits = cracks.field_bits[anchor]  # written by particle_to_grid this substep, read only here
            anchor_base, anchor_fx = stencil_base(at, grid.origin, 1.0 / dx, grid.shape)
            va, Ca = gather(velocity, anchor_bits, anchor_base, anchor_fx, dx)
            vp = va + (0.5 * (Ca - wp.transpose(Ca))) * offset  # its spin, not its strain
            Cp = Ca
        advect(p, vp, Cp, substep, grid, particles)

    return grid_to_particle, ride


GRID_TO_PARTICLE, RIDE = {}, {}  # per number of fields: G2P of the particles with mass, and of the massless ones
for _n_fields in (1, 2):
    GRID_TO_PARTICLE[_n_fields], RIDE[_n_fields] = grid_to_particle_kernels(_n_fields)
PER_FIELD_COUNT = (PARTICLE_TO_GRID, MARK_RIDERS, GRID_UPDATE, GRID_TO_PARTICLE, RIDE)
"""The kernels made per number of fields, each {n_fields: kernel}; each kernel is a module of its own."""


@wp.kernel
def free_flight(start: int, substep: Step, grid: GridNodes, particles: Particles):
    """Particles off the grid: v += dt (g + f / m), x += dt v (symplectic Euler, as on the grid), the
    ground's contact law below its plane, F frozen. A particle a cell back inside the grid is marked to
    rejoin it (free = 2) at the next P2G."""
    p = wp.tid() + start
    if particles.free[p] != 1:
        return
    dt = substep.dt
    vp = particles.v[p] + dt * substep.gravity
    if particles.mass[p] > 0.0:
        vp += dt * particles.force[p] / particles.mass[p]
    if particles.prescribed[p] != 0:
        vp = particles.prescribed_velocity[p]
    xp = particles.x[p] + dt * vp
    ground_y = grid.origin[1] + float(grid.ground_node) * grid.dx
    if substep.ground_kind != GROUND_NONE and xp[1] <= ground_y:
        vp = ground_contact(vp, substep.ground_kind, substep.friction)
        xp = wp.vec3(xp[0], ground_y, xp[2])
    particles.x[p] = xp
    particles.v[p] = vp
    if on_grid(xp, grid.origin, grid.dx, grid.shape, grid.closed_faces, 1.0):
        particles.free[p] = 2


class MPMSolver:
    """State and substep of one MLS-MPM simulation.

    Particles (P of them, simulation frame): `x` (P,3) m, `v` (P,3) m/s, `C`
    (P,3,3) 1/s, `F` (P,3,3) elastic deformation gradient, `history` (P,)
    material history scalar, `mass` (P,) kg, `volume` (P,) m^3, `object_id`
    (P,), `free` (P,) flags of the particles off the grid. Conditions write
    `force` (P,3) N, `prescribed` (P,) flags and `prescribed_velocity` (P,3)
    m/s; `rigid` (rigid.RigidBodies or None) projects rigid objects after G2P.
    The kernels take these arrays grouped in `particles` (state.Particles), the
    grid in `nodes` (state.GridNodes) and the substep's length and laws in `step` (state.Step).

    `stiffening` is the largest hardening factor snow's stress may reach in the next substep; a caller
    sizes the substep for it (constitutive.wave_speed). It is the clamp's SNOW_HARDENING_MAX unless
    `follow_hardening`: then, after every substep, SNOW_HARDENING_GROWTH times the largest factor the
    snow's particles have, so that snow at rest steps at its own stiffness, not at the fivefold one its
    hardening may reach (docs/decisions/0039-granular-substeps.md).

    Args:
        walls: the domain's faces are slip walls; else only the ground (if any) closes it.
        follow_hardening: snow's stress stiffens at most to `stiffening`, which follows its particles.
    """

    def __init__(self, grid: Grid, positions: np.ndarray, masses: np.ndarray, volumes: np.ndarray,
                 object_id: np.ndarray, materials: list, gravity: np.ndarray, ground: Ground,
                 walls: bool = False, device: str = "cpu", n_parts: int | None = None,
                 follow_hardening: bool = False):
        self.grid, self.ground, self.walls, self.device = grid, ground, bool(walls), device
        self.gravity = wp.vec3(*np.asarray(gravity, dtype=np.float32))
        n = len(positions)
        self.n_particles = n
        cpu = wp.get_device(device).is_cpu
        self.n_parts = max(1, min(2, os.cpu_count() or 1)) if cpu else 1
        if n_parts is not None:
            self.n_parts = n_parts
        zeros3 = np.zeros((n, 3), np.float32)
        self.x = wp.array(np.asarray(positions, np.float32), dtype=wp.vec3, device=device)
        self.v = wp.array(zeros3, dtype=wp.vec3, device=device)
        self.C = wp.zeros(n, dtype=wp.mat33, device=device)
        self.F = wp.array(np.tile(np.eye(3, dtype=np.float32), (n, 1, 1)), dtype=wp.mat33, device=device)
        self.volume_stress = wp.zeros(n, dtype=wp.mat33, device=device)
        self.mass = wp.array(np.asarray(masses, np.float32), dtype=float, device=device)
        self._host_mass = np.asarray(masses, np.float64)  # follow() weighs the particles every few substeps
        self.volume = wp.array(np.asarray(volumes, np.float32), dtype=float, device=device)
        self.object_id = wp.array(np.asarray(object_id, np.int32), dtype=wp.int32, device=device)
        self._history0 = np.array([initial_history(m) for m in materials], np.float32)[np.asarray(object_id)]
        self.history = wp.array(self._history0, dtype=float, device=device)
        self.force = wp.zeros(n, dtype=wp.vec3, device=device)
        self.prescribed = wp.zeros(n, dtype=wp.int32, device=device)
        self.prescribed_velocity = wp.zeros(n, dtype=wp.vec3, device=device)
        self.free = wp.zeros(n, dtype=wp.int32, device=device)
        self.own_ground = wp.zeros(n, dtype=wp.int32, device=device)
        self.riders = Riders()
        self.riders.anchor = wp.array(anchors(positions, masses, object_id), dtype=wp.int32, device=device)
        self.riders.anchor_position = wp.zeros(n, dtype=wp.vec3, device=device)
        self._massless = bool(np.any(np.asarray(masses) <= 0))  # whether MARK_RIDERS and RIDE are launched
        self.materials = self._yielding = params_array(materials, device)
        self._elastic = params_array(materials, device, yielding=False)
        # per snow object (its index, its material), where the substep follows its hardening
        self._snow = [(k, m) for k, m in enumerate(materials) if m.preset == "snow"] if follow_hardening else []
        self._smallest_history = wp.empty(len(materials), dtype=float, device=device)
        self.stiffening = SNOW_HARDENING_MAX
        self.rigid = None
        self._pinned = None  # pin(): where substeps leave the particles
        self.particles = Particles()
        for name in Particles.vars:
            setattr(self.particles, name, getattr(self, name))

        nx, ny, nz = grid.shape
        # a second velocity field per node where a body can tear (crack_fields.py)
        self.n_fields = 2 if breaks(materials) else 1
        self.crack = CrackFields(grid.shape, n, device) if self.n_fields == 2 else CrackFields.unused(device)
        self.nodes = GridNodes()
        self.nodes.dx = grid.dx
        self.nodes.shape = wp.vec3i(nx, ny, nz)
        self.nodes.n_parts = self.n_parts
        self.nodes.momentum_mass = wp.zeros((self.n_parts * self.n_fields, nx, ny, nz), dtype=wp.vec4, device=device)
        self.nodes.velocity = wp.zeros((self.n_fields, nx, ny, nz), dtype=wp.vec3, device=device)
        self.nodes.mass = wp.zeros((self.n_fields, nx, ny, nz), dtype=float, device=device)
        self.nodes.unsupported_velocity = self.nodes.velocity  # its own array once rigid bodies are attached
        self.step = Step()
        self.step.gravity = self.gravity
        self.step.ground_kind = ground.kind
        self.step.friction = ground.friction
        self.step.walls = int(self.walls)
        self.step.keep_unsupported = 0
        self.ground_height = grid.origin[1] + BOUNDARY_NODES * grid.dx if ground.height is None else ground.height
        # the grid never reaches below where it starts: the ground (if any) stays on it
        self._lowest_origin = grid.origin[1]
        self._move_to(np.asarray(grid.origin, np.float64))
        # particle ranges, one per thread
        self._ranges = _split(n, self.n_parts)
        self._pool = ThreadPoolExecutor(self.n_parts) if self.n_parts > 1 else None
        self._corners = wp.zeros(6, dtype=wp.int32, device=device)  # stencil_node_box's output
        self._no_corners = np.array([nx, ny, nz, -1, -1, -1], np.int32)  # its start: an empty box
        self._follow_hardening()
        # compile before threads race to it and before the first substep, whose time the run's estimate
        # takes for a substep's: the kernels made per field count each live in a module of their own
        wp.load_module("stages.simulate", device=device, recursive=True)
        for kernels in PER_FIELD_COUNT:
            wp.load_module(kernels[self.n_fields].module, device=device)

    def _parallel(self, launches):
        """Run launch closures concurrently (one per thread on the CPU)."""
        if self._pool is None:
            for launch in launches:
                launch()
        else:
            for future in [self._pool.submit(launch) for launch in launches]:
                future.result()

    def _per_particle(self, *steps):
        """Run (kernel, args_of_start) steps over the particles, each thread its own range through all steps.

        Steps that read and write only their own particles need no barrier
        between them, so a thread goes on to the next without waiting.
        """
        def run_range(start: int, count: int, part: int) -> None:
            for kernel, args_of_start in steps:
                wp.launch(kernel, dim=count, inputs=args_of_start(start, part), device=self.device)

        self._parallel([
            (lambda s=s, c=c, part=part: run_range(s, c, part))
            for part, (s, c) in enumerate(self._ranges) if c > 0
        ])

    def _active_nodes(self) -> tuple[np.ndarray, np.ndarray]:
        """Node box [lo, hi) that the particles' stencils touch.

        On the CPU only these nodes are updated (and cleared for the next
        P2G), a few percent of the grid for a compact object; on a GPU the
        whole grid is cheaper than the host round trip. The box comes from a
        kernel pass over the particles (a numpy pass cost ten times more).
        """
        shape = np.array(self.grid.shape)
        if not wp.get_device(self.device).is_cpu:
            return np.zeros(3, int), shape
        self._corners.assign(self._no_corners)
        wp.launch(stencil_node_box, dim=self.n_particles, device=self.device,
                  inputs=[self.particles, self.nodes, self._corners])
        corners = self._corners.numpy()
        return corners[:3].astype(int), corners[3:].astype(int) + 3

    def substep(self, dt: float) -> None:
        """Advance all particles by dt seconds."""
        step, cracks, nodes, particles, riders = self.step, self.crack.state, self.nodes, self.particles, self.riders
        step.dt, step.stiffening = dt, self.stiffening
        if self.n_fields == 2:
            self.crack.find(self)
        p2g = [(PARTICLE_TO_GRID[self.n_fields], lambda s, part: [s, part, step, particles, cracks, nodes])]
        if self._massless:
            p2g.append((MARK_RIDERS[self.n_fields], lambda s, part: [s, particles, riders, cracks, nodes]))
        self._per_particle(*p2g)
        lo, hi = self._active_nodes()
        if np.all(hi > lo):  # else every particle is off the grid
            update = GRID_UPDATE[self.n_fields]
            self._parallel([
                (lambda s=s, c=c: wp.launch(update, dim=(c, hi[1] - lo[1], hi[2] - lo[2]), device=self.device,
                                            inputs=[wp.vec3i(s, lo[1], lo[2]), step, cracks, nodes]))
                for s, c in _split(hi[0] - lo[0], self.n_parts, lo[0]) if c > 0
            ])
        g2p = [(GRID_TO_PARTICLE[self.n_fields], lambda s, part: [s, step, cracks, nodes, particles])]
        if self._massless:
            g2p.append((RIDE[self.n_fields], lambda s, part: [s, step, cracks, nodes, particles, riders]))
        flight = (free_flight, lambda s, part: [s, step, nodes, particles])
        stress = (update_stress, lambda s, part: [s, step, self.materials, particles])
        if self.rigid is None:
            self._per_particle(flight, *g2p, stress)
        else:  # the rigid projection gathers every rigid particle's G2P velocity first
            self._per_particle(flight, *g2p)
            self.rigid.project(self, dt)
            self._per_particle(stress)
        if self._pinned is not None:
            wp.copy(self.x, self._pinned)
        self._follow_hardening()

    @property
    def hardening_followed(self) -> bool:
        """Whether `stiffening` follows snow's particles, and with it the substep their callers size."""
        return bool(self._snow)

    def _follow_hardening(self) -> None:
        """Set `stiffening` to SNOW_HARDENING_GROWTH times the snow particles' largest hardening factor."""
        if not self._snow:
            return
        self._smallest_history.fill_(np.inf)
        wp.launch(smallest_history, dim=self.n_particles, device=self.device,
                  inputs=[self.object_id, self.history, self._smallest_history])
        smallest = self._smallest_history.numpy()  # one value per object: no copy of the particles' histories
        largest = max(float(snow_hardening(m, smallest[k])) for k, m in self._snow)
        self.stiffening = min(SNOW_HARDENING_MAX, SNOW_HARDENING_GROWTH * largest)

    def hold_yield(self, held: bool) -> None:
        """With `held`, the solids that yield or break (constitutive.YIELDING_SOLIDS) respond elastically only."""
        self.materials = self._elastic if held else self._yielding

    def pin(self, pinned: bool) -> None:
        """With `pinned`, substeps leave every particle where it is now: velocities, C, F and stress evolve as
        usual, positions do not, so the grid's forces are those of this one configuration (the settle solves
        the equilibrium of the photographed geometry, rest_state.py)."""
        self._pinned = wp.clone(self.x) if pinned else None

    def attach_rigid(self, rigid) -> None:
        """Let a rigid.RigidBodies move its members after G2P; they meet the ground as whole bodies."""
        self.rigid = rigid
        self.nodes.unsupported_velocity = wp.zeros_like(self.nodes.velocity)
        self.step.keep_unsupported = 1
        flags = np.zeros(self.n_particles, np.int32)
        flags[rigid.members.numpy()] = 1
        self.own_ground.assign(flags)

    def reset(self, positions: np.ndarray, keep: np.ndarray) -> None:
        """Put every particle back at `positions` (P,3), at rest and on the grid; the `keep` (P,) bool
        particles keep their F, history and stress, the others start unstrained."""
        keep = np.asarray(keep, bool)
        self.x.assign(np.asarray(positions, np.float32))
        for state in (self.v, self.C, self.free, self.prescribed, self.prescribed_velocity, self.force):
            state.zero_()
        eye = np.eye(3, dtype=np.float32)
        self.F.assign(np.where(keep[:, None, None], self.F.numpy(), eye))
        self.history.assign(np.where(keep, self.history.numpy(), self._history0))
        self.volume_stress.assign(np.where(keep[:, None, None], self.volume_stress.numpy(), 0.0).astype(np.float32))
        self._follow_hardening()

    def _move_to(self, origin: np.ndarray) -> None:
        """Put the grid's node (0, 0, 0) at `origin` (3,) m; the ground stays on its node plane."""
        self.grid = Grid(origin=tuple(float(o) for o in origin), dx=self.grid.dx, shape=self.grid.shape)
        self.nodes.origin = wp.vec3(*origin.astype(np.float32))
        self.nodes.ground_node = int(round((self.ground_height - origin[1]) / self.grid.dx))
        on_floor = self.ground.kind != GROUND_NONE and self.nodes.ground_node >= BOUNDARY_NODES
        self.nodes.closed_faces = wp.vec3i(2, 2, 2) if self.walls else wp.vec3i(0, int(on_floor), 0)

    def follow(self, margin: int) -> None:
        """Move the grid by whole cells so that every particle lies `margin` cells inside its wall layer.

        Where the particles spread wider than that allows, the grid centres on their centre of mass
        along that axis and the outliers fly freely. It never moves below where it started (the
        ground), and never with walls, which are its faces.
        """
        if self.walls:
            return
        x = self.x.numpy().astype(np.float64)
        if not np.isfinite(x).all():
            return  # blown up: the caller's check says so at the end of the frame
        dx, shape = self.grid.dx, np.asarray(self.grid.shape)
        origin = np.asarray(self.grid.origin)
        inner = BOUNDARY_NODES + margin  # cells from a face to the nearest allowed particle
        along_axes = np.ascontiguousarray(x.T)  # (3, P): numpy reduces a (P, 3) array over P ten times slower
        lo, hi = along_axes.min(axis=1), along_axes.max(axis=1)
        fits = (hi - lo) <= (shape - 1 - 2 * inner) * dx
        low_shift = np.floor((lo - origin) / dx - inner)  # cells the grid may move up and keep lo inside
        high_shift = np.ceil((hi - origin) / dx - (shape - 1 - inner))  # cells it must move to hold hi
        centre = self._host_mass @ x / self._host_mass.sum()
        centred = np.round((centre - origin) / dx - (shape - 1) / 2)
        shift = np.where(fits, np.where(high_shift > 0, high_shift, np.minimum(low_shift, 0)), centred)
        new = origin + shift * dx
        if self.ground.kind != GROUND_NONE:
            new[1] = max(new[1], self._lowest_origin)
        if np.any(new != origin):
            self._move_to(new)

    def n_free(self) -> int:
        """Particles off the grid now."""
        return int(np.count_nonzero(self.free.numpy() == 1))

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None


def anchors(positions: np.ndarray, masses: np.ndarray, object_id: np.ndarray) -> np.ndarray:
    """(P,) int32: for each massless particle the nearest particle with mass of its object at `positions`
    (P,3) m, -1 for the particles with mass and where its object has none (masses (P,) kg, object_id (P,))."""
    masses, object_id = np.asarray(masses), np.asarray(object_id)
    out = np.full(len(masses), -1, np.int32)
    for k in np.unique(object_id):
        massive = np.flatnonzero((object_id == k) & (masses > 0))
        massless = np.flatnonzero((object_id == k) & (masses <= 0))
        if len(massive) and len(massless):
            out[massless] = massive[cKDTree(positions[massive]).query(positions[massless])[1]]
    return out


def _split(n: int, parts: int, first: int = 0) -> list[tuple[int, int]]:
    """(start, count) of `parts` contiguous ranges covering first .. first + n - 1."""
    edges = first + np.linspace(0, n, parts + 1).astype(int)
    return [(int(a), int(b - a)) for a, b in zip(edges[:-1], edges[1:])]
