"""Two velocity fields per grid node across a crack (DFG: Homel & Herbold 2017; Wolper et al. 2019).

One velocity per node cannot open a crack. The nodes between the two sides of a tear take both
sides' momentum, so the broken material there is dragged along the kernel's velocity ramp (3
cells wide) and the material next to it is stretched until it breaks too: a band of dust between
the pieces instead of two torn faces.

Here each particle meets each node of its stencil in one of two fields: field 0 where its damage
gradient points the way of the node's steepest one (the largest |grad D| among the particles
there), field 1 where it points against it. The particles on either side of the ridge of damage
(the crack) meet in different fields. The fields of a node are bound by what is left of the
material there (crack_contact): undamaged they move as one field would, and they move apart
freely as the damage near the node goes to 1, so the material's toughness still sets how far it
stretches before it tears; where they approach, they meet (frictionless contact). A node with
no damage near it has one field. The binding matters: split only where damage is 1, with no
binding, the material beside a crack keeps breaking until the split comes (2 % of the torn test
ball's particles fly loose between the pieces, 0.7 % bound; docs/decisions/0003-crack-fields.md).

Per substep, before P2G (only for scenes with a fracture object):
  damage_to_grid           node damage (the mass-weighted mean) and the largest damage near the node
  damage_gradient          each particle's grad D, the MLS gradient of the node damage (as C is of v)
  steepest_gradient        each node's steepest grad D_p among the particles of its stencil, the
                           node's crack direction (two launches: the largest norm, then its gradient)
"""
from __future__ import annotations

import warp as wp

from .constitutive import FRACTURE, MaterialParams
from .state import Cracks, GridNodes, Particles
from .stencil import stencil_base, stencil_weights


@wp.kernel
def damage_to_grid(materials: wp.array(dtype=MaterialParams), particles: Particles, grid: GridNodes, cracks: Cracks):
    """Scatter w_ip (m_p D_p, m_p) and the largest D_p to the nodes (D = 0 for materials that do not break)."""
    p = wp.tid()
    if particles.free[p] == 1:
        return
    damage = float(0.0)
    if materials[particles.object_id[p]].kind == FRACTURE:
        damage = particles.history[p]
    mass = particles.mass
    base, fx = stencil_base(particles.x[p], grid.origin, 1.0 / grid.dx, grid.shape)
    weights = stencil_weights(fx)
    for i in range(3):
        for j in range(3):
            for k in range(3):
                w = weights[0, i] * weights[1, j] * weights[2, k]
                wp.atomic_add(cracks.node_damage_mass, base[0] + i, base[1] + j, base[2] + k,
                              w * wp.vec2(mass[p] * damage, mass[p]))
                wp.atomic_max(cracks.node_max_damage, base[0] + i, base[1] + j, base[2] + k, damage)


@wp.kernel
def damage_gradient(start: int, particles: Particles, grid: GridNodes, cracks: Cracks):
    """grad D_p = (4 / dx^2) sum_i w_ip D_i (x_i - x_p), 1/m, with D_i the node's mass-weighted damage."""
    p = wp.tid() + start
    if particles.free[p] == 1:
        return
    dx = grid.dx
    base, fx = stencil_base(particles.x[p], grid.origin, 1.0 / dx, grid.shape)
    weights = stencil_weights(fx)
    g = wp.vec3(0.0)
    for i in range(3):
        for j in range(3):
            for k in range(3):
                node = cracks.node_damage_mass[base[0] + i, base[1] + j, base[2] + k]
                offset = dx * (wp.vec3(float(i), float(j), float(k)) - fx)
                g += (weights[0, i] * weights[1, j] * weights[2, k] * node[0] / node[1]) * offset
    cracks.gradient[p] = (4.0 / (dx * dx)) * g


@wp.kernel
def steepest_gradient(select: int, particles: Particles, grid: GridNodes, cracks: Cracks):
    """The node's crack direction, the grad D_p of largest norm among the particles whose stencil
    holds it, in two launches: select 0 takes each node's largest |grad D_p|, select 1 writes the
    gradient that has it (ties write equal norms; any one will do)."""
    p = wp.tid()
    if particles.free[p] == 1:
        return
    base, fx = stencil_base(particles.x[p], grid.origin, 1.0 / grid.dx, grid.shape)
    gradient = cracks.gradient[p]
    norm = wp.length(gradient)
    if select == 1 and norm <= 0.0:
        return
    for i in range(3):
        for j in range(3):
            for k in range(3):
                node = wp.vec3i(base[0] + i, base[1] + j, base[2] + k)
                if select == 0:
                    wp.atomic_max(cracks.node_gradient_norm, node[0], node[1], node[2], norm)
                elif norm >= cracks.node_gradient_norm[node[0], node[1], node[2]]:
                    cracks.node_direction[node[0], node[1], node[2]] = gradient


@wp.func
def crack_field(damage: float, direction: wp.vec3, gradient: wp.vec3):
    """Field (0 or 1) in which a particle of damage gradient `gradient` meets a node (`damage`: the
    largest near the node, `direction`: its crack direction)."""
    if damage > 0.0 and wp.dot(gradient, direction) < 0.0:
        return 1
    return 0


@wp.func
def crack_contact(v0: wp.vec3, m0: float, v1: wp.vec3, m1: float, direction: wp.vec3, damage: float):
    """Node velocities of the two fields of a crack, bound by what is left of the material.

    Each field keeps the fraction `damage` (the largest near the node) of its velocity relative
    to the pair's centre of mass v_cm: undamaged, both move at v_cm as one field would; broken,
    they move freely. Field 0 lies on the -direction side (its particles' damage rises along
    `direction`), so they approach where (v0 - v1) . n > 0, and there they also meet: no relative
    velocity along n is left. Every change is a multiple of v_k - v_cm common to both fields, so
    their momentum is conserved.
    """
    v_cm = (m0 * v0 + m1 * v1) / (m0 + m1)
    r0 = v0 - v_cm
    r1 = v1 - v_cm
    n = wp.normalize(direction)
    if wp.dot(v0 - v1, n) > 0.0:
        r0 = r0 - wp.dot(r0, n) * n
        r1 = r1 - wp.dot(r1, n) * n
    return v_cm + damage * r0, v_cm + damage * r1


class CrackFields:
    """The crack arrays (`state`, a state.Cracks: node arrays of shape (nx, ny, nz), particle arrays
    (P,)) and the passes that fill them."""

    def __init__(self, shape: tuple[int, int, int], n_particles: int, device: str):
        self.device = device
        self.state = Cracks()
        self.state.node_damage_mass = wp.zeros(shape, dtype=wp.vec2, device=device)
        self.state.node_max_damage = wp.zeros(shape, dtype=float, device=device)
        self.state.node_gradient_norm = wp.zeros(shape, dtype=float, device=device)
        self.state.node_direction = wp.zeros(shape, dtype=wp.vec3, device=device)
        self.state.gradient = wp.zeros(n_particles, dtype=wp.vec3, device=device)
        self.state.field_bits = wp.zeros(n_particles, dtype=wp.int32, device=device)

    @staticmethod
    def unused(device: str) -> "CrackFields":
        """One-element stand-ins for the kernels' arguments where no object breaks."""
        return CrackFields((1, 1, 1), 1, device)

    def find(self, solver) -> None:
        """Fill the node arrays from the particles' damage (solver: mpm.MPMSolver, before its P2G).

        The scatters use atomic maxima and sums, so they run as one launch (a CPU launch is one
        thread, and the copies of P2G's parallel scatter are not needed for four small arrays)."""
        n, state = solver.n_particles, [solver.particles, solver.nodes, self.state]
        wp.launch(damage_to_grid, dim=n, device=self.device, inputs=[solver.materials, *state])
        solver._per_particle((damage_gradient, lambda s, part: [s, *state]))
        for select in (0, 1):  # the largest norm at every node must be known before the one that has it
            wp.launch(steepest_gradient, dim=n, device=self.device, inputs=[select, *state])


def breaks(materials: list) -> bool:
    """Whether any of the objects' materials (schemas.materials models) can tear."""
    return any(m.preset == "fracture" for m in materials)

