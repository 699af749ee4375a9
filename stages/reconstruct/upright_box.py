"""An upright box standing on the ground, fitted to a silhouette seen in a GravityView (standing.py).

Cartons, books and other things with corners: where its image overlaps the silhouette best the box is the body
(standing.standing_solid, docs/decisions/0019-standing-solids.md). The fit works in the gravity frame of
a view turned to face the object (x across, y down along gravity, z horizontal towards the silhouette),
the ground at y = 1.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Optional

import numpy as np
from scipy import ndimage, optimize
from scipy.spatial import ConvexHull, QhullError

from .depth import edge_points

if TYPE_CHECKING:
    from .standing import GravityView

BOX_YAWS_DEG = (0.0, 20.0, 40.0, 60.0, 80.0)
"""The box's fit starts from these turns (a box turned by 90 degrees is the same box)."""


@dataclass
class UprightBox:
    """A box standing on the ground y = 1 of the gravity frame: base centre (x, 1, z), yaw (radians) about the
    vertical, width (along its turned x), depth (along its turned z), height."""

    x: float
    z: float
    yaw: float
    width: float
    depth: float
    height: float
    kind = "upright box"

    @property
    def extent(self) -> float:
        """Largest extent: its longest side."""
        return max(self.width, self.depth, self.height)

    def axes(self) -> np.ndarray:
        """(3,3) rows: its own x, y (down), z in the gravity frame."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])

    def centre(self) -> np.ndarray:
        """(3,) its middle."""
        return np.array([self.x, 1.0 - self.height / 2, self.z])

    def half(self) -> np.ndarray:
        """(3,) half its sides along its own x, y, z."""
        return 0.5 * np.array([self.width, self.height, self.depth])

    def corners(self) -> np.ndarray:
        """(8,3) its corners."""
        signs = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)
        return self.centre() + (signs * self.half()) @ self.axes()

    def intersect(self, rays: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(t_in, t_out) (N,) where rays t * rays (N,3) enter and leave it (slabs); NaN where they miss."""
        origin = -self.axes() @ self.centre()
        d = rays @ self.axes().T
        with np.errstate(divide="ignore", invalid="ignore"):
            a, b = (-self.half() - origin) / d, (self.half() - origin) / d
        a = np.where(d == 0, np.where(np.abs(origin) <= self.half(), -np.inf, np.nan), a)
        b = np.where(d == 0, np.where(np.abs(origin) <= self.half(), np.inf, np.nan), b)
        enter, leave = np.minimum(a, b).max(1), np.maximum(a, b).min(1)
        hit = enter < leave
        return np.where(hit, enter, np.nan), np.where(hit, leave, np.nan)

    def base_height(self) -> float:
        """The height (y, downwards) of its base: the ground."""
        return 1.0


def hull_of(view: GravityView, box: UprightBox) -> Optional[np.ndarray]:
    """(M,2) image coordinates of the box's image, counter-clockwise; None if it is not in front of the camera."""
    corners = box.corners()
    if np.any(corners @ view.R[:, 2] <= 1e-6):
        return None
    uv = view.project(corners)
    try:
        return uv[ConvexHull(uv).vertices]
    except QhullError:
        return None


def outline_distance(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Distance (N,) of points (N,2) from the boundary of a polygon (M,2)."""
    a, b = polygon, np.roll(polygon, -1, axis=0)
    edge = b - a
    s = np.clip(np.einsum("nmk,mk->nm", points[:, None, :] - a[None], edge) / np.sum(edge * edge, 1), 0.0, 1.0)
    nearest = a[None] + s[..., None] * edge[None]
    return np.linalg.norm(points[:, None, :] - nearest, axis=2).min(1)


def upright_box(view: GravityView) -> Optional[UprightBox]:
    """The box standing on the ground whose image best follows the outline: Nelder-Mead on the mean squared
    distance of the outline from the image's edge plus that of the image's edge from the outline (the
    blurred signed distance), from BOX_YAWS_DEG, the rest started from the silhouette's lowest point and
    its width and height."""
    outline = edge_points(view.mask)[:, ::-1] + 0.5  # (u, v)
    rows, cols = np.nonzero(view.mask)
    focal = view.K[0, 0]
    low = view.rays(np.array([rows.max()]), np.array([int(np.median(cols[rows == rows.max()]))]))[0]
    if low[1] <= 0:  # its lowest point does not look down at the ground
        return None
    near = low / low[1]  # where that ray meets the ground y = 1
    size = np.ptp(cols) / focal * near[2] / math.sqrt(2)
    tall = np.ptp(rows) / focal * near[2] * 0.7
    samples = np.linspace(0.0, 1.0, 12, endpoint=False)

    def cost(p: np.ndarray) -> float:
        x, z, yaw, w, d, h = p
        if min(w, d, h) <= 0:
            return 1e9
        polygon = hull_of(view, UprightBox(x, z, yaw, w, d, h))
        if polygon is None:
            return 1e9
        edge = np.roll(polygon, -1, axis=0) - polygon
        along = polygon[:, None, :] + samples[None, :, None] * edge[:, None, :]
        lengths = np.repeat(np.linalg.norm(edge, axis=1), len(samples))
        sdf = ndimage.map_coordinates(view.sdf, [along[..., 1].ravel() - 0.5, along[..., 0].ravel() - 0.5],
                                      order=1, mode="nearest")
        return float(np.mean(outline_distance(outline, polygon) ** 2) + np.sum(lengths * sdf ** 2) / lengths.sum())

    best = None
    for yaw in BOX_YAWS_DEG:
        start = np.array([near[0], near[2] + size / 2, math.radians(yaw), size, size, tall])
        simplex = start + np.diag([0.1 * size, 0.1 * size, 0.2, 0.2 * size, 0.2 * size, 0.2 * tall])
        result = optimize.minimize(cost, start, method="Nelder-Mead",
                                   options={"initial_simplex": np.vstack([start, simplex]), "xatol": 1e-5,
                                            "fatol": 1e-6, "maxfev": 1500})
        if best is None or result.fun < best.fun:
            best = result
    return UprightBox(*best.x)
