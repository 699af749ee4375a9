"""The photographed world at rest: the stress the objects stand under.

A photographed object is in equilibrium. Its shape is the loaded shape, but a
simulation that starts from it with no stress lets it fall into its own
weight: it sags by twice its static deflection, rings and, on a narrow
support, rocks. The settle (simulation.Simulation.settle, quasi_static.py) finds
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

The settle is paid only where it matters (`why_not_settled`,
docs/decisions/0020-settle-where-it-matters.md): a body whose static sag
rho g H^2 / (2 E) is under a tenth of a grid cell starts unstressed (its fall
into its weight is smaller than the grid resolves) unless it is snow, which
compacts plastically on its contact (docs/decisions/0039-granular-substeps.md),
sand never settles (a heap has no elastic shape to hold), and a body tossed
off the ground at t = 0 carries no load. It lasts at most SETTLE_SHARE of the run's substeps.

The ground lies through the objects' lowest point (simulation.py): a body
stands because its base carries it, and `support_margin` says whether it does.
The `warn_*` functions say, before and after the settle, where a body cannot
stand as photographed.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from .constitutive import MIN_STRETCH, lame_parameters

log = logging.getLogger("physmotion.simulate")

# The settle (quasi_static.py) lasts at most this many periods of the slowest body's fundamental mode.
SETTLE_PERIODS = 10.0
# ... and at most this share of the run's substeps (docs/decisions/0020-settle-where-it-matters.md).
SETTLE_SHARE = 0.2
# A body whose column sag under its weight is below this many grid cells is not settled: started
# unstressed it falls into its weight by twice that, which the grid does not resolve.
SAG_CELLS = 0.1
# Held up in its photographed shape, a body that stands gives way by its static deflection; one whose
# settle moved it by more than this many times an elastic column's sag (plus a tenth of a cell), or
# turned it by more than TURN_DEG, is giving way and is named.
GIVING_WAY_FACTOR = 3.0
TURN_DEG = 1.0
# A settle whose kinetic energy has not peaked once in this many periods is still falling: the body
# touches the ground on too small a contact (a soft ball on its lowest point) to stand as photographed.
FOOTLESS_PERIODS = 2.0
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
    """Angle in degrees of the best rotation (weighted Kabsch) taking the points rest (N,3) onto now (N,3);
    NaN where `now` is not finite (a settle that blew up: its run then stops with one paragraph)."""
    if not np.isfinite(now).all():
        return math.nan
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


@dataclass
class Settled:
    """What Simulation.settle found."""

    bodies: list[int] = field(default_factory=list)
    """Objects settled into their weight in the photographed shape."""
    skipped: dict[int, str] = field(default_factory=dict)
    """Objects on the ground or held that start unstressed, and why (`why_not_settled`)."""
    footless: list[int] = field(default_factory=list)
    """Settled objects with no equilibrium as photographed (`warn_footless`): they start unstressed."""
    giving_way: list[int] = field(default_factory=list)
    """Settled objects still giving way when the settle ended (`warn_giving_way`)."""
    substeps: int = 0
    relaxation_s: float = 0.0
    """Simulated seconds of relaxation."""
    peaks: int = 0
    """Kinetic energy peaks, each one's energy taken out."""
    residual: float = 0.0
    """The last peak's kinetic energy over the first's."""
    sag: float = 0.0
    """Largest downward deflection (m) that the pinned particles were kept from."""
    wall_s: float = 0.0


def why_not_settled(material, height: float, cell: float, gravity: float, lifted: bool) -> str | None:
    """Why a deformable body `height` m tall, on the ground or held, starts unstressed (None: it settles).

    Sand has no elastic shape to hold (a heap finds its slope in the run); a body tossed off the ground at
    t = 0 (`lifted`) carries no load; and a body whose column sag rho g H^2 / (2 E) (gravity m/s^2) is
    under SAG_CELLS of a `cell` m grid cell falls into its weight by less than the grid resolves. Snow
    settles whatever its elastic sag: where it stands on a contact its weight compacts it plastically
    past its critical compression, by more than its elastic sag (the 23 cm ball of
    benchmarks/examples.py: 2.5 mm held up against an elastic 0.72 mm), and started unstressed it rings
    on that contact (docs/decisions/0039-granular-substeps.md)."""
    if material.preset == "sand":
        return "sand: a heap has no elastic shape to hold, it finds its slope in the run"
    if lifted:
        return "tossed off the ground at t = 0, it carries no load"
    sag = column_sag(material, height, gravity)
    if sag > height:  # no stress holds it up: settling would only chase its slump, for as long as that takes
        return (f"its sag under its weight, rho g H^2 / 2E = {sag:.3g} m, is beyond its {1e3 * height:.0f} mm "
                f"height: it cannot stand and slumps from t = 0")
    if sag < SAG_CELLS * cell and material.preset != "snow":
        return (f"its sag under its weight, rho g H^2 / 2E = {1e3 * sag:.3g} mm, is under {SAG_CELLS:g} of a "
                f"{1e3 * cell:.2f} mm cell")
    return None


def warn_crushed_by_weight(k: int, material, height: float, gravity: float) -> None:
    """Say so when object k's weight presses its base (rho g H, a column `height` m tall) past its yield stress."""
    yield_stress = getattr(material, "yield_stress", None)
    pressure = material.density * gravity * height
    if yield_stress and pressure > yield_stress:
        log.warning("object %d (%s) is %.0f mm tall: its weight presses its base with about rho g H = %.3g Pa, "
                    "above its yield_stress %.3g Pa, so it will slump under its own weight as a column of this "
                    "material would. To keep its shape raise objects[%d].material.yield_stress above %.3g Pa, or "
                    "make size_m smaller", k, material.preset, 1e3 * height, pressure, yield_stress, k, pressure)


def warn_dented_by_impact(k: int, material, speed: float) -> None:
    """Say so when metal object k, moving at `speed` m/s as its conditions set it, would meet the ground or
    what it strikes with an impact stress sqrt(E rho) v (a bar's elastic wave stopping it) past its
    yield stress: it dents and flattens where it lands instead of bouncing as a stiff metal does."""
    if material.preset != "metal" or speed <= 0:
        return
    stress = math.sqrt(material.youngs_modulus * material.density) * speed
    if stress <= material.yield_stress:
        return
    log.warning("object %d (metal, E = %.3g Pa) is set moving at up to %.2g m/s: meeting the ground at that speed "
                "stresses it about sqrt(E rho) v = %.3g Pa, above its yield_stress %.3g Pa, so it dents and "
                "flattens where it lands, as soft metal would. To keep its shape raise "
                "objects[%d].material.yield_stress above %.3g Pa (a stiffer youngs_modulus raises the impact "
                "stress as sqrt(E) and shortens the substep as much)", k, material.youngs_modulus, speed, stress,
                material.yield_stress, k, stress)


def warn_unsupported(k: int, x: np.ndarray, centre: np.ndarray, ground_y: float, spacing: float) -> None:
    """Say so when no support holds object k (rest points x (N,3), centre of mass (3,), simulation frame, m)
    up: its centre of mass lies outside the hull of its points within a lattice `spacing` of the ground
    (its contact patch, as the ground's nodes meet it), so it tips over at t = 0."""
    if not np.any(x[:, 1] <= ground_y + 0.5 * spacing):
        return  # in flight
    foot = x[:, 1] <= ground_y + spacing
    margin = support_margin(x[foot][:, [0, 2]], centre[[0, 2]])
    if margin >= spacing:
        return
    where = ("%.1f mm outside it" % (-1e3 * margin) if margin < 0 else "%.1f mm inside its edge" % (1e3 * margin)
             ) if math.isfinite(margin) else "over a line of contact, not an area"
    log.warning("object %d does not stand as reconstructed: its support (seen from above, the hull of its points "
                "within %.1f mm of the ground) holds its centre of mass %s, so it tips over from t = 0 as that "
                "shape would, rigid too. If the photographed object stands, its reconstruction is too thin or "
                "leans where the photograph does not show it: hold its foot with a `fixed` condition "
                "(physics.conditions) or add reconstruct.extra_views", k, 1e3 * spacing, where)


def warn_overstressed(k: int, material, rest: np.ndarray, F: np.ndarray, masses: np.ndarray) -> None:
    """Say so when more than OVERSTRESSED_SHARE of object k's mass (masses (N,) kg at rest points (N,3), settled
    elastic F (N,3,3)) stands past its yield stress."""
    if not getattr(material, "yield_stress", None):  # metal, plasticine and foam yield by von Mises
        return
    stress = von_mises_stress(F, material)
    over = stress > material.yield_stress
    share = float(masses[over].sum() / masses.sum())
    if share <= OVERSTRESSED_SHARE:
        return
    heights = 1e3 * (rest[:, 1] - rest[:, 1].min())
    log.warning("object %d (%s): standing under its own weight as photographed, %.1f %% of its mass is stressed "
                "past its yield_stress %.3g Pa (up to %.3g Pa, %.0f to %.0f mm above its lowest point), so it "
                "yields there in the run and may sag, lean or fall as a body of this material would. To keep "
                "its shape raise objects[%d].material.yield_stress above %.3g Pa, or make size_m smaller", k,
                material.preset, 100 * share, material.yield_stress, stress.max(), heights[over].min(),
                heights[over].max(), k, np.percentile(stress, 100 * (1 - OVERSTRESSED_SHARE)))


def warn_giving_way(k: int, material, rest: np.ndarray, settled: np.ndarray, masses: np.ndarray, seconds: float,
                    gravity: float, cell: float) -> bool:
    """Name object k and return True when, held in its photographed shape for `seconds` of settle, it was
    still giving way: it went (settled (N,3) against rest (N,3) m, masses (N,) kg) more than GIVING_WAY_FACTOR
    times an elastic column's sag of its height (plus SAG_CELLS of a `cell`) down, or turned more than
    TURN_DEG. A body that moved less stands, whether or not its relaxation reached quasi_static.RELAXED."""
    height = float(np.ptp(rest[:, 1]))
    column = column_sag(material, height, gravity)
    sag = float(np.max(rest[:, 1] - settled[:, 1]))
    turn = turn_deg(rest, settled, masses)
    if sag <= GIVING_WAY_FACTOR * column + SAG_CELLS * cell and turn <= TURN_DEG:
        return False
    log.warning("object %d (%s, E = %.3g Pa) did not come to rest under its own weight in %.2f s: held in its "
                "photographed shape it was still giving way, %.1f mm of sag and %.1f degrees of turn, where an "
                "elastic column of its %.0f mm height sags %.2f mm. In the run it may go on sagging, buckle or tip "
                "over. A stiffer material (objects[%d].material.youngs_modulus%s), a smaller size_m or preset "
                "rigid holds it up", k, material.preset, material.youngs_modulus, seconds, 1e3 * sag, turn,
                1e3 * height, 1e3 * column, k, " or yield_stress" if getattr(material, "yield_stress", None) else "")
    return True


def warn_footless(k: int, material, periods: float, seconds: float) -> None:
    """Name object k, whose pinned settle found no kinetic peak in `periods` of its slowest mode (`seconds` of
    wall time): it touches the ground on too small a contact to carry its weight as photographed."""
    log.warning("object %d (%s, E = %.3g Pa) touches the ground on too small a contact to carry its weight in its "
                "photographed shape (no equilibrium in %.0f of its slowest periods, %.0f s): it starts unstressed "
                "and sags into its weight from t = 0, as a soft body set down on a point would. A stiffer material "
                "(objects[%d].material.youngs_modulus) sags less", k, material.preset, material.youngs_modulus,
                periods, seconds, k)
