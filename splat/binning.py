"""Tile binning: which Gaussians touch which 8x8 tile, in depth order per tile.

Not differentiable: it only decides which pixel meets which Gaussian and in
what order. The outcome is a list of (tile, Gaussian) intersections sorted by
tile, then by camera-space depth, ties by Gaussian index.
"""
from __future__ import annotations

from dataclasses import dataclass

import torch
import warp as wp

from .launch import launch

TILE_SIZE = wp.constant(8)
"""Tile side in pixels."""
ALPHA_MIN = wp.constant(1.0 / 255.0)
"""A Gaussian reaches exactly the pixels where its alpha is at least this."""
POWER_MARGIN = wp.constant(1e-3)
"""Slack on the exponent -1/2 d^T Sigma^-1 d wherever a cheap test stands in for alpha >= 1/255
(tile binning, the compositing pre-test): far above float32 rounding, so they over-cover, never miss."""


@wp.func
def pixel_span(centre: float, half_extent: float, size: int) -> wp.vec2i:
    """First and one-past-last pixel index whose centre (index + 0.5) lies within centre +- half_extent.

    Works in floats clamped to [-1, size + 1] before converting, so that Gaussians
    far off screen cannot overflow the integer conversion.
    """
    lo = wp.clamp(wp.ceil(centre - half_extent - 0.5), -1.0, float(size + 1))
    hi = wp.clamp(wp.floor(centre + half_extent - 0.5) + 1.0, -1.0, float(size + 1))
    return wp.vec2i(wp.clamp(int(lo), 0, size), wp.clamp(int(hi), 0, size))


@wp.func
def extent_squared(conic: wp.vec3, opacity: float) -> float:
    """k^2 with alpha >= 1/255 exactly inside the ellipse d^T Sigma^-1 d <= k^2 = 2 ln(255 opacity)
    (plus the margin); -1 when the Gaussian reaches nothing or is culled (zero conic)."""
    det = conic[0] * conic[2] - conic[1] * conic[1]
    if not (opacity >= ALPHA_MIN and det > 0.0 and conic[0] > 0.0):  # written so that NaN fails too
        return -1.0
    return 2.0 * wp.log(255.0 * opacity) + 2.0 * POWER_MARGIN


@wp.func
def tile_rect(mean2d: wp.vec2, conic: wp.vec3, extent_sq: float, width: int, height: int) -> wp.vec4i:
    """Tiles (x0, y0, x1, y1), end exclusive, whose pixels the ellipse's bounding box covers.

    The box has half-widths sqrt(k^2 Sigma_00) and sqrt(k^2 Sigma_11): the design's
    extent (k times the standard deviation) taken per axis.
    """
    if extent_sq < 0.0:
        return wp.vec4i(0)
    det = conic[0] * conic[2] - conic[1] * conic[1]
    cols = pixel_span(mean2d[0], wp.sqrt(extent_sq * conic[2] / det), width)
    rows = pixel_span(mean2d[1], wp.sqrt(extent_sq * conic[0] / det), height)
    if cols[0] >= cols[1] or rows[0] >= rows[1]:
        return wp.vec4i(0)
    return wp.vec4i(cols[0] // TILE_SIZE, rows[0] // TILE_SIZE,
                    (cols[1] - 1) // TILE_SIZE + 1, (rows[1] - 1) // TILE_SIZE + 1)


@wp.func
def edge_minimum(conic_along: float, conic_cross: float, conic_fixed: float, fixed: float, lo: float, hi: float) -> float:
    """min over t in [lo, hi] of conic_fixed f^2 + 2 conic_cross f t + conic_along t^2, with f = ``fixed``."""
    t = wp.clamp(-conic_cross * fixed / conic_along, lo, hi)
    return conic_fixed * fixed * fixed + 2.0 * conic_cross * fixed * t + conic_along * t * t


@wp.func
def ellipse_meets_tile(mean2d: wp.vec2, conic: wp.vec3, extent_sq: float, tx: int, ty: int,
                       width: int, height: int) -> bool:
    """Whether any pixel centre of tile (tx, ty) lies in the ellipse d^T Sigma^-1 d <= extent_sq.

    Exact for the box spanned by the tile's pixel centres: the convex quadratic's
    minimum over the box is 0 when the mean is inside, else on one of its edges.
    Tiles of the bounding box that the ellipse misses (elongated or tilted
    Gaussians) are dropped, so fewer tile-Gaussian pairs are composited.
    """
    x0 = float(tx * TILE_SIZE) + 0.5 - mean2d[0]
    x1 = float(wp.min((tx + 1) * TILE_SIZE, width)) - 0.5 - mean2d[0]
    y0 = float(ty * TILE_SIZE) + 0.5 - mean2d[1]
    y1 = float(wp.min((ty + 1) * TILE_SIZE, height)) - 0.5 - mean2d[1]
    if x0 <= 0.0 and x1 >= 0.0 and y0 <= 0.0 and y1 >= 0.0:
        return True
    a, b, c = conic[0], conic[1], conic[2]
    q = wp.min(wp.min(edge_minimum(c, b, a, x0, y0, y1), edge_minimum(c, b, a, x1, y0, y1)),
               wp.min(edge_minimum(a, b, c, y0, x0, x1), edge_minimum(a, b, c, y1, x0, x1)))
    return q <= extent_sq


@wp.kernel
def count_tiles_kernel(
    means2d: wp.array(dtype=wp.vec2), conics: wp.array(dtype=wp.vec3), opacities: wp.array(dtype=float),
    width: int, height: int, counts: wp.array(dtype=wp.int64),
):
    i = wp.tid()
    extent_sq = extent_squared(conics[i], opacities[i])
    r = tile_rect(means2d[i], conics[i], extent_sq, width, height)
    count = wp.int64(0)
    for ty in range(r[1], r[3]):
        for tx in range(r[0], r[2]):
            if ellipse_meets_tile(means2d[i], conics[i], extent_sq, tx, ty, width, height):
                count += wp.int64(1)
    counts[i] = count


@wp.kernel
def write_tile_keys_kernel(
    means2d: wp.array(dtype=wp.vec2), conics: wp.array(dtype=wp.vec3), opacities: wp.array(dtype=float),
    width: int, height: int, depth_ranks: wp.array(dtype=wp.int64), offsets: wp.array(dtype=wp.int64),
    keys: wp.array(dtype=wp.int64),
):
    """Key of an intersection: tile * G + depth rank, so one sort orders by tile, then depth, then index."""
    i = wp.tid()
    extent_sq = extent_squared(conics[i], opacities[i])
    r = tile_rect(means2d[i], conics[i], extent_sq, width, height)
    tiles_x = (width + TILE_SIZE - 1) // TILE_SIZE
    n = offsets[i]
    num_gaussians = wp.int64(depth_ranks.shape[0])
    for ty in range(r[1], r[3]):
        for tx in range(r[0], r[2]):
            if ellipse_meets_tile(means2d[i], conics[i], extent_sq, tx, ty, width, height):
                keys[n] = wp.int64(ty * tiles_x + tx) * num_gaussians + depth_ranks[i]
                n += wp.int64(1)


@dataclass
class TileBins:
    """Intersections sorted by (tile, depth, index).

    gaussian_ids: (N,) int64, the Gaussian of each intersection.
    tile_offsets: (tiles + 1,) int32, intersections of tile t are [tile_offsets[t], tile_offsets[t+1]).
    tiles_x, tiles_y: the tile grid, row-major tile index ty * tiles_x + tx.
    """

    gaussian_ids: torch.Tensor
    tile_offsets: torch.Tensor
    tiles_x: int
    tiles_y: int

    @property
    def num_tiles(self) -> int:
        return self.tiles_x * self.tiles_y

    def tile_loads(self) -> torch.Tensor:
        """(tiles,) intersections per tile: the work of compositing it."""
        return self.tile_offsets[1:] - self.tile_offsets[:-1]


def bin_gaussians(means2d: torch.Tensor, conics: torch.Tensor, opacities: torch.Tensor, depths: torch.Tensor,
                  width: int, height: int) -> TileBins:
    """Bin projected Gaussians into tiles, each tile's list sorted front to back.

    Args:
        means2d: (G, 2) px; conics: (G, 3) 1/px^2, zero when culled; opacities: (G,);
        depths: (G,) camera-space z, the sort key; width, height: image size in px.
    """
    G, device = means2d.shape[0], means2d.device
    tiles_x, tiles_y = -(-width // TILE_SIZE), -(-height // TILE_SIZE)
    geometry = [wp.from_torch(means2d.detach().contiguous(), dtype=wp.vec2),
                wp.from_torch(conics.detach().contiguous(), dtype=wp.vec3),
                wp.from_torch(opacities.detach().contiguous()), width, height]

    counts = torch.empty(G, dtype=torch.int64, device=device)
    launch(count_tiles_kernel, G, inputs=geometry, outputs=[wp.from_torch(counts)], device=device)
    ends = torch.cumsum(counts, 0)
    num_intersections = int(ends[-1]) if G else 0

    depth_order = torch.sort(depths.detach(), stable=True).indices
    depth_ranks = torch.empty_like(depth_order)
    depth_ranks[depth_order] = torch.arange(G, device=device)

    keys = torch.empty(num_intersections, dtype=torch.int64, device=device)
    launch(write_tile_keys_kernel, G, inputs=[*geometry, wp.from_torch(depth_ranks), wp.from_torch(ends - counts)],
           outputs=[wp.from_torch(keys)], device=device)
    keys = torch.sort(keys).values

    tiles = keys // max(G, 1)
    gaussian_ids = depth_order[keys - tiles * G]
    tile_counts = torch.bincount(tiles, minlength=tiles_x * tiles_y)
    tile_offsets = torch.zeros(tiles_x * tiles_y + 1, dtype=torch.int32, device=device)
    tile_offsets[1:] = torch.cumsum(tile_counts, 0)
    return TileBins(gaussian_ids, tile_offsets, tiles_x, tiles_y)
