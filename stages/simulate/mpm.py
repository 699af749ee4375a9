"""MLS-MPM with APIC transfer and quadratic B-splines (Hu et al. 2018), in Warp.

All quantities live in the *simulation frame*: metres, with gravity along -y
(see domain.py), so the ground is the grid plane y = ground_node * dx.

One substep, one kernel per physical step:
  particle_to_grid   scatter mass and APIC momentum plus stress and external forces
  grid_update        momentum -> velocity, gravity, ground and wall conditions
  grid_to_particle   gather velocity and its gradient C, advect, F <- (I + dt C) F
  rigid projection   (rigid.py) rigid objects follow one rigid motion
  update_stress      (constitutive.py) return mapping and Kirchhoff stress

On the CPU each particle kernel is split into `n_parts` ranges launched from
their own Python threads (a Warp CPU launch runs on one thread); P2G scatters
each range into its own grid copy (momentum and mass together, one vec4 per
node) so the copies never race, and the grid update sums them. The grid
update visits only the box of nodes that the particles' stencils touch
(`stencil_node_box`), which is also all it needs to clear for the next P2G.
"""
from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import warp as wp

from .constitutive import initial_history, params_array, update_stress

# Nodes this close to a domain face form the wall layer; particles are kept
# this far inside, so a quadratic stencil never leaves the grid.
BOUNDARY_NODES = 3

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
    """Ground plane y = ground_node * dx (+ origin) with its contact law."""

    kind: int = GROUND_NONE  # GROUND_NONE | GROUND_STICKY | GROUND_SLIP | GROUND_FRICTION
    friction: float = 0.0  # Coulomb coefficient (GROUND_FRICTION)
    ground_node: int = BOUNDARY_NODES


@wp.func
def stencil_base(x: wp.vec3, origin: wp.vec3, inv_dx: float, shape: wp.vec3i):
    """Lower corner node of the 3x3x3 quadratic stencil of x, clamped onto the grid, and x in cell units."""
    xg = (x - origin) * inv_dx
    base = wp.vec3i(
        wp.clamp(int(wp.floor(xg[0] - 0.5)), 0, shape[0] - 3),
        wp.clamp(int(wp.floor(xg[1] - 0.5)), 0, shape[1] - 3),
        wp.clamp(int(wp.floor(xg[2] - 0.5)), 0, shape[2] - 3),
    )
    return base, xg - wp.vec3(float(base[0]), float(base[1]), float(base[2]))


@wp.func
def quadratic_weights(fx: float):
    """Quadratic B-spline weights of the three nodes at distances fx, fx - 1, fx - 2 (cells)."""
    return wp.vec3(0.5 * (1.5 - fx) * (1.5 - fx), 0.75 - (fx - 1.0) * (fx - 1.0), 0.5 * (fx - 0.5) * (fx - 0.5))


@wp.kernel
def particle_to_grid(
    start: int,
    part: int,
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    C: wp.array(dtype=wp.mat33),
    mass: wp.array(dtype=float),
    volume_stress: wp.array(dtype=wp.mat33),
    force: wp.array(dtype=wp.vec3),
    origin: wp.vec3,
    dx: float,
    dt: float,
    shape: wp.vec3i,
    grid_momentum_mass: wp.array4d(dtype=wp.vec4),
):
    """Scatter m_p, APIC momentum m_p (v_p + C_p (x_i - x_p)), stress force and external force to the grid.

    Node i of the stencil receives w_ip (m_p v_p + dt f_p + A_p (x_i - x_p), m_p) as one vec4.
    """
    p = wp.tid() + start
    inv_dx = 1.0 / dx
    base, fx = stencil_base(x[p], origin, inv_dx, shape)
    wx = quadratic_weights(fx[0])
    wy = quadratic_weights(fx[1])
    wz = quadratic_weights(fx[2])
    m = mass[p]
    # MLS-MPM: the stress force enters as an affine term, -dt V tau M^-1 with M^-1 = 4 / dx^2
    affine = m * C[p] - (4.0 * dt * inv_dx * inv_dx) * volume_stress[p]
    # x_i - x_p = dx ((i, j, k) - fx), so the node momentum is linear in (i, j, k): start from the
    # stencil corner and add one column of dx A_p per node step along each axis (3 adds, not a mat-vec)
    step = wp.transpose(dx * affine)  # row a: momentum change per node step along axis a
    corner = m * v[p] + dt * force[p] - dx * (affine * fx)
    for i in range(3):
        momentum_i = corner + float(i) * step[0]
        for j in range(3):
            momentum_ij = momentum_i + float(j) * step[1]
            w_ij = wx[i] * wy[j]
            for k in range(3):
                momentum = momentum_ij + float(k) * step[2]
                w = w_ij * wz[k]
                wp.atomic_add(grid_momentum_mass, part, base[0] + i, base[1] + j, base[2] + k,
                              w * wp.vec4(momentum[0], momentum[1], momentum[2], m))


@wp.kernel
def stencil_node_box(
    x: wp.array(dtype=wp.vec3),
    origin: wp.vec3,
    dx: float,
    shape: wp.vec3i,
    corners: wp.array(dtype=wp.int32),
):
    """Smallest (corners[0:3]) and largest (corners[3:6]) stencil corner node of all particles per axis."""
    p = wp.tid()
    base, fx = stencil_base(x[p], origin, 1.0 / dx, shape)
    for a in range(3):
        wp.atomic_min(corners, a, base[a])
        wp.atomic_max(corners, 3 + a, base[a])


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


@wp.kernel
def grid_update(
    offset: wp.vec3i,
    n_parts: int,
    gravity: wp.vec3,
    dt: float,
    shape: wp.vec3i,
    ground_kind: int,
    ground_node: int,
    friction: float,
    grid_momentum_mass: wp.array4d(dtype=wp.vec4),
    grid_velocity: wp.array3d(dtype=wp.vec3),
):
    """v_i = (sum of momenta) / (sum of masses) + dt g, then ground and walls; clears the P2G copies."""
    i, j, k = wp.tid()
    i += offset[0]
    j += offset[1]
    k += offset[2]
    total = wp.vec4(0.0)
    for part in range(n_parts):
        total += grid_momentum_mass[part, i, j, k]
        grid_momentum_mass[part, i, j, k] = wp.vec4(0.0)
    m = total[3]
    v = wp.vec3(0.0)
    if m > 0.0:
        v = wp.vec3(total[0], total[1], total[2]) / m + dt * gravity
        if ground_kind != GROUND_NONE and j <= ground_node:
            v = ground_contact(v, ground_kind, friction)
        v = wall_slip(v, wp.vec3i(i, j, k), shape)
    grid_velocity[i, j, k] = v


@wp.kernel
def grid_to_particle(
    start: int,
    grid_velocity: wp.array3d(dtype=wp.vec3),
    origin: wp.vec3,
    dx: float,
    dt: float,
    shape: wp.vec3i,
    prescribed: wp.array(dtype=wp.int32),
    prescribed_velocity: wp.array(dtype=wp.vec3),
    x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    C: wp.array(dtype=wp.mat33),
    F: wp.array(dtype=wp.mat33),
):
    """Gather v_p and the APIC affine velocity C_p, advect x_p, and update the trial F_p = (I + dt C_p) F_p."""
    p = wp.tid() + start
    inv_dx = 1.0 / dx
    base, fx = stencil_base(x[p], origin, inv_dx, shape)
    wx = quadratic_weights(fx[0])
    wy = quadratic_weights(fx[1])
    wz = quadratic_weights(fx[2])
    # node offsets times weights, o_a = w_a (node - fx_a) dx, per axis
    ox = wp.cw_mul(wx, wp.vec3(0.0, 1.0, 2.0) - wp.vec3(fx[0])) * dx
    oy = wp.cw_mul(wy, wp.vec3(0.0, 1.0, 2.0) - wp.vec3(fx[1])) * dx
    oz = wp.cw_mul(wz, wp.vec3(0.0, 1.0, 2.0) - wp.vec3(fx[2])) * dx
    # v_p = sum w v_i and column a of B = sum w v_i (x_i - x_p)_a; the weights are products
    # wx wy wz, so both sums are taken one axis at a time (k, then j, then i)
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
                vi = grid_velocity[base[0] + i, base[1] + j, base[2] + k]
                v_ij += wz[k] * vi
                vz_ij += oz[k] * vi
            v_i += wy[j] * v_ij
            vy_i += oy[j] * v_ij
            vz_i += wy[j] * vz_ij
        vp += wx[i] * v_i
        Bx += ox[i] * v_i
        By += wx[i] * vy_i
        Bz += wx[i] * vz_i
    Cp = (4.0 * inv_dx * inv_dx) * wp.matrix_from_cols(Bx, By, Bz)
    if prescribed[p] != 0:
        vp = prescribed_velocity[p]  # velocity and fixed conditions override the grid
    # keep particles off the wall layer so every stencil stays on the grid
    lo = float(BOUNDARY_NODES) * dx
    xp = x[p] + dt * vp - origin
    xp = wp.vec3(
        wp.clamp(xp[0], lo, float(shape[0] - 1) * dx - lo),
        wp.clamp(xp[1], lo, float(shape[1] - 1) * dx - lo),
        wp.clamp(xp[2], lo, float(shape[2] - 1) * dx - lo),
    )
    x[p] = xp + origin
    v[p] = vp
    C[p] = Cp
    F[p] = (wp.identity(n=3, dtype=float) + dt * Cp) * F[p]


class MPMSolver:
    """State and substep of one MLS-MPM simulation.

    Particles (P of them, simulation frame): `x` (P,3) m, `v` (P,3) m/s, `C`
    (P,3,3) 1/s, `F` (P,3,3) elastic deformation gradient, `history` (P,)
    material history scalar, `mass` (P,) kg, `volume` (P,) m^3, `object_id`
    (P,). Conditions write `force` (P,3) N, `prescribed` (P,) flags and
    `prescribed_velocity` (P,3) m/s; `rigid` (rigid.RigidBodies or None)
    projects rigid objects after G2P.
    """

    def __init__(self, grid: Grid, positions: np.ndarray, masses: np.ndarray, volumes: np.ndarray,
                 object_id: np.ndarray, materials: list, gravity: np.ndarray, ground: Ground,
                 device: str = "cpu", n_parts: int | None = None):
        self.grid, self.ground, self.device = grid, ground, device
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
        self.volume = wp.array(np.asarray(volumes, np.float32), dtype=float, device=device)
        self.object_id = wp.array(np.asarray(object_id, np.int32), dtype=wp.int32, device=device)
        history = np.array([initial_history(m) for m in materials], np.float32)[np.asarray(object_id)]
        self.history = wp.array(history, dtype=float, device=device)
        self.force = wp.zeros(n, dtype=wp.vec3, device=device)
        self.prescribed = wp.zeros(n, dtype=wp.int32, device=device)
        self.prescribed_velocity = wp.zeros(n, dtype=wp.vec3, device=device)
        self.materials = params_array(materials, device)
        self.rigid = None

        nx, ny, nz = grid.shape
        self.grid_momentum_mass = wp.zeros((self.n_parts, nx, ny, nz), dtype=wp.vec4, device=device)
        self.grid_velocity = wp.zeros((nx, ny, nz), dtype=wp.vec3, device=device)
        self._origin = wp.vec3(*np.asarray(grid.origin, np.float32))
        self._shape = wp.vec3i(nx, ny, nz)
        # particle ranges, one per thread
        self._ranges = _split(n, self.n_parts)
        self._pool = ThreadPoolExecutor(self.n_parts) if self.n_parts > 1 else None
        self._corners = wp.zeros(6, dtype=wp.int32, device=device)  # stencil_node_box's output
        self._no_corners = np.array([nx, ny, nz, -1, -1, -1], np.int32)  # its start: an empty box
        wp.load_module("stages.simulate", device=device, recursive=True)  # compile before threads race to

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
                  inputs=[self.x, self._origin, self.grid.dx, self._shape, self._corners])
        corners = self._corners.numpy()
        return corners[:3].astype(int), corners[3:].astype(int) + 3

    def substep(self, dt: float) -> None:
        """Advance all particles by dt seconds."""
        g, dev = self.grid, self.device
        self._per_particle((particle_to_grid, lambda s, part: [
            s, part, self.x, self.v, self.C, self.mass, self.volume_stress, self.force,
            self._origin, g.dx, dt, self._shape, self.grid_momentum_mass]))
        lo, hi = self._active_nodes()
        self._parallel([
            (lambda s=s, c=c: wp.launch(grid_update, dim=(c, hi[1] - lo[1], hi[2] - lo[2]), device=dev, inputs=[
                wp.vec3i(s, lo[1], lo[2]), self.n_parts, self.gravity, dt, self._shape, self.ground.kind,
                self.ground.ground_node, self.ground.friction, self.grid_momentum_mass, self.grid_velocity]))
            for s, c in _split(hi[0] - lo[0], self.n_parts, lo[0]) if c > 0
        ])
        g2p = (grid_to_particle, lambda s, part: [
            s, self.grid_velocity, self._origin, g.dx, dt, self._shape, self.prescribed,
            self.prescribed_velocity, self.x, self.v, self.C, self.F])
        stress = (update_stress, lambda s, part: [
            s, self.materials, self.object_id, self.volume, dt, self.F, self.history, self.volume_stress])
        if self.rigid is None:
            self._per_particle(g2p, stress)
        else:  # the rigid projection gathers every rigid particle's G2P velocity first
            self._per_particle(g2p)
            self.rigid.project(self, dt)
            self._per_particle(stress)

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None


def _split(n: int, parts: int, first: int = 0) -> list[tuple[int, int]]:
    """(start, count) of `parts` contiguous ranges covering first .. first + n - 1."""
    edges = first + np.linspace(0, n, parts + 1).astype(int)
    return [(int(a), int(b - a)) for a, b in zip(edges[:-1], edges[1:])]
