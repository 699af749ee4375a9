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

import warp as wp

from schemas.materials import PRESETS

from .state import Particles

# Integer tags of the presets inside kernels, in PRESETS order.
JELLY, METAL, SAND, PLASTICINE, FOAM, SNOW, RIGID, FRACTURE = range(8)
assert PRESETS == ("jelly", "metal", "sand", "plasticine", "foam", "snow", "rigid", "fracture")

# Snow's hardening factor exp(xi (1 - J_p)) is clamped to this range (as in
# Stomakhin et al.'s reference settings) so its wave speed, and with it the
# CFL time step, stays bounded.
SNOW_HARDENING_MIN = 0.1
SNOW_HARDENING_MAX = 5.0
# A yield stress (Pa) or critical stretch no state reaches: a material that does not yield.
NO_YIELD = 1.0e30
# The solids whose yielding the settle holds off (sand and snow settle as granular heaps).
YIELDING_SOLIDS = ("metal", "plasticine", "foam", "fracture")
# Singular values below this are treated as this (inverted or crushed
# particles), so that log-strain models stay finite.
MIN_STRETCH = 1.0e-2


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


def wave_speed(material) -> float:
    """Largest elastic (P-)wave speed sqrt((lambda + 2 mu) / rho) in m/s, for the CFL bound; 0 for rigid
    bodies, whose particles follow one rigid motion and carry no wave."""
    if material.preset == "rigid":
        return 0.0
    mu, lam = lame_parameters(material.youngs_modulus, material.poisson_ratio)
    stiffening = SNOW_HARDENING_MAX if material.preset == "snow" else 1.0
    return math.sqrt(stiffening * (lam + 2.0 * mu) / material.density)


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


# ------------------------------------------------------------ plasticity


@wp.func
def von_mises_return(eps: wp.vec3, mu: float, yield_stress: float, relaxation: float):
    """Radial return of the deviatoric Hencky strain onto the von Mises cylinder.

    ``relaxation`` in (0, 1] is the fraction of the overstress removed this
    step: 1 is rate-independent plasticity, less is Perzyna viscoplasticity.
    Returns (new strain, equivalent plastic strain increment).
    """
    mean = (eps[0] + eps[1] + eps[2]) / 3.0
    dev = eps - wp.vec3(mean)
    dev_norm = wp.length(dev)
    # |dev tau| = 2 mu |dev eps| may not exceed sqrt(2/3) sigma_y
    excess = dev_norm - wp.sqrt(2.0 / 3.0) * yield_stress / (2.0 * mu)
    if excess <= 0.0:
        return eps, 0.0
    gamma = relaxation * excess
    return eps - (gamma / dev_norm) * dev, wp.sqrt(2.0 / 3.0) * gamma


@wp.func
def drucker_prager_return(eps: wp.vec3, mu: float, lam: float, alpha: float):
    """Klar et al. 2016 return mapping of the Hencky strain onto the Drucker-Prager cone (cohesionless sand)."""
    tr = eps[0] + eps[1] + eps[2]
    if tr >= 0.0:
        return wp.vec3(0.0)  # stretched sand has no strength: back to the cone tip
    dev = eps - wp.vec3(tr / 3.0)
    dev_norm = wp.length(dev)
    gamma = dev_norm + (3.0 * lam + 2.0 * mu) / (2.0 * mu) * tr * alpha
    if gamma <= 0.0 or dev_norm == 0.0:
        return eps
    return eps - (gamma / dev_norm) * dev


@wp.kernel
def update_stress(start: int, dt: float, materials: wp.array(dtype=MaterialParams), particles: Particles):
    """Return-map F (trial -> elastic part) and write V_p * Kirchhoff stress (N m); dt in s, materials
    indexed by the particles' object_id."""
    p = wp.tid() + start
    mat = materials[particles.object_id[p]]
    Fp = particles.F[p]
    history = particles.history
    tau = wp.mat33(0.0)

    if mat.kind == JELLY:
        if mat.neo_hookean == 1:
            tau = neo_hookean_kirchhoff(Fp, mat.mu, mat.lam)
        else:
            tau = fixed_corotated_kirchhoff(Fp, polar_rotation(Fp), mat.mu, mat.lam)
    elif mat.kind != RIGID:  # rigid: no stress, its particles follow one rigid motion (rigid.py)
        U = wp.mat33()
        sig = wp.vec3()
        V = wp.mat33()
        wp.svd3(Fp, U, sig, V)
        if mat.kind == METAL or mat.kind == PLASTICINE or mat.kind == FOAM:
            strain = history[p]
            yield_stress = mat.yield_stress
            relaxation = 1.0
            if mat.kind == METAL:
                yield_stress = mat.yield_stress + mat.hardening * mat.youngs_modulus * strain
            elif mat.kind == PLASTICINE:
                yield_stress = mat.yield_stress * wp.exp(-mat.softening * strain)
            else:
                # Perzyna: the overstress relaxes with time constant viscosity / (2 mu)
                relaxation = 1.0 / (1.0 + mat.viscosity / (2.0 * mat.mu * dt))
            eps, d_strain = von_mises_return(log_stretch(sig), mat.mu, yield_stress, relaxation)
            history[p] = strain + d_strain
            Fp = U * wp.diag(exp_stretch(eps)) * wp.transpose(V)
            tau = hencky_kirchhoff(U, eps, mat.mu, mat.lam)
        elif mat.kind == SAND:
            eps = drucker_prager_return(log_stretch(sig), mat.mu, mat.lam, mat.friction_alpha)
            Fp = U * wp.diag(exp_stretch(eps)) * wp.transpose(V)
            tau = hencky_kirchhoff(U, eps, mat.mu, mat.lam)
        elif mat.kind == SNOW:
            # clamp the principal stretches; what is clamped away becomes plastic volume change
            lo = 1.0 - mat.critical_compression
            hi = 1.0 + mat.critical_stretch
            clamped = wp.vec3(wp.clamp(sig[0], lo, hi), wp.clamp(sig[1], lo, hi), wp.clamp(sig[2], lo, hi))
            Jp = history[p] * (sig[0] * sig[1] * sig[2]) / (clamped[0] * clamped[1] * clamped[2])
            history[p] = Jp
            Fp = U * wp.diag(clamped) * wp.transpose(V)
            h = wp.clamp(wp.exp(mat.hardening * (1.0 - Jp)), SNOW_HARDENING_MIN, SNOW_HARDENING_MAX)
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

    particles.F[p] = Fp
    particles.volume_stress[p] = particles.volume[p] * tau


@wp.func
def elastic_energy_density(mat: MaterialParams, F: wp.mat33, history: float):
    """Stored elastic energy per unit rest volume, J/m^3, of an elastic deformation gradient."""
    U = wp.mat33()
    sig = wp.vec3()
    V = wp.mat33()
    wp.svd3(F, U, sig, V)
    if mat.kind == RIGID:
        return 0.0
    if mat.kind == JELLY and mat.neo_hookean == 1:
        J = wp.max(wp.determinant(F), MIN_STRETCH * MIN_STRETCH * MIN_STRETCH)
        logJ = wp.log(J)
        return 0.5 * mat.mu * (wp.ddot(F, F) - 3.0) - mat.mu * logJ + 0.5 * mat.lam * logJ * logJ
    if mat.kind == JELLY or mat.kind == SNOW or mat.kind == FRACTURE:
        scale = 1.0
        if mat.kind == SNOW:
            scale = wp.clamp(wp.exp(mat.hardening * (1.0 - history)), SNOW_HARDENING_MIN, SNOW_HARDENING_MAX)
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
