"""An object's solid as gaussians.h5 carries it: a signed distance sampled on a grid aligned with gravity.

pm-reconstruct knows each object's body (a body of revolution, an upright box, the union of medial
balls, cut flat where it stands); pm-simulate fills its particles from that body, not from the
Gaussians. The grid's axes are the simulation frame's (`gravity_axes`: x the picture's right made
horizontal, y up, z = x cross y) and its middle node lies on the body's centre of volume, so a body
that is mirror-symmetric about a vertical plane through it is sampled mirror-symmetrically.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np
from scipy import ndimage

NODES = 64
"""Grid nodes along each axis (2 mm on a 12 cm body)."""


def gravity_axes(down: np.ndarray) -> np.ndarray:
    """Rotation Q (3,3), x_sim = Q x_world, taking the unit `down` direction to -y_sim.

    Rows: sim x = world x made orthogonal to up (so the picture's x stays x), sim y = up, sim z = x cross
    y (right-handed).
    """
    up = -down / np.linalg.norm(down)
    x = np.array([1.0, 0.0, 0.0]) - up[0] * up
    if np.linalg.norm(x) < 1e-6:  # gravity along the picture's x axis
        x = np.array([0.0, 0.0, 1.0]) - up[2] * up
    x /= np.linalg.norm(x)
    return np.stack([x, up, np.cross(x, up)])


def inside_share(distance: np.ndarray, cell: float) -> np.ndarray:
    """The share (shape of distance) of a cube of side `cell` m that lies inside a surface at signed distance
    `distance` m from its centre (negative inside): 1/2 less the distance over the side (exact for a face
    parallel to the cube's)."""
    return np.clip(0.5 - distance / cell, 0.0, 1.0)


@dataclass
class SolidGrid:
    """One object's solid. distance (N,N,N) f4: signed distance in m (negative inside) at the nodes;
    centre (3,): the middle node, world (camera) frame, m; axes (3,3): rows the grid's i, j, k directions in
    the world frame (gravity_axes); spacing: m between nodes. Node (i,j,k) lies at
    centre + ((i,j,k) - (N-1)/2) * spacing @ axes."""

    distance: np.ndarray
    centre: np.ndarray
    axes: np.ndarray
    spacing: float

    def node_coordinates(self, points: np.ndarray) -> np.ndarray:
        """(P,3) fractional node indices of world points (P,3) m."""
        return (points - self.centre) @ self.axes.T / self.spacing + 0.5 * (self.distance.shape[0] - 1)

    def distance_at(self, points: np.ndarray) -> np.ndarray:
        """(P,) signed distance in m at world points (P,3) (trilinear; beyond the grid its edge's value)."""
        ijk = self.node_coordinates(points)
        return ndimage.map_coordinates(self.distance.astype(np.float64), ijk.T, order=1, mode="nearest")

    def inside_fraction(self, points: np.ndarray, cell: float) -> np.ndarray:
        """(P,) the share of a cube of side `cell` m about each point (P,3) that lies inside (inside_share)."""
        return inside_share(self.distance_at(points), cell)

    def volume(self) -> float:
        """m^3 inside the solid: each node's cube, one spacing wide, by its share inside."""
        return float(inside_share(self.distance.astype(np.float64), self.spacing).sum()) * self.spacing ** 3


def solid_fields(solids: Sequence[Optional[SolidGrid]]) -> dict:
    """The gaussians.h5 fields (GaussiansArtifact.solid_*) of one solid per object; None: no solid (an
    init_ply's or a learned prior's object, whose solid is its Gaussians'), stored as NaN."""
    n = next((s.distance.shape[0] for s in solids if s is not None), 1)
    distance = np.full((len(solids), n, n, n), np.nan, np.float32)
    centre, axes, spacing = (np.full((len(solids), 3), np.nan), np.full((len(solids), 3, 3), np.nan),
                             np.full(len(solids), np.nan))
    for k, s in enumerate(solids):
        if s is not None:
            distance[k], centre[k], axes[k], spacing[k] = s.distance, s.centre, s.axes, s.spacing
    return dict(solid_distance=distance, solid_centre=centre, solid_axes=axes, solid_spacing=spacing)


def solids_of(distance: np.ndarray, centre: np.ndarray, axes: np.ndarray, spacing: np.ndarray
              ) -> list[Optional[SolidGrid]]:
    """The per-object solids (None where there is none) of the gaussians.h5 fields (solid_fields)."""
    return [SolidGrid(distance[k], centre[k], axes[k], float(spacing[k])) if np.isfinite(spacing[k]) else None
            for k in range(len(spacing))]
