"""Differentiable Gaussian rasterizer (Warp kernels, torch autograd); it reads and writes no files
(the 3DGS PLY format is schemas.ply).

Standard 3DGS semantics (DESIGN.md, "Rasterizer"): EWA projection with 0.3 px
dilation, alpha clamped to 0.99, a Gaussian reaches the pixels where its alpha
is at least 1/255, front to back by camera z (ties by index), compositing stops
before the transmittance falls below 1e-4. The pipeline, one module per step:
``project`` -> ``binning`` -> ``composite``; ``rasterize`` chains them.
"""
import warp as _wp

_wp.init()  # from_torch and launches need the runtime; init is idempotent

from .camera import Camera
from .covariance import covariances_from_scales_rotations
from .project import DILATION_PX2
from .rasterize import Render, rasterize

__all__ = ["Camera", "DILATION_PX2", "Render", "covariances_from_scales_rotations", "rasterize"]
