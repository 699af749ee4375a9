"""The quadratic B-spline stencil every particle-grid transfer uses (stages/simulate/stencil.py), against its
float64 definition: N(r) = 3/4 - r^2 for |r| < 1/2, (3/2 - |r|)^2 / 2 for |r| < 3/2, 0 beyond."""
from __future__ import annotations

import numpy as np
import warp as wp

from stages.simulate.stencil import stencil_weights


@wp.kernel
def weights_at(fx: wp.array(dtype=wp.vec3), weights: wp.array(dtype=wp.mat33)):
    p = wp.tid()
    weights[p] = stencil_weights(fx[p])


def b_spline(r: np.ndarray) -> np.ndarray:
    r = np.abs(r)
    return np.where(r < 0.5, 0.75 - r ** 2, np.where(r < 1.5, 0.5 * (1.5 - r) ** 2, 0.0))


def test_the_stencil_weighs_each_node_by_the_quadratic_b_spline(device):
    """At 2000 points of the cell a stencil's corner node is chosen for (fx in [0.5, 1.5) per axis, cells),
    row a of stencil_weights is N(fx_a - i) for nodes i = 0, 1, 2 (float64, tol 1e-6); the weights sum to 1
    and their first moment about the point is 0 and their second 1/4 per axis (what APIC's C = 4/dx^2
    sum w v (x_i - x_p)^T relies on)."""
    fx = np.random.default_rng(0).uniform(0.5, 1.5, (2000, 3))
    out = wp.zeros(len(fx), dtype=wp.mat33, device=device)
    wp.launch(weights_at, dim=len(fx), inputs=[wp.array(fx.astype(np.float32), dtype=wp.vec3, device=device), out],
              device=device)
    weights = out.numpy().astype(np.float64)  # (P, axis, node)
    offsets = np.arange(3)[None, None, :] - fx[:, :, None]  # node i minus the point, cells
    np.testing.assert_allclose(weights, b_spline(offsets), atol=1e-6)
    np.testing.assert_allclose(weights.sum(axis=2), 1.0, atol=1e-6)
    np.testing.assert_allclose((weights * offsets).sum(axis=2), 0.0, atol=1e-6)
    np.testing.assert_allclose((weights * offsets ** 2).sum(axis=2), 0.25, atol=1e-6)
