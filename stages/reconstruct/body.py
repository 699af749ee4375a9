"""Each object's body as a signed distance: the solid the closure found, handed to pm-simulate once.

The closure (closure.object_depths) takes a body for each object: a standing solid (a body of revolution
about the vertical or an upright box), the union of its medial balls, or both (a cup and the balls of its
handle), or where the scene gives its thickness the silhouette cut to a slab (Prism); cut flat where it
stands. `Body` evaluates that body's signed distance exactly at any point, and
`sample` lays it on a grid aligned with gravity whose middle node lies on the body's centre of volume
(schemas.solid.SolidGrid), so a body symmetric about a vertical plane through its centre is sampled
symmetrically, whatever the photograph's pixels.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np
from scipy import ndimage

from schemas.camera import MIN_DEPTH, project_points
from schemas.solid import NODES, SolidGrid, gravity_axes, inside_share

from .standing import Revolution, signed_distance_px
from .upright_box import UprightBox

CENTRING_ROUNDS = 3
"""The grid is laid about the body's centre of volume as the grid before it measured it: 3 rounds bring it
within a micrometre on a 12 cm ball."""
MARGIN_NODES = 4
"""Nodes beyond the body's box on each side, so a shift of the centre keeps the body on the grid."""


@dataclass
class Balls:
    """A union of balls: centres (N,3) camera frame, m; radii (N,) m."""

    centres: np.ndarray
    radii: np.ndarray

    def distance(self, points: np.ndarray, chunk: int = 4096) -> np.ndarray:
        """(P,) signed distance in m of points (P,3) to the union."""
        out = np.empty(len(points))
        for start in range(0, len(points), chunk):
            p = points[start:start + chunk]
            gaps = np.linalg.norm(p[:, None, :] - self.centres[None], axis=2) - self.radii[None]
            out[start:start + chunk] = gaps.min(axis=1)
        return out


@dataclass
class Standing:
    """A standing solid fitted in a gravity view (standing.GravityView.R (3,3): rows its axes in the camera
    frame), at `scale` m per unit of its fit."""

    solid: Revolution | UprightBox
    R: np.ndarray
    scale: float

    def distance(self, points: np.ndarray) -> np.ndarray:
        """(P,) signed distance in m of camera-frame points (P,3): exact for a box, for a body of
        revolution the larger of the distance to its side at that height and to its end faces."""
        g = points @ self.R.T / self.scale
        if isinstance(self.solid, UprightBox):
            box = self.solid
            local = np.abs((g - box.centre()) @ box.axes().T) - box.half()
            outside = np.linalg.norm(np.maximum(local, 0.0), axis=1)
            return self.scale * (outside + np.minimum(local.max(axis=1), 0.0))
        rev = self.solid
        radial = np.hypot(g[:, 0] - rev.axis_x, g[:, 2] - 1.0)
        held = np.flatnonzero(rev.radii > 0)
        top, bottom = rev.edges[held[0]], rev.edges[held[-1] + 1]
        slab = np.clip(np.searchsorted(rev.edges, g[:, 1], side="right") - 1, held[0], held[-1])
        ends = np.maximum(top - g[:, 1], g[:, 1] - bottom)
        return self.scale * np.maximum(radial - rev.radii[slab], ends)


@dataclass
class Prism:
    """A flat object: its silhouette's cone of rays cut to a slab, the points whose picture lies on the
    silhouette and within `half` m of the plane x . normal = middle (normal (3,) unit, camera frame; middle m).
    mask (H,W) bool: the silhouette; K (3,3) its camera."""

    mask: np.ndarray
    K: np.ndarray
    normal: np.ndarray
    middle: float
    half: float
    outside_px: np.ndarray = field(init=False, repr=False)
    """(H,W) the silhouette's signed distance in pixels, negative inside (standing.signed_distance_px)."""

    def __post_init__(self):
        self.outside_px = -signed_distance_px(self.mask)

    def distance(self, points: np.ndarray) -> np.ndarray:
        """(P,) signed distance in m of camera-frame points (P,3): the larger of the slab's and the silhouette's
        (its pixels at the point's depth; a lower bound at the rim, exact on the faces)."""
        cols, rows = (project_points(points, self.K) - 0.5).T  # pixel centres at integer indices
        z = np.maximum(points[:, 2], MIN_DEPTH)
        beside = ndimage.map_coordinates(self.outside_px, [rows, cols], order=1, mode="nearest") * z / self.K[0, 0]
        return np.maximum(beside, np.abs(points @ self.normal - self.middle) - self.half)


@dataclass
class Body:
    """The union of parts (Balls, Standing), cut by the ground plane where it stands: `down` (3,) gravity's
    unit direction (camera frame) and `floor` the plane's height, -(x . down) in m, below which nothing is."""

    parts: list = field(default_factory=list)
    down: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))
    floor: float = -np.inf

    def distance(self, points: np.ndarray) -> np.ndarray:
        """(P,) signed distance in m of camera-frame points (P,3), negative inside."""
        d = np.min([part.distance(points) for part in self.parts], axis=0)
        return np.maximum(d, self.floor + points @ self.down)


def sample(body: Body, points: np.ndarray, nodes: int = NODES) -> Optional[SolidGrid]:
    """The body on a grid of nodes^3 aligned with gravity about its centre of volume; `points` (P,3) m
    (camera frame) span it (its front and back). None if the grid holds none of it."""
    axes = gravity_axes(body.down)
    local = points @ axes.T
    span = float(np.max(local.max(0) - local.min(0)))
    spacing = span / (nodes - 1 - 2 * MARGIN_NODES)
    centre = 0.5 * (local.max(0) + local.min(0)) @ axes
    offsets = (np.stack(np.meshgrid(*[np.arange(nodes)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
               - 0.5 * (nodes - 1)) * spacing @ axes
    for _ in range(CENTRING_ROUNDS):
        distance = body.distance(centre + offsets)
        weight = inside_share(distance, spacing)
        if weight.sum() <= 0:
            return None
        centre = centre + weight @ offsets / weight.sum()
    distance = body.distance(centre + offsets)
    return SolidGrid(distance.reshape(nodes, nodes, nodes).astype(np.float32), centre, axes, spacing)
