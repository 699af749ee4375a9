"""The appearance of the fill particles: the body's material where the surface opens.

pm-simulate fills each object's volume with a lattice of particles behind its
surface Gaussians (trajectories.h5, ``is_gaussian`` false). Each is rendered as
a Gaussian of its own (as PhysGaussian renders its filled particles):

- colour: that of the surface it lies under, the nearest opaque Gaussian of its
  object at rest (:func:`surface_under`); its rest normal is that Gaussian's too;
- opacity: :data:`INTERIOR_OPACITY`, solid material;
- covariance: round, of standard deviation :data:`GRAIN_SIGMA` lattice spacings
  (:func:`lattice_spacing`), deformed by the particle's own F like any Gaussian.

Where the material flows (:class:`Mixing`: granular flow, a tear), every particle,
surface Gaussians included, becomes a round grain of its share of the volume, and
grains of granular materials each take a brightness of their own (:func:`grain_shades`).

At rest the interior must stay hidden behind the surface, so that frame 0 is the
reconstruction's render. The lattice's outer cells reach up to a cell past the
Gaussians (stages/simulate/fill.py), and a reconstruction's surface is not
opaque everywhere, so some particles would show at rest: :func:`hidden_at_rest`
narrows those near the silhouette and finds the ones that would still show.
Those are transparent at rest and become opaque as their material flows or tears
(:class:`Mixing`, which also grows the narrowed ones back to full grains): the
interior appears where the surface opens, and only there.
"""
from __future__ import annotations

import math

import cv2
import numpy as np
import torch
from scipy.spatial import cKDTree

import splat
from schemas.materials import PRESETS

from .source_map import project, to_camera

GRAIN_SIGMA = 0.5
"""Standard deviation of a fill particle's Gaussian at rest, in lattice spacings. Neighbours half a
spacing from a point between them cover it each with alpha e^-0.5: a lattice seen through one layer
is opaque (alpha >= 0.84 midway between four), a lone grain is a grain of about the spacing."""
INTERIOR_OPACITY = 1.0
"""Opacity of a fill particle (the rasterizer clamps each Gaussian's alpha to 0.99)."""
OPAQUE_ALPHA = 0.99
"""Rest-render alpha from which a pixel hides what lies behind its surface."""
OPAQUE_SURFACE = 0.5
"""Opacity from which a surface Gaussian gives its colour to the interior under it (fainter ones are
the reconstruction's soft edges and floaters, whose colours are mixed with the background's)."""
GRANULAR = ("sand", "snow")
"""The presets whose particles read as grains once they flow (grain_shades)."""
GRAIN_SHADE = 0.13
"""Spread (standard deviation) of the grains' brightness relative to their colour: measured on
scikit-image's gravel photograph (data.gravel, grains about 16 px), its brightness blurred to a
quarter of a grain against the mean over a few grains (0.19 at an eighth, 0.13 at a quarter)."""
FLOW_NEIGHBOURS = 8
"""Nearest particles at rest whose motion relative to a particle tells whether its material flows (Mixing)."""
HIDDEN_TRANSMITTANCE = 1.0 / 255
"""Mean transmittance over its footprint up to which a fill particle counts as hidden in the render at
rest: its colour then moves no pixel by more than about a grey level."""
HIDING_ROUNDS = 4
"""Rounds of dropping the fill particles that show at rest (each can uncover a few behind)."""
REACH_SIGMAS = math.sqrt(2 * math.log(255))
"""How far a Gaussian of opacity 1 reaches in standard deviations: to alpha 1/255 (splat's cut-off)."""
DILATION_PX2 = 0.3
"""splat's EWA dilation of every projected covariance (px^2)."""


def lattice_spacing(rest_positions: np.ndarray, is_gaussian: np.ndarray, object_id: np.ndarray) -> np.ndarray:
    """(P,) the fill lattice's spacing (m) of each particle's object: the median distance from its fill
    particles to their nearest neighbour (fill.py lays one regular lattice per object); inf for an
    object with fewer than two.

    Args:
        rest_positions: (P, 3) the particles at rest, m; is_gaussian, object_id: (P,).
    """
    spacing = np.full(len(rest_positions), np.inf)
    for k in np.unique(object_id):
        points = rest_positions[(object_id == k) & ~is_gaussian]
        if len(points) >= 2:
            spacing[object_id == k] = np.median(cKDTree(points).query(points, k=2)[0][:, 1])
    return spacing


def surface_under(rest_positions: np.ndarray, object_id: np.ndarray, surface_means: np.ndarray,
                  surface_object: np.ndarray, surface_opacity: np.ndarray) -> np.ndarray:
    """(N,) index into the surface Gaussians of the one each fill particle lies under: the nearest at
    rest among its object's Gaussians of opacity at least OPAQUE_SURFACE (among all of them where it
    has none so opaque).

    Args:
        rest_positions: (N, 3), object_id: (N,): the fill particles at rest.
        surface_means: (G, 3), surface_object: (G,), surface_opacity: (G,): the Gaussians.
    """
    under = np.zeros(len(rest_positions), np.int64)
    for k in np.unique(object_id):
        members = object_id == k
        candidates = np.flatnonzero(surface_object == k)
        opaque = candidates[surface_opacity[candidates] >= OPAQUE_SURFACE]
        candidates = opaque if len(opaque) else candidates
        under[members] = candidates[cKDTree(surface_means[candidates]).query(rest_positions[members])[1]]
    return under


def grain_shades(material_id: np.ndarray) -> np.ndarray:
    """(P,) each particle's relative brightness as a grain, GRAIN_SHADE times a standard normal number
    (seeded: the same for every run), for the particles of granular materials (GRANULAR); 0 for the
    others. A heap of grains of one colour is not one flat colour: each grain's facets catch the light
    differently."""
    granular = np.isin(material_id, [PRESETS.index(p) for p in GRANULAR])
    return np.where(granular, GRAIN_SHADE * np.random.default_rng(0).standard_normal(len(material_id)), 0.0)


class Mixing:
    """How far each particle's material has flowed, in [0, 1]: 0 while its neighbourhood moves with
    its own deformation (rigidly or elastically, however far), 1 once its neighbours have moved a
    lattice spacing past what F predicts (granular flow, a tear), never falling back (no flicker):

        mixing_i(t) = max over t' <= t of min(1, mean_j |x_j - x_i - F_i (X_j - X_i)| / spacing_i)

    over its FLOW_NEIGHBOURS nearest particles j of its object at rest. A flowing surface Gaussian is
    no longer a patch of surface: turned edge-on by the flow it would read as a streak, so the render
    turns it into a grain of the material (render.py).

    Args:
        rest_positions: (R, 3) the rendered particles at rest, m; object_id: (R,); spacing: (R,) m
            (lattice_spacing; inf: no lattice, never mixes).
    """

    def __init__(self, rest_positions: torch.Tensor, object_id: np.ndarray, spacing: torch.Tensor):
        points = rest_positions.detach().cpu().double().numpy()
        k = min(FLOW_NEIGHBOURS + 1, len(points))
        neighbours = cKDTree(points).query(points, k=k)[1].reshape(len(points), k)[:, 1:]
        self.neighbours = torch.as_tensor(neighbours, device=rest_positions.device)
        self.same = torch.as_tensor(object_id[neighbours] == object_id[:, None], device=rest_positions.device)
        self.rest_offsets = rest_positions[self.neighbours] - rest_positions[:, None]
        self.spacing = spacing
        self.so_far = torch.zeros(len(points), dtype=rest_positions.dtype, device=rest_positions.device)

    def __call__(self, positions: torch.Tensor, F: torch.Tensor) -> torch.Tensor:
        """(R,) the mixing up to this frame; positions (R, 3) m and F (R, 3, 3) of the frame, in order."""
        if self.neighbours.shape[1] == 0:
            return self.so_far
        predicted = self.rest_offsets @ F.transpose(1, 2)
        departed = (positions[self.neighbours] - positions[:, None] - predicted).norm(dim=-1)
        count = self.same.sum(1).clamp_min(1)
        mean = torch.where(self.same, departed, 0.0).sum(1) / count
        self.so_far = torch.maximum(self.so_far, (mean / self.spacing).clamp(0, 1).nan_to_num(0.0))
        return self.so_far


def blending_weights(means: torch.Tensor, covariances: torch.Tensor, opacities: torch.Tensor,
                     camera: splat.Camera) -> torch.Tensor:
    """(N,) each Gaussian's blending weight T_k alpha_k summed over the pixels of its render from
    ``camera`` (px): the gradient of the rendered sum of a constant feature 1 with respect to it."""
    ones = torch.ones_like(means[:, :1], requires_grad=True)
    splat.rasterize(means.detach(), opacities.detach(), ones, camera, covariances=covariances.detach()).features.sum() \
        .backward()
    return ones.grad[:, 0]


def hidden_at_rest(rest_positions: torch.Tensor, sigma: torch.Tensor, surface_means: torch.Tensor,
                   surface_covariances: torch.Tensor, surface_opacities: torch.Tensor,
                   camera: splat.Camera) -> torch.Tensor:
    """(N,) each fill particle's standard deviation (m) narrowed so that it stays hidden behind the
    surface at rest, and (N,) bool whether it does (those that do not are transparent at rest).

    First each particle is narrowed so that its footprint, out to REACH_SIGMAS of its projected
    standard deviation (with splat's dilation), stays on pixels where the surface's rest alpha is at
    least OPAQUE_ALPHA (0 where its centre is off them or in front of the surface's rendered
    distance). Then, rendered together with the surface at rest, any particle that still shows
    (its summed blending weight, over what it would add alone, above HIDDEN_TRANSMITTANCE: where the
    surface is translucent, or its Gaussians lie behind the particle) is taken out, and again for what that uncovers, up to
    HIDING_ROUNDS times.

    Args:
        rest_positions: (N, 3) world, m; sigma: (N,) their standard deviation from the lattice, m.
        surface_means, surface_covariances, surface_opacities: the G surface Gaussians at rest.
    """
    with torch.no_grad():
        surface = splat.rasterize(surface_means, surface_opacities, torch.zeros_like(surface_means[:, :1]), camera,
                                  covariances=surface_covariances)
    K = torch.as_tensor(camera.K, dtype=rest_positions.dtype, device=rest_positions.device)
    in_camera = to_camera(rest_positions, camera.world_to_camera)
    uv = project(in_camera, K)
    opaque = (surface.alpha >= OPAQUE_ALPHA).cpu().numpy().astype(np.uint8)
    # px from each opaque pixel's centre to the nearest pixel that is not (0 on those)
    room = torch.as_tensor(cv2.distanceTransform(opaque, cv2.DIST_L2, cv2.DIST_MASK_PRECISE),
                           device=rest_positions.device)
    col = uv[:, 0].floor().long()
    row = uv[:, 1].floor().long()
    inside = (col >= 0) & (col < camera.width) & (row >= 0) & (row < camera.height) & (in_camera[:, 2] > 0)
    col, row = col.clamp(0, camera.width - 1), row.clamp(0, camera.height - 1)
    room_px = torch.where(inside, room[row, col] - 0.5, 0.0)  # from the particle's pixel's edge
    behind = in_camera.norm(dim=1) > surface.depth[row, col] / surface.alpha[row, col].clamp_min(OPAQUE_ALPHA)
    px_per_m = K[0, 0] / in_camera[:, 2].clamp_min(1e-9)
    fits_px2 = (room_px.clamp_min(0) / REACH_SIGMAS) ** 2 - DILATION_PX2
    narrowed = torch.minimum(sigma, fits_px2.clamp_min(0).sqrt() / px_per_m)
    hidden = inside & behind & (fits_px2 > 0)
    sigma = torch.where(hidden, narrowed, 0.0)
    eye = torch.eye(3, dtype=surface_covariances.dtype, device=sigma.device)
    G = len(surface_means)
    for _ in range(HIDING_ROUNDS):
        kept = torch.nonzero(hidden)[:, 0]
        weights = blending_weights(
            torch.cat([surface_means, rest_positions[kept].to(surface_means.dtype)]),
            torch.cat([surface_covariances, sigma[kept].to(eye.dtype)[:, None, None] ** 2 * eye]),
            torch.cat([surface_opacities, torch.full((len(kept),), INTERIOR_OPACITY, dtype=surface_opacities.dtype,
                                                     device=sigma.device)]), camera)[G:]
        # what the particle would add alone: its opacity (clamped as splat does) over its projected
        # footprint, 2 pi det(Sigma_2D)^(1/2) with the dilation
        alone = min(INTERIOR_OPACITY, 0.99) * 2 * math.pi * ((sigma[kept] * px_per_m[kept]) ** 2 + DILATION_PX2)
        showing = kept[weights > HIDDEN_TRANSMITTANCE * alone]
        if len(showing) == 0:
            break
        hidden[showing] = False
    return sigma, hidden
