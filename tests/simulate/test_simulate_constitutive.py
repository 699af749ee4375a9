"""The return mapping of every preset that yields against its law written out in float64 with numpy's SVD.

update_stress takes the Hencky strain of a deformation gradient near a rotation as a matrix series, with
no SVD (constitutive.near_rotation_strain); the reference here takes it from the singular values, as the
papers write each law: Drucker-Prager sand (Klar et al. 2016), von Mises metal, plasticine and foam,
Stomakhin et al.'s snow, and fracture's damage. Deformation gradients near a rotation (the series) and
far from one (the SVD inside the kernel) both.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
import warp as wp

from schemas import materials as M
from stages.simulate.constitutive import (SNOW_HARDENING_MAX, SNOW_HARDENING_MIN, initial_history, lame_parameters,
                                          params_array, update_stress)
from stages.simulate.state import Particles, Step

DT = 1e-4  # s
N = 400


def deformations(rng, n: int, reach: float) -> np.ndarray:
    """(n,3,3) random rotations times symmetric stretches of log-strain up to about `reach`, float64."""
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    R = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
                  2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                  2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=1).reshape(n, 3, 3)
    A = rng.normal(size=(n, 3, 3)) * reach / 3
    S = 0.5 * (A + A.transpose(0, 2, 1))
    values, vectors = np.linalg.eigh(S)
    stretch = np.einsum("nij,nj,nkj->nik", vectors, np.exp(values), vectors)
    return stretch @ R


def reference(material, F: np.ndarray, history: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(elastic F (n,3,3), history (n,), Kirchhoff stress (n,3,3)) of each law in float64."""
    mu, lam = lame_parameters(material.youngs_modulus, material.poisson_ratio)
    U, sig, Vt = np.linalg.svd(F)
    preset = material.preset
    F_out, h_out, tau = F.copy(), history.copy(), np.zeros_like(F)
    for i in range(len(F)):
        u, s, vt = U[i], sig[i], Vt[i]
        if preset in ("sand", "metal", "plasticine", "foam"):
            eps = np.log(s)
            tr = eps.sum()
            dev = eps - tr / 3
            norm = np.linalg.norm(dev)
            if preset == "sand":
                alpha = math.sqrt(2 / 3) * 2 * math.sin(math.radians(material.friction_angle_deg)) / (
                    3 - math.sin(math.radians(material.friction_angle_deg)))
                gamma = norm + (3 * lam + 2 * mu) / (2 * mu) * tr * alpha
                if tr >= 0:
                    eps = np.zeros(3)
                elif gamma > 0:
                    eps = eps - gamma / norm * dev
            else:
                strength = material.yield_stress
                relaxation = 1.0
                if preset == "metal":
                    strength += material.hardening * material.youngs_modulus * history[i]
                elif preset == "plasticine":
                    strength *= math.exp(-material.softening * history[i])
                else:
                    relaxation = 1 / (1 + material.viscosity / (2 * mu * DT))
                excess = norm - math.sqrt(2 / 3) * strength / (2 * mu)
                if excess > 0:
                    eps = eps - relaxation * excess / norm * dev
                    h_out[i] += math.sqrt(2 / 3) * relaxation * excess
            F_out[i] = u @ np.diag(np.exp(eps)) @ vt
            tau[i] = u @ np.diag(2 * mu * eps + lam * eps.sum()) @ u.T
        elif preset == "snow":
            clamped = np.clip(s, 1 - material.critical_compression, 1 + material.critical_stretch)
            h_out[i] = history[i] * s.prod() / clamped.prod()
            F_out[i] = u @ np.diag(clamped) @ vt
            k = np.clip(math.exp(material.hardening * (1 - h_out[i])), SNOW_HARDENING_MIN, SNOW_HARDENING_MAX)
            J = clamped.prod()
            tau[i] = 2 * k * mu * (F_out[i] - u @ vt) @ F_out[i].T + k * lam * (J - 1) * J * np.eye(3)
        else:  # fracture
            h_out[i] = max(history[i], np.clip((s[0] - 1 - material.critical_stretch) / material.toughness, 0, 1))
            J = s.prod()
            tau[i] = 2 * mu * (F[i] - u @ vt) @ F[i].T + lam * (J - 1) * J * np.eye(3)
            if J > 1:
                tau[i] *= 1 - h_out[i]
                if h_out[i] >= 1:
                    F_out[i] = u @ vt
    return F_out, h_out, tau


def kernel(material, F: np.ndarray, history: np.ndarray, device: str) -> tuple[np.ndarray, ...]:
    """update_stress on particles of unit volume: (elastic F, history, Kirchhoff stress), float64."""
    n = len(F)
    p = Particles()
    p.F = wp.array(F.astype(np.float32), dtype=wp.mat33, device=device)
    p.history = wp.array(history.astype(np.float32), dtype=float, device=device)
    p.volume_stress = wp.zeros(n, dtype=wp.mat33, device=device)
    p.volume = wp.array(np.ones(n, np.float32), dtype=float, device=device)
    p.object_id = wp.zeros(n, dtype=wp.int32, device=device)
    step = Step()
    step.dt, step.stiffening = DT, SNOW_HARDENING_MAX
    wp.launch(update_stress, dim=n, device=device, inputs=[0, step, params_array([material], device), p])
    return tuple(a.numpy().astype(np.float64) for a in (p.F, p.history, p.volume_stress))


@pytest.mark.parametrize("material", [M.Sand(), M.Metal(), M.Plasticine(), M.Foam(), M.Snow(), M.Fracture()],
                         ids=lambda m: m.preset)
@pytest.mark.parametrize("reach, tolerance", [(0.02, 2e-5), (0.2, 2e-4), (0.8, 1e-3)],
                         ids=["small", "large", "beyond the series"])
def test_the_return_mapping_is_the_law_in_float64(device, material, reach, tolerance):
    """Elastic F, history and Kirchhoff stress of random deformations (rotations times stretches of log-strain
    up to `reach`; metal, plasticine and foam with plastic strain already gathered, snow compacted or
    loosened) agree with the law in float64: F and history within 2e-5 for small strains, all of them taken
    by the series, and within 2e-4 and 1e-3 for larger ones, more and more of them taken by float32's SVD
    (its error grows with the strain); the stress within as much (at least 1e-4) of its largest entry."""
    rng = np.random.default_rng(7)
    F = deformations(rng, N, reach)
    history = np.full(N, initial_history(material))
    if material.preset == "snow":
        history = rng.uniform(0.9, 1.05, N)
    elif material.preset != "fracture":
        history = rng.uniform(0.0, 0.2, N)
    F_ref, history_ref, tau_ref = reference(material, F, history)
    F_got, history_got, tau_got = kernel(material, F, history, device)
    np.testing.assert_allclose(F_got, F_ref, atol=tolerance)
    np.testing.assert_allclose(history_got, history_ref, atol=tolerance)
    np.testing.assert_allclose(tau_got, tau_ref, atol=max(tolerance, 1e-4) * np.abs(tau_ref).max())
