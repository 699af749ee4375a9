"""The quadratic B-spline stencil that every particle-grid transfer uses (3x3x3 nodes)."""
from __future__ import annotations

import warp as wp


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


@wp.func
def stencil_weights(fx: wp.vec3):
    """The 3x3x3 stencil's quadratic B-spline weights at fx (cells from its corner node, stencil_base), one row
    per axis: node (i, j, k) of the stencil weighs w[0, i] w[1, j] w[2, k], and the weights sum to 1."""
    return wp.matrix_from_rows(quadratic_weights(fx[0]), quadratic_weights(fx[1]), quadratic_weights(fx[2]))
