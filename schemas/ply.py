"""Import and export of Gaussians in the standard 3DGS PLY layout.

One ``vertex`` element with float properties x y z (metres), f_dc_0..2
(degree-0 spherical-harmonic coefficients: colour = 0.5 + SH_C0 * f_dc),
opacity (logit), scale_0..2 (log) and rot_0..3 (quaternion w x y z, not
necessarily unit). Files from other tools (3DGS, LGM, gsplat) may carry more
properties (normals, f_rest_* for view-dependent colour); reading ignores them,
because physmotion's colours are not view-dependent. Writing emits the fields
above plus zero normals, the layout LGM and most viewers read.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from plyfile import PlyData, PlyElement, PlyParseError

from .program import InputError

log = logging.getLogger(__name__)

SH_C0 = 0.28209479177387814
"""Degree-0 spherical harmonic, 1 / (2 sqrt(pi))."""
OPACITY_EPS = 1e-6
"""Opacities are clipped to [eps, 1 - eps] before the logit so that 0 and 1 stay finite."""

_FIELDS = {
    "means": ["x", "y", "z"],
    "colors": ["f_dc_0", "f_dc_1", "f_dc_2"],
    "opacities": ["opacity"],
    "scales": ["scale_0", "scale_1", "scale_2"],
    "rotations": ["rot_0", "rot_1", "rot_2", "rot_3"],
}
_WRITE_ORDER = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2", "opacity",
                "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]


@dataclass
class GaussianCloud:
    """Gaussians as physmotion holds them (DESIGN.md, Conventions), in the frame of whoever made them
    (LGM's are OpenGL-style); float numpy arrays (read_ply gives float32).

    means (G, 3) metres; scales (G, 3) linear standard deviations, metres;
    rotations (G, 4) unit quaternions (w, x, y, z); opacities (G,) in [0, 1];
    colors (G, 3) sRGB in [0, 1] (read as stored, not clipped).
    """

    means: np.ndarray
    scales: np.ndarray
    rotations: np.ndarray
    opacities: np.ndarray
    colors: np.ndarray

    def __len__(self) -> int:
        return len(self.means)

    def select(self, keep: np.ndarray) -> "GaussianCloud":
        """The Gaussians ``keep`` (G,) bool or indices picks."""
        return GaussianCloud(self.means[keep], self.scales[keep], self.rotations[keep], self.opacities[keep],
                             self.colors[keep])


def read_ply(path: str | Path) -> GaussianCloud:
    """Read a 3DGS PLY file; raises InputError naming the file and field when it is not one."""
    path = Path(path)
    fix = "give a PLY exported by 3D Gaussian Splatting, LGM or gsplat (binary or ASCII)"
    try:
        vertices = PlyData.read(str(path))["vertex"].data
    except FileNotFoundError:
        raise InputError(path, None, "the file does not exist", "check the path (reconstruct.init_ply)") from None
    except KeyError:
        raise InputError(path, "vertex", "the PLY has no 'vertex' element", fix) from None
    except (PlyParseError, ValueError) as err:  # malformed header or body; ValueError covers bad bytes
        raise InputError(path, None, f"not a readable PLY file ({err})", fix) from None

    names = set(vertices.dtype.names)
    columns = {}
    for key, fields in _FIELDS.items():
        missing = [f for f in fields if f not in names]
        if missing:
            raise InputError(path, ", ".join(missing), f"the vertex element lacks {', '.join(missing)}", fix)
        columns[key] = np.stack([np.asarray(vertices[f], dtype=np.float64) for f in fields], axis=-1)
        if not np.all(np.isfinite(columns[key])):
            raise InputError(path, ", ".join(fields), "some values are NaN or infinite",
                             "remove or repair those Gaussians in the tool that wrote the file")
    if any(n.startswith("f_rest_") for n in names):
        log.info("%s: ignoring f_rest_* (view-dependent colour); physmotion keeps the degree-0 colour", path)

    norms = np.linalg.norm(columns["rotations"], axis=-1, keepdims=True)
    if np.any(norms == 0):
        raise InputError(path, "rot_0..rot_3", f"{int(np.sum(norms == 0))} Gaussians have a zero quaternion",
                         "write a valid rotation for every Gaussian (identity is 1 0 0 0)")
    return GaussianCloud(
        means=columns["means"].astype(np.float32),
        scales=np.exp(columns["scales"]).astype(np.float32),
        rotations=(columns["rotations"] / norms).astype(np.float32),
        opacities=(1.0 / (1.0 + np.exp(-columns["opacities"][:, 0]))).astype(np.float32),
        colors=(0.5 + SH_C0 * columns["colors"]).astype(np.float32),
    )


def write_ply(path: str | Path, gaussians: GaussianCloud) -> None:
    """Write Gaussians as a binary little-endian 3DGS PLY (see the module docstring)."""
    G = gaussians.means.shape[0]
    opacities = np.clip(np.asarray(gaussians.opacities, dtype=np.float64), OPACITY_EPS, 1.0 - OPACITY_EPS)
    values = {
        **dict(zip(_FIELDS["means"], np.asarray(gaussians.means, dtype=np.float64).T)),
        "nx": np.zeros(G), "ny": np.zeros(G), "nz": np.zeros(G),
        **dict(zip(_FIELDS["colors"], ((np.asarray(gaussians.colors, dtype=np.float64) - 0.5) / SH_C0).T)),
        "opacity": np.log(opacities / (1.0 - opacities)),
        **dict(zip(_FIELDS["scales"], np.log(np.asarray(gaussians.scales, dtype=np.float64)).T)),
        **dict(zip(_FIELDS["rotations"], np.asarray(gaussians.rotations, dtype=np.float64).T)),
    }
    vertices = np.empty(G, dtype=[(name, "<f4") for name in _WRITE_ORDER])
    for name in _WRITE_ORDER:
        vertices[name] = values[name]
    PlyData([PlyElement.describe(vertices, "vertex")], byte_order="<").write(str(path))
