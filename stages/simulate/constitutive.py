"""Constitutive models: elastic stress and plastic return mapping per material.

One kernel, ``update_stress``, runs once per substep after G2P: it projects each
particle's trial deformation gradient back onto its material's admissible set
(the return mapping), stores the elastic part, and writes ``V_p tau_p``: the
particle volume times its Kirchhoff stress, which P2G turns into grid forces.

Per-particle ``history`` is one scalar whose meaning depends on the material:
accumulated equivalent plastic strain (metal, plasticine, foam), the plastic
volume ratio J_p (snow, starts at 1), damage in [0, 1] (fracture), unused
(jelly, sand, rigid).
"""
from __future__ import annotations

import math

import numpy as np
import warp as wp

from schemas.materials import PRESETS

from .state import Particles, Step

# Integer tags of the presets inside kernels, in PRESETS order.
JELLY, METAL, SAND, PLASTICINE, FOAM, SNOW, RIGID, FRACTURE = range(8)
assert PRESETS == ("jelly", "metal", "sand", "plasticine", "foam", "snow", "rigid", "fracture")

# Snow's hardening factor exp(xi (1 - J_p)) is clamped to this range (as in
# Stomakhin et al.'s reference settings) so its wave speed, and with it the
# CFL time step, stays bounded.
SNOW_HARDENING_MIN = 0.1
SNOW_HARDENING_MAX = 5.0
# The substep follows the hardening the snow has (MPMSolver.stiffening): it is sized for this many times
# the largest factor of its particles, and the stress of the substep stiffens no further
# (docs/decisions/0039-granular-substeps.md).
SNOW_HARDENING_GROWTH = 1.25
# A yield stress (Pa) or critical stretch no state reaches: a material that does not yield.
NO_YIELD = 1.0e30
# The solids whose yielding the settle holds off (sand and snow settle as granular heaps).
YIELDING_SOLIDS = ("metal", "plasticine", "foam", "fracture")
# Singular values below this are treated as this (inverted or crushed
# particles), so that log-strain models stay finite.
MIN_STRETCH = 1.0e-2
# Where Y = (F F^T - I)(F F^T + I)^-1 is at most this (Frobenius) norm and det F > 0, the return mapping
# takes the Hencky strain as a matrix series and no SVD (`near_rotation_strain`): every principal
# stretch within 0.73 .. 1.36. Float32's SVD costs about 0.6 us a particle on the CPU and is good to
# 1e-4; the series costs a quarter of that and is good to 1.4e-7 in float32, its truncation at |Y| = 0.3
# 1.1e-8 (docs/decisions/0039-granular-substeps.md).
SERIES_REACH = 0.3


@wp.struct
class MaterialParams:
    """Parameters of one object's material, in SI units (see schemas.materials)."""

    kind: int  # preset tag (JELLY ... FRACTURE)
    neo_hookean: int  # jelly only: 1 neo-Hookean, 0 fixed-corotated
    mu: float  # Lame shear modulus, Pa
    lam: float  # Lame first parameter, Pa
    yield_stress: float  # von Mises uniaxial yield stress, Pa
    hardening: float  # metal: d(yield)/d(plastic strain) in units of E; snow: xi
    youngs_modulus: float  # Pa
    softening: float  # plasticine: yield stress decays as exp(-softening * plastic strain)
    viscosity: float  # foam: Perzyna viscosity, Pa s
    friction_alpha: float  # sand: Drucker-Prager cone slope sqrt(2/3) 2 sin(phi) / (3 - sin(phi))
    critical_compression: float  # snow theta_c
    critical_stretch: float  # snow theta_s, fracture damage onset
    toughness: float  # fracture: stretch over which damage goes 0 -> 1


def lame_parameters(youngs_modulus: float, poisson_ratio: float) -> tuple[float, float]:
    """(mu, lambda) in Pa from Young's modulus (Pa) and Poisson's ratio."""
    mu = youngs_modulus / (2.0 * (1.0 + poisson_ratio))
    lam = youngs_modulus * poisson_ratio / ((1.0 + poisson_ratio) * (1.0 - 2.0 * poisson_ratio))
    return mu, lam


def material_params(material, yielding: bool = True) -> MaterialParams:
    """Warp parameter struct of one `schemas.materials` preset model; with yielding False a solid
    (YIELDING_SOLIDS) keeps its elasticity but neither yields nor breaks."""
    p = MaterialParams()
    p.kind = PRESETS.index(material.preset)
    p.neo_hookean = int(getattr(material, "model", "") == "neo_hookean")
    p.youngs_modulus = getattr(material, "youngs_modulus", 0.0)  # rigid: none
    p.mu, p.lam = lame_parameters(p.youngs_modulus, getattr(material, "poisson_ratio", 0.0))
    p.yield_stress = getattr(material, "yield_stress", 0.0)
    p.hardening = getattr(material, "hardening", 0.0)
    p.softening = getattr(material, "softening", 0.0)
    p.viscosity = getattr(material, "viscosity", 0.0)
    sin_phi = math.sin(math.radians(getattr(material, "friction_angle_deg", 0.0)))
    p.friction_alpha = math.sqrt(2.0 / 3.0) * 2.0 * sin_phi / (3.0 - sin_phi)
    p.critical_compression = getattr(material, "critical_compression", 0.0)
    p.critical_stretch = getattr(material, "critical_stretch", 0.0)
    p.toughness = getattr(material, "toughness", 1.0)
    if not yielding and material.preset in YIELDING_SOLIDS:
        p.yield_stress = p.critical_stretch = NO_YIELD
    return p


def wave_speed(material, stiffening: float = SNOW_HARDENING_MAX) -> float:
    """Largest elastic (P-)wave speed sqrt((lambda + 2 mu) / rho) in m/s, for the CFL bound; 0 for rigid
    bodies, whose particles follow one rigid motion and carry no wave. Snow's moduli are taken times
    `stiffening`, the largest hardening factor its stress may reach (by default the clamp's
    SNOW_HARDENING_MAX)."""
    if material.preset == "rigid":
        return 0.0
    mu, lam = lame_parameters(material.youngs_modulus, material.poisson_ratio)
    factor = stiffening if material.preset == "snow" else 1.0
    return math.sqrt(factor * (lam + 2.0 * mu) / material.density)


def snow_hardening(material, plastic_volume: np.ndarray) -> np.ndarray:
    """Snow's hardening factor exp(xi (1 - J_p)), clamped as the stress clamps it, of plastic volume ratios
    J_p (any shape)."""
    return np.clip(np.exp(material.hardening * (1.0 - np.asarray(plastic_volume, np.float64))),
                   SNOW_HARDENING_MIN, SNOW_HARDENING_MAX)


def initial_history(material) -> float:
    """Starting value of the per-particle history scalar (J_p = 1 for snow, else 0)."""
    return 1.0 if material.preset == "snow" else 0.0


# ---------------------------------------------------------------- elasticity


@wp.func
def polar_rotation(F: wp.mat33):
    """Rotation R of the polar decomposition F = R S.

    Scaled Newton iteration X <- (g X + (g X)^-T) / 2 with g = |det X|^(-1/3)
    (Higham 1986): a few 3x3 inverses, about 4x cheaper than wp.svd3 for the
    near-rotations MPM produces. Inverted or crushed F takes the SVD rotation
    U V^T (Warp's U, V are proper rotations), which the fixed-corotated model
    needs to push the particle back out.
    """
    if wp.determinant(F) <= 1.0e-4:
        U = wp.mat33()
        sig = wp.vec3()
        V = wp.mat33()
        wp.svd3(F, U, sig, V)
        return U * wp.transpose(V)
    X = F
    for _ in range(8):
        g = wp.pow(wp.abs(wp.determinant(X)), -1.0 / 3.0)
        Y = 0.5 * (g * X + wp.transpose(wp.inverse(X)) / g)
        change = Y - X
        X = Y
        if wp.ddot(change, change) < 1.0e-12:
            break
    return X


@wp.func
def fixed_corotated_kirchhoff(F: wp.mat33, R: wp.mat33, mu: float, lam: float):
    """tau = 2 mu (F - R) F^T + lam (J - 1) J I (Stomakhin et al. 2012)."""
    J = wp.determinant(F)
    return 2.0 * mu * (F - R) * wp.transpose(F) + wp.diag(wp.vec3(lam * (J - 1.0) * J))


@wp.func
def neo_hookean_kirchhoff(F: wp.mat33, mu: float, lam: float):
    """tau = mu (F F^T - I) + lam log(J) I, with J kept positive."""
    J = wp.max(wp.determinant(F), MIN_STRETCH * MIN_STRETCH * MIN_STRETCH)
    return mu * (F * wp.transpose(F) - wp.identity(n=3, dtype=float)) + wp.diag(wp.vec3(lam * wp.log(J)))


@wp.func
def hencky_kirchhoff(U: wp.mat33, eps: wp.vec3, mu: float, lam: float):
    """St. Venant-Kirchhoff on the Hencky (log) strain eps = log(sigma): tau = U (2 mu eps + lam tr(eps)) U^T."""
    tr = eps[0] + eps[1] + eps[2]
    return U * wp.diag(2.0 * mu * eps + wp.vec3(lam * tr)) * wp.transpose(U)


@wp.func
def log_stretch(sig: wp.vec3):
    return wp.vec3(
        wp.log(wp.max(sig[0], MIN_STRETCH)),
        wp.log(wp.max(sig[1], MIN_STRETCH)),
        wp.log(wp.max(sig[2], MIN_STRETCH)),
    )


@wp.func
def exp_stretch(eps: wp.vec3):
    return wp.vec3(wp.exp(eps[0]), wp.exp(eps[1]), wp.exp(eps[2]))


@wp.func
def near_rotation_strain(F: wp.mat33):
    """(Left Hencky strain log V of F = V R, whether F is near enough a rotation for it): the series
    atanh Y = Y + Y^3/3 + Y^5/5 + ... of Y = (b - I)(b + I)^-1, b = F F^T (log b = 2 atanh Y), to 1.4e-7
    an entry in float32 (its truncation 1.1e-8), where det F > 0 and |Y| <= SERIES_REACH; (0, False)
    elsewhere."""
    I = wp.identity(n=3, dtype=float)
    b = F * wp.transpose(F)
    Y = (b - I) * wp.inverse(b + I)
    Y = 0.5 * (Y + wp.transpose(Y))  # a function of b, symmetric but for float32's rounding
    if wp.determinant(F) <= 0.0 or wp.ddot(Y, Y) > SERIES_REACH * SERIES_REACH:
        return wp.mat33(0.0), False
    Y2 = Y * Y
    term = Y
    eps = Y
    for k in range(1, 6):
        term = term * Y2
        eps = eps + term * (1.0 / float(2 * k + 1))
        if wp.ddot(term, term) < 1.0e-16:
            break
    return eps, True


@wp.func
def symmetric_exp(Z: wp.mat33):
    """exp(Z) of a symmetric Z of norm about 1 or less (a Hencky strain or a plastic step): its Taylor series
    to under 1e-8."""
    E = wp.identity(n=3, dtype=float)
    term = E
    for k in range(1, 16):
        term = term * Z * (1.0 / float(k))
        E = E + term
        if wp.ddot(term, term) < 1.0e-16:
            break
    return E


@wp.func
def eigenvalue_range(A: wp.mat33):
    """(smallest, largest) eigenvalue of a symmetric A, in closed form (Smith 1961)."""
    q = wp.trace(A) / 3.0
    B = A - q * wp.identity(n=3, dtype=float)
    p2 = wp.ddot(B, B) / 6.0
    if p2 < 1.0e-30:
        return q, q
    p = wp.sqrt(p2)
    phi = wp.acos(wp.clamp(wp.determinant(B) / (2.0 * p2 * p), -1.0, 1.0)) / 3.0
    return q + 2.0 * p * wp.cos(phi + 2.0 * wp.pi / 3.0), q + 2.0 * p * wp.cos(phi)


# ------------------------------------------------------------ plasticity


@wp.func
def plastic_flow(mat: MaterialParams, strain: float, dt: float, tr: float, dev_norm: float):
    """The return mapping of a Hencky strain of trace `tr` and deviatoric norm `dev_norm` (eps =
    dev + tr / 3 I): (the share of its deviatoric part removed, the share of its volumetric part removed,
    the equivalent plastic strain gained).

    Sand: Klar et al. 2016 onto the Drucker-Prager cone (cohesionless; stretched sand goes back to the
    cone's tip). Metal, plasticine, foam: radial return onto the von Mises cylinder, |dev tau| = 2 mu
    |dev eps| <= sqrt(2/3) sigma_y, sigma_y hardening with the plastic `strain` (metal) or softening
    (plasticine); foam removes only the share 1 / (1 + viscosity / (2 mu dt)) of the overstress in a
    substep of dt s (Perzyna viscoplasticity).
    """
    if mat.kind == SAND:
        if tr >= 0.0:
            return 1.0, 1.0, 0.0
        gamma = dev_norm + (3.0 * mat.lam + 2.0 * mat.mu) / (2.0 * mat.mu) * tr * mat.friction_alpha
        if gamma <= 0.0 or dev_norm == 0.0:
            return 0.0, 0.0, 0.0
        return gamma / dev_norm, 0.0, 0.0
    yield_stress = mat.yield_stress
    relaxation = 1.0
    if mat.kind == METAL:
        yield_stress = mat.yield_stress + mat.hardening * mat.youngs_modulus * strain
    elif mat.kind == PLASTICINE:
        yield_stress = mat.yield_stress * wp.exp(-mat.softening * strain)
    elif mat.kind == FOAM:
        relaxation = 1.0 / (1.0 + mat.viscosity / (2.0 * mat.mu * dt))
    excess = dev_norm - wp.sqrt(2.0 / 3.0) * yield_stress / (2.0 * mat.mu)
    if excess <= 0.0:
        return 0.0, 0.0, 0.0
    gamma = relaxation * excess
    return gamma / dev_norm, 0.0, wp.sqrt(2.0 / 3.0) * gamma


@wp.func
def snow_factor(mat: MaterialParams, Jp: float, stiffening: float):
    """Snow's hardening factor exp(xi (1 - J_p)), clamped to [SNOW_HARDENING_MIN, stiffening]."""
    return wp.clamp(wp.exp(mat.hardening * (1.0 - Jp)), SNOW_HARDENING_MIN, stiffening)


@wp.kernel
def update_stress(start: int, substep: Step, materials: wp.array(dtype=MaterialParams), particles: Particles):
    """Return-map F (trial -> elastic part) and write V_p * Kirchhoff stress (N m) over a substep of
    `substep.dt` s; materials indexed by the particles' object_id; snow's hardening factor at most
    `substep.stiffening`, what the substep was sized for.

    Where F is near a rotation (near_rotation_strain) the Hencky strain and the plastic step are matrix
    series and no SVD is taken: snow only where none of its principal stretches is clamped. Elsewhere
    (a crushed, inverted or much stretched particle, snow at its limits) the SVD's principal stretches.
    """
    p = wp.tid() + start
    mat = materials[particles.object_id[p]]
    Fp = particles.F[p]
    history = particles.history
    tau = wp.mat33(0.0)
    I = wp.identity(n=3, dtype=float)

    if mat.kind == JELLY:
        if mat.neo_hookean == 1:
            tau = neo_hookean_kirchhoff(Fp, mat.mu, mat.lam)
        else:
            tau = fixed_corotated_kirchhoff(Fp, polar_rotation(Fp), mat.mu, mat.lam)
    elif mat.kind != RIGID:  # rigid: no stress, its particles follow one rigid motion (rigid.py)
        hencky, near = near_rotation_strain(Fp)
        if near and mat.kind == SNOW:
            lo, hi = eigenvalue_range(hencky)
            near = lo >= wp.log(1.0 - mat.critical_compression) and hi <= wp.log(1.0 + mat.critical_stretch)
        if near:
            if mat.kind == SNOW or mat.kind == FRACTURE:
                R = symmetric_exp(-hencky) * Fp
                if mat.kind == SNOW:  # unclamped: no plastic volume change
                    h = snow_factor(mat, history[p], substep.stiffening)
                    tau = fixed_corotated_kirchhoff(Fp, R, h * mat.mu, h * mat.lam)
                else:
                    _, hi = eigenvalue_range(hencky)
                    damage = wp.max(history[p], wp.clamp((wp.exp(hi) - 1.0 - mat.critical_stretch) / mat.toughness,
                                                         0.0, 1.0))
                    history[p] = damage
                    tau = fixed_corotated_kirchhoff(Fp, R, mat.mu, mat.lam)
                    if wp.determinant(Fp) > 1.0:
                        tau = (1.0 - damage) * tau
                        if damage >= 1.0:
                            Fp = R
            else:  # sand, metal, plasticine, foam
                tr = wp.trace(hencky)
                deviator = hencky - (tr / 3.0) * I
                dev_share, volume_share, d_strain = plastic_flow(mat, history[p], substep.dt, tr,
                                                                 wp.sqrt(wp.ddot(deviator, deviator)))
                history[p] = history[p] + d_strain
                step = -dev_share * deviator - (volume_share * tr / 3.0) * I
                if dev_share > 0.0 or volume_share > 0.0:
                    Fp = symmetric_exp(step) * Fp
                hencky = hencky + step
                tau = 2.0 * mat.mu * hencky + (mat.lam * wp.trace(hencky)) * I
        else:
            U = wp.mat33()
            sig = wp.vec3()
            V = wp.mat33()
            wp.svd3(Fp, U, sig, V)
            if mat.kind == SNOW:
                # clamp the principal stretches; what is clamped away becomes plastic volume change
                lo = 1.0 - mat.critical_compression
                hi = 1.0 + mat.critical_stretch
                clamped = wp.vec3(wp.clamp(sig[0], lo, hi), wp.clamp(sig[1], lo, hi), wp.clamp(sig[2], lo, hi))
                Jp = history[p] * (sig[0] * sig[1] * sig[2]) / (clamped[0] * clamped[1] * clamped[2])
                history[p] = Jp
                Fp = U * wp.diag(clamped) * wp.transpose(V)
                h = snow_factor(mat, Jp, substep.stiffening)
                tau = fixed_corotated_kirchhoff(Fp, U * wp.transpose(V), h * mat.mu, h * mat.lam)
            elif mat.kind == FRACTURE:
                # damage grows irreversibly with the largest principal stretch
                damage = wp.max(history[p], wp.clamp((sig[0] - 1.0 - mat.critical_stretch) / mat.toughness, 0.0, 1.0))
                history[p] = damage
                tau = fixed_corotated_kirchhoff(Fp, U * wp.transpose(V), mat.mu, mat.lam)
                if sig[0] * sig[1] * sig[2] > 1.0:
                    # broken material carries no tension but still resists compression
                    tau = (1.0 - damage) * tau
                    if damage >= 1.0:
                        Fp = U * wp.transpose(V)
            else:  # sand, metal, plasticine, foam
                eps = log_stretch(sig)
                tr = eps[0] + eps[1] + eps[2]
                dev = eps - wp.vec3(tr / 3.0)
                dev_share, volume_share, d_strain = plastic_flow(mat, history[p], substep.dt, tr, wp.length(dev))
                history[p] = history[p] + d_strain
                eps = eps - dev_share * dev - wp.vec3(volume_share * tr / 3.0)
                Fp = U * wp.diag(exp_stretch(eps)) * wp.transpose(V)
                tau = hencky_kirchhoff(U, eps, mat.mu, mat.lam)

    particles.F[p] = Fp
    particles.volume_stress[p] = particles.volume[p] * tau


@wp.func
def elastic_energy_density(mat: MaterialParams, F: wp.mat33, history: float):
    """Stored elastic energy per unit rest volume, J/m^3, of an elastic deformation gradient."""
    if mat.kind == RIGID:
        return 0.0
    if mat.kind == JELLY and mat.neo_hookean == 1:
        J = wp.max(wp.determinant(F), MIN_STRETCH * MIN_STRETCH * MIN_STRETCH)
        logJ = wp.log(J)
        return 0.5 * mat.mu * (wp.ddot(F, F) - 3.0) - mat.mu * logJ + 0.5 * mat.lam * logJ * logJ
    U = wp.mat33()
    sig = wp.vec3()
    V = wp.mat33()
    wp.svd3(F, U, sig, V)
    if mat.kind == JELLY or mat.kind == SNOW or mat.kind == FRACTURE:
        scale = 1.0
        if mat.kind == SNOW:
            scale = snow_factor(mat, history, SNOW_HARDENING_MAX)
        J = sig[0] * sig[1] * sig[2]
        s1 = sig - wp.vec3(1.0)
        return scale * (mat.mu * wp.dot(s1, s1) + 0.5 * mat.lam * (J - 1.0) * (J - 1.0))
    eps = log_stretch(sig)
    tr = eps[0] + eps[1] + eps[2]
    return mat.mu * wp.dot(eps, eps) + 0.5 * mat.lam * tr * tr


def params_array(materials, device, yielding: bool = True) -> wp.array:
    """Device array of MaterialParams, one per object (indexed by object_id)."""
    return wp.array([material_params(m, yielding) for m in materials], dtype=MaterialParams, device=device)



@wp.kernel
def elastic_energy(
    materials: wp.array(dtype=MaterialParams),
    object_id: wp.array(dtype=wp.int32),
    volume: wp.array(dtype=float),
    F: wp.array(dtype=wp.mat33),
    history: wp.array(dtype=float),
    energy: wp.array(dtype=float),
):
    """Stored elastic energy V_p Psi(F_p) of each particle, J."""
    p = wp.tid()
    energy[p] = volume[p] * elastic_energy_density(materials[object_id[p]], F[p], history[p])


@wp.kernel
def deformation_since_rest(F: wp.array(dtype=wp.mat33), rest_F_inverse: wp.array(dtype=wp.mat33), Q: wp.mat33,
                           world_F: wp.array(dtype=wp.mat33)):
    """Each particle's deformation since the photograph in the world frame, Q^T F_p F_rest,p^-1 Q, where
    F_rest,p is its F in the settled rest state and Q (3,3) turns world vectors into the simulation frame."""
    p = wp.tid()
    world_F[p] = wp.transpose(Q) @ F[p] @ rest_F_inverse[p] @ Q
