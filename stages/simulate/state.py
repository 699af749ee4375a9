"""The MPM solver's state as Warp structs, the arguments its kernels share.

A kernel takes the few structs it needs (mpm.py, crack_fields.py, constitutive.py) rather than a
long list of arrays, so a kernel's signature says which state it reads and writes. A struct holds
references to the solver's arrays: writing an element through it writes the solver's array.
Everything is in the simulation frame (metres, gravity along -y; domain.py).
"""
from __future__ import annotations

import warp as wp


@wp.struct
class Particles:
    """Per-particle state, P particles."""

    x: wp.array(dtype=wp.vec3)  # (P,) position, m
    v: wp.array(dtype=wp.vec3)  # (P,) velocity, m/s
    C: wp.array(dtype=wp.mat33)  # (P,) APIC affine velocity, 1/s
    F: wp.array(dtype=wp.mat33)  # (P,) elastic deformation gradient
    history: wp.array(dtype=float)  # (P,) material history scalar (constitutive.py)
    volume_stress: wp.array(dtype=wp.mat33)  # (P,) rest volume times Kirchhoff stress, N m
    mass: wp.array(dtype=float)  # (P,) kg
    volume: wp.array(dtype=float)  # (P,) rest volume, m^3
    object_id: wp.array(dtype=wp.int32)  # (P,) index of the object's MaterialParams
    force: wp.array(dtype=wp.vec3)  # (P,) external force of the conditions, N
    prescribed: wp.array(dtype=wp.int32)  # (P,) 1 where a condition sets the velocity
    prescribed_velocity: wp.array(dtype=wp.vec3)  # (P,) that velocity, m/s
    free: wp.array(dtype=wp.int32)  # (P,) 0 on the grid, 1 off it (free flight), 2 rejoining at the next P2G
    own_ground: wp.array(dtype=wp.int32)  # (P,) 1 for bodies that meet the ground as a whole (rigid.py)


@wp.struct
class Riders:
    """The massless particles' anchors: each follows its anchor's motion where its own stencil cannot (mpm.ride)."""

    anchor: wp.array(dtype=wp.int32)  # (P,) a massless particle's nearest massive one of its object at rest
    # (mpm.anchors), whose crack side it takes; -1 for the others
    anchor_position: wp.array(dtype=wp.vec3)  # (P,) where a massless particle's anchor is at this P2G, m


@wp.struct
class GridNodes:
    """The background grid where it is now: node (i, j, k) at origin + dx (i, j, k), and its node arrays."""

    origin: wp.vec3  # node (0, 0, 0), m
    dx: float  # node spacing, m
    shape: wp.vec3i  # nodes per axis
    closed_faces: wp.vec3i  # per axis: 0 open, 1 the low face closed (the ground), 2 both faces (walls)
    ground_node: int  # the ground's node plane j
    n_parts: int  # particle ranges, each scattering into its own copies of momentum_mass
    momentum_mass: wp.array4d(dtype=wp.vec4)  # (n_parts * fields, nx, ny, nz) P2G's (momentum kg m/s, mass kg)
    velocity: wp.array4d(dtype=wp.vec3)  # (fields, nx, ny, nz) m/s after the ground's contact law
    unsupported_velocity: wp.array4d(dtype=wp.vec3)  # (fields, nx, ny, nz) m/s before it (rigid bodies)
    mass: wp.array4d(dtype=float)  # (fields, nx, ny, nz) kg, the grid update's (G2P of massless particles)


@wp.struct
class Cracks:
    """The crack direction per node and each particle's side of it (crack_fields.py); one-element
    stand-ins where no object can tear."""

    node_damage_mass: wp.array3d(dtype=wp.vec2)  # (nx, ny, nz) sum of w m D, sum of w m
    node_max_damage: wp.array3d(dtype=float)  # (nx, ny, nz) largest damage near the node
    node_gradient_norm: wp.array3d(dtype=float)  # (nx, ny, nz) largest |grad D| near the node, 1/m
    node_direction: wp.array3d(dtype=wp.vec3)  # (nx, ny, nz) the grad D that has it: the crack direction
    gradient: wp.array(dtype=wp.vec3)  # (P,) each particle's damage gradient grad D, 1/m
    field_bits: wp.array(dtype=wp.int32)  # (P,) bit 9 i + 3 j + k: the field of stencil node (i, j, k)


@wp.struct
class Step:
    """One substep's length and the laws that act on the grid and the particles' stress."""

    dt: float  # s
    stiffening: float  # the largest hardening factor snow's stress reaches (mpm.MPMSolver.stiffening)
    gravity: wp.vec3  # m/s^2
    ground_kind: int  # mpm.GROUND_NONE ... GROUND_FRICTION
    friction: float  # Coulomb coefficient of the ground
    walls: int  # 1: the domain's faces are slip walls
    keep_unsupported: int  # 1: keep the velocity before the ground's law as well (rigid bodies)
