"""The appearance of the fill particles: the body's material where the surface opens.

pm-simulate fills each object's volume with a lattice of particles behind its
surface Gaussians (trajectories.h5, ``is_gaussian`` false). Each is rendered as
a Gaussian of its own (as PhysGaussian renders its filled particles):

- colour: the surface's in front of it at rest, the Gaussians' render on its rest ray
  (:func:`fitted_photograph`, :func:`rest_ray_colours`), a porous solid's crumb (:func:`crumb_colours`);
  its rest normal is that of the surface it lies under, the nearest opaque Gaussian of its object at rest
  (:func:`surface_under`);
- opacity: :data:`INTERIOR_OPACITY`, solid material;
- covariance: round, of standard deviation :data:`GRAIN_SIGMA` lattice spacings
  (:func:`lattice_spacing`), deformed by the particle's own F like any Gaussian.

Where the material flows (:class:`Mixing`: granular flow, a tear; never an elastic solid's,
:data:`ELASTIC`), every particle, surface Gaussians included, becomes a hard grain of about a lattice
spacing (:func:`grain_shapes`): a solid's round and on its lattice; sand's and snow's of varied sizes,
elongated and turned at random, each moved off its lattice site by a random fraction of the cell
(:func:`grain_offsets`: a heap shows no lattice). A grain takes the photograph's colour where its rest
position projects (:func:`rest_ray_colours`: a two-coloured body's inside keeps the colour of the part it
belongs to, so a heap shows both); a porous solid's interior, the crumbs of its torn face, the colour of its
object's lit half (:func:`crumb_colours`). A particle is a centimetre of material, not one of its grains: over
it lie the material's own grains and pores, sized from the material and drawn no finer than the frame shows
(:func:`fine_structure`, :func:`fine_features`): sand's and snow's grains, brighter and darker as a granular
photograph's pixels are at as many grains a pixel, spilling past their particle so that neighbours mix; a
porous solid's pores, lit as light bouncing in their cavities (:func:`pore_shades`).

At rest the interior must stay hidden behind the surface, so that frame 0 is the
reconstruction's render. The lattice's outer cells reach up to a cell past the
Gaussians (stages/simulate/fill.py), and a reconstruction's surface is not
opaque everywhere, so some particles would show at rest: :func:`hidden_at_rest`
narrows those near the silhouette and finds the ones that would still show, from
forward renders only (:func:`exposure`), so that the choice is the same bytes on
every run and thread count.
Those are transparent at rest and become opaque as their material flows or tears
(:class:`Mixing`, which also grows the narrowed ones back to full grains): the
interior appears where the surface opens, and only there.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import cv2
import numpy as np
import torch
from scipy import ndimage
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

import splat
from schemas.camera import project_points

from .source_map import to_camera

GRAIN_SIGMA = 0.5
"""Standard deviation of a fill particle's Gaussian at rest, in lattice spacings. Neighbours half a
spacing from a point between them cover it each with alpha e^-0.5: a lattice seen through one layer
is opaque (alpha >= 0.84 midway between four), a lone grain is a grain of about the spacing."""
INTERIOR_OPACITY = 1.0
"""Opacity of a fill particle (the rasterizer clamps each Gaussian's alpha to 0.99)."""
OPAQUE_ALPHA = 0.99
"""Rest-render alpha from which a pixel hides what lies behind its surface."""
OPAQUE_SURFACE = 0.5
"""Opacity from which a surface Gaussian gives its rest normal to the interior under it (fainter ones are
the reconstruction's soft edges and floaters)."""
GRANULAR = ("sand", "snow")
"""The presets whose grains take the photograph's colours on their rest rays once they flow."""
ELASTIC = ("jelly",)
"""The presets that only deform elastically, neither yielding nor tearing: their material never flows
(:class:`Mixing`). What their particles depart from F is the simulation's, where a held region meets a pushed
one (the coffee's cup: a fifth of its particles above 0.05), and drawn as grains it shows a jelly's wall as
discs in single pixels' colours of the photograph."""
POROUS = ("fracture", "foam")
"""The presets whose broken or torn material shows pores (pores): crumb, a cake's or a sponge's inside. A ductile
solid (metal, plasticine) that flows stays a continuous material of its colours."""
GRAIN_OPACITY = 50.0
"""Opacity of a grain of flowing material (alpha = min(0.99, opacity exp(-r^2 / 2 sigma^2)), so above 1
a flat-topped disc): a grain is an opaque solid with a hard edge, and at 50 its alpha falls from 0.9 to 0.1
over a quarter of its radius (the edge antialiased), where a Gaussian of opacity 1 takes over 1.4 radii
and a heap of them reads as a blur of one colour."""
GRAIN_EDGE_SIGMAS = math.sqrt(2 * math.log(2 * GRAIN_OPACITY))
"""A hard grain's alpha-1/2 radius in standard deviations: opacity exp(-r^2 / 2 sigma^2) = 1/2 at
r = sigma sqrt(2 ln(2 GRAIN_OPACITY))."""
GRAIN_SHADE = 0.11
"""Spread (standard deviation) of a pixel's brightness over its neighbourhood's (a Gaussian of 2 px) where a pixel
spans one grain: scikit-image's gravel photograph (data.gravel, grains about 16 px) area-averaged to 16 px a pixel.
Where a pixel spans k grains it spreads k^-GRAIN_SHADE_FALLOFF of it (0.065, 0.045 and 0.034 at 2, 3 and 4)."""
GRAIN_SHADE_FALLOFF = 0.86
"""Power of the grains across a pixel by which its brightness's spread falls (GRAIN_SHADE): 1 for grains
shaded each on its own; the gravel's falls slower, its light and shade spanning a few grains."""
FINE_BLUR = 0.39
"""Share of a drawn grain's brightness spread that the frame's pixels show: a grain is a soft Gaussian, splat's
dilation widens it, and it overlaps its neighbours. Measured on a flat layer of sand at 1 to 4 grains a pixel
(0.38 to 0.42); with it the layer's pixels spread 0.117, 0.067 and 0.048 at 1, 2 and 3 grains a pixel, the
gravel's 0.112, 0.065 and 0.045 (tests/render_enhance/test_render_grains.py)."""
GRAIN_SIZES = (0.6, 1.3)
"""Range of a flowing sand particle's diameter over the lattice's grain (uniform, then scaled by 1 / sqrt of
the mean square, so that the particles cover on average the area the lattice's do): particles all of one
size on a lattice read as scales."""
GRAIN_ELONGATION = 1.5
"""A flowing sand particle's long axis over its two short ones (a heap of round discs reads as bubbles)."""
GRAIN_DIAMETER = 0.5e-3
"""Diameter of a grain of sand or snow, m: medium sand (0.25-0.5 mm on Wentworth's scale), old snow's
rounded grains (0.2-1 mm). A particle of the simulation (a lattice spacing, about a centimetre) holds
thousands of them: its picture is their texture, not one grain."""
PORE_DIAMETERS = (0.3e-3, 3e-3)
"""Range of the diameter of a crumb's pores, m (log-uniform, so that most are small): bread's gas cells,
from a tenth of a millimetre to a few, half of them under a millimetre."""
PORE_SHARE = 0.3
"""Share of a torn crumb's face that its pores take: the void fraction of bread's sliced crumb (0.2-0.5 in
image analyses of white bread)."""
PORE_OPENINGS = (0.25, 0.75)
"""Range of the share f of a pore's sphere that the torn face cuts away (uniform): from a cavity barely
opened to a shallow bowl. Lit by a sky that fills its opening, the inside of a sphere sees the opening with
view factor f wherever it stands, and the rest of itself with 1 - f, so with albedo rho its radiosity is
rho f E / (1 - rho (1 - f)) against a flat face's rho E (pore_shades)."""
FINE_PX = 1.0
"""The smallest diameter (output px, at the particle's distance at rest) a grain or pore is drawn at, a pixel:
splat's antialiasing (DILATION_PX2) widens it to about 1.6 px (full width at half maximum), and a finer
Gaussian would be that filter alone. A drawn grain larger than the material's stands for the grains within it
(fine_structure). At 1.5 px the sand's texture is as strong, its variance of the Laplacian a third lower."""
GRAIN_REACH = 1.5
"""How far from its particle's centre a grain of sand or snow lies, in the particle's picture's radii: the
grains of neighbouring particles interleave where they meet, as sand of two colours does where it mixes, and
the heap shows no particle's outline."""
FWHM_SIGMAS = 2 * math.sqrt(2 * math.log(2))
"""A Gaussian's full width at half maximum in standard deviations (2.355)."""
FINE_PER_PARTICLE = 64
"""At most this many grains or pores drawn on one particle (a particle 10 px across at FINE_PX)."""
EDGE_PX = 2
"""Pixels inside its silhouette from which the photograph gives a grain its colour (the silhouette's own mix in the
background)."""
LUMA = np.array([0.299, 0.587, 0.114])
"""Rec. 601 luma weights of linear-in-code RGB."""
FLOW_NEIGHBOURS = 8
"""Nearest particles at rest whose motion relative to a particle tells whether its material flows (Mixing)."""
HIDDEN_TRANSMITTANCE = 1.0 / 255
"""Mean transmittance over its footprint up to which a fill particle counts as hidden in the render at
rest: its colour then moves no pixel by more than about a grey level."""
HIDING_ROUNDS = 4
"""Rounds of dropping the fill particles that show at rest (each can uncover a few behind)."""
LAYERS_PER_RENDER = 32
"""Depth layers of transmittance per render (channels; transmittance_layers)."""
REACH_SIGMAS = math.sqrt(2 * math.log(255))
"""How far a Gaussian of opacity 1 reaches in standard deviations: to alpha 1/255 (splat's cut-off; 3.3)."""


def lattice_spacing(spacing: float, is_gaussian: np.ndarray, object_id: np.ndarray) -> np.ndarray:
    """(P,) the fill lattice's spacing (m) of each particle's object: `spacing`, trajectories.h5's
    /particles@lattice_spacing; inf for an object with fewer than two fill particles (no lattice).

    Args:
        is_gaussian, object_id: (P,).
    """
    per_particle = np.full(len(object_id), np.inf)
    for k in np.unique(object_id):
        if np.count_nonzero((object_id == k) & ~is_gaussian) >= 2:
            per_particle[object_id == k] = spacing
    return per_particle


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


def grain_shapes(spacing: np.ndarray, granular: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(P, 3, 3) covariance (m^2) and (P,) opacity of each particle as a grain of its material, once
    its material flows (Mixing): sand and snow as they heap, a torn solid's crumbs along its tear.

    A hard grain of GRAIN_OPACITY about the size of the lattice: an ellipsoid whose alpha is 1/2 on the
    surface of volume (4/3) pi (s r)^3, r = GRAIN_SIGMA sqrt(2 ln 2) spacing (so neighbours overlap and a
    heap or a torn face is opaque). Of sand and snow (``granular``), s is the grain's size, uniform over
    GRAIN_SIZES scaled so that the mean of s^2 is 1 (the grains cover the area the lattice's would), its
    long axis GRAIN_ELONGATION times its two short ones, turned at random (seeded: the same for every run).
    Of a solid, s = 1 and the grain is round, the ball of about its cell's volume (r = 0.59 spacings, the
    cell's ball 0.62), so that a torn piece's outline is its material's: its texture is its pores
    (:func:`pores`). A grain's size does not follow the volume its particle carries: a cell the surface
    cuts carries a sliver of it, and a surface Gaussian none (stages/simulate/fill.py). A torn face drawn in
    soft grains of its share of the volume is a blur a lattice spacing wide.

    Args:
        spacing: (P,) each particle's lattice spacing, m (lattice_spacing; inf where its object has no
            lattice: a covariance of 0 there, which the render replaces by the particle's own);
        granular: (P,) bool, a particle of sand or snow.
    """
    low, high = GRAIN_SIZES
    mean_square = (high ** 3 - low ** 3) / (3 * (high - low))  # of s uniform on [low, high]
    sizes = np.random.default_rng(1).uniform(low, high, len(spacing)) / math.sqrt(mean_square)
    sizes = np.where(granular, sizes, 1.0)
    # alpha 1/2 where opacity exp(-r^2 / 2 sigma^2) = 1/2: r = sigma sqrt(2 ln(2 opacity))
    half_alpha_radius = (GRAIN_SIGMA * math.sqrt(2 * math.log(2)) * sizes
                         * np.where(np.isfinite(spacing), spacing, 0.0))
    hard_sigma = half_alpha_radius / GRAIN_EDGE_SIGMAS
    elongation = np.where(granular, GRAIN_ELONGATION, 1.0)[:, None]
    axes = elongation ** np.array([2 / 3, -1 / 3, -1 / 3])  # product 1: the round grain's volume
    turns = Rotation.random(len(spacing), random_state=0).as_matrix()
    hard = np.einsum("pij,pj,pkj->pik", turns, axes ** 2, turns) * hard_sigma[:, None, None] ** 2
    return hard, np.full(len(spacing), GRAIN_OPACITY)


def grain_offsets(spacing: np.ndarray) -> np.ndarray:
    """(P, 3) m: where a particle's grain is drawn, from its position, once its material flows
    (Mixing): uniform over the lattice cell centred on it (seeded: the same for every run); 0 where
    there is no lattice (spacing inf).

    The particles sit on the simulation's lattice, and a heap near the camera would show it as a
    honeycomb of grains. A shift uniform over the cell puts each grain anywhere in its cell: the
    centres' structure factor at every reciprocal lattice vector is then that of independent points,
    |E exp(i k d)|^2 = prod sinc^2(k_j s / 2) = 0 (no lattice peak).

    Args:
        spacing: (P,) m (lattice_spacing).
    """
    shift = np.random.default_rng(2).uniform(-0.5, 0.5, (len(spacing), 3))
    return shift * np.where(np.isfinite(spacing), spacing, 0.0)[:, None]


def inner_pixels(labels: np.ndarray, k: int) -> np.ndarray:
    """(H, W) bool: the pixels of object k at least EDGE_PX inside its silhouette (eroded by a disc of radius
    EDGE_PX), or all of its pixels where none lies that far inside (a thin object); labels (H, W) 0
    background, k + 1 object k (gaussians.h5's mask)."""
    own = (labels == k + 1).astype(np.uint8)
    inner = cv2.erode(own, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * EDGE_PX + 1, 2 * EDGE_PX + 1)))
    return (inner if inner.any() else own) > 0


def rest_ray_colours(rest_positions: np.ndarray, object_id: np.ndarray, photo: np.ndarray, labels: np.ndarray,
                     K: np.ndarray, world_to_camera: np.ndarray) -> np.ndarray:
    """(N, 3) in [0, 1]: the photograph's colour where each point projects at rest, read at the nearest
    pixel of its own object that lies at least EDGE_PX inside the object's silhouette (the silhouette's
    own pixels mix the object's colour with the background's; a point that projects off its object, a
    side wall's, takes the colour of the object next to it).

    Args:
        rest_positions: (N, 3) world, m; object_id: (N,).
        photo: (H, W, 3) u8 RGB; labels: (H, W) 0 background, k + 1 object k (gaussians.h5's mask);
        K: (3, 3) the photograph's intrinsics; world_to_camera: (4, 4).
    """
    uv = project_points(to_camera(rest_positions, world_to_camera), K)
    H, W = labels.shape
    col = np.clip(np.floor(uv[:, 0]), 0, W - 1).astype(np.int64)
    row = np.clip(np.floor(uv[:, 1]), 0, H - 1).astype(np.int64)
    colours = np.zeros((len(rest_positions), 3))
    for k in np.unique(object_id):
        source = inner_pixels(labels, k)
        if not source.any():
            continue
        members = object_id == k
        nearest_row, nearest_col = ndimage.distance_transform_edt(~source, return_distances=False,
                                                                  return_indices=True)
        r, c = nearest_row[row[members], col[members]], nearest_col[row[members], col[members]]
        colours[members] = photo[r, c] / 255.0
    return colours


def fitted_photograph(means: torch.Tensor, covariances: torch.Tensor, opacities: torch.Tensor, colors: torch.Tensor,
                      camera: splat.Camera) -> np.ndarray:
    """(H, W, 3) u8 RGB: the surface Gaussians (means (G, 3), m; covariances (G, 3, 3), m^2; opacities (G,);
    colors (G, 3)) rendered at rest in the photograph's ``camera``, their colour over their alpha (black where
    they draw none): the photograph as the fit sees it, its single pixels' highlights and noise averaged away."""
    with torch.no_grad():
        render = splat.rasterize(means, opacities, colors, camera, covariances=covariances)
    colour = render.features / render.alpha[..., None].clamp_min(1e-6)
    return (colour.clamp(0, 1) * 255 + 0.5).to(torch.uint8).cpu().numpy()


def crumb_colours(object_id: np.ndarray, photo: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """(N, 3) in [0, 1]: the colour of each point's object where it opens (a torn face, its crumbs): the
    mean of the photograph's colours over the object's pixels at least EDGE_PX inside its silhouette whose
    luma (Rec. 601) is at least the object's median; black for an object the photograph does not show.

    The photograph shows an object's surface shaded (its side away from the light, the dark lines of a
    crust's texture, the cavities between its bumps): the mean over all its pixels is darker than its
    material. A freshly opened face has none of that surface's weathering, and its own shading comes from
    its pores (fine_structure): its colour is the object's lit half.

    Args:
        object_id: (N,); photo: (H, W, 3) u8 RGB; labels: (H, W) 0 background, k + 1 object k
            (gaussians.h5's mask).
    """
    colours = np.zeros((len(object_id), 3))
    for k in np.unique(object_id):
        pixels = photo[inner_pixels(labels, k)].astype(np.float64) / 255.0
        if len(pixels) == 0:
            continue
        luma = pixels @ LUMA
        colours[object_id == k] = pixels[luma >= np.median(luma)].mean(0)
    return colours


class FineStructure(NamedTuple):
    """The grains or pores drawn on the particles, M in all, fixed at rest (fine_structure): owner (M,) the
    particle each lies on; place (M, 2) where in its particle's picture (a point of the unit disc, the picture's
    right and down, scaled to the particle's alpha-1/2 ellipse as drawn); sigma (M,) its standard deviation, m
    (round); factor (M, 3) its colour over its particle's."""

    owner: np.ndarray
    place: np.ndarray
    sigma: np.ndarray
    factor: np.ndarray


def pore_shades(colours: np.ndarray, openings: np.ndarray) -> np.ndarray:
    """(N, 3) the brightness of a pore's inside over its face's, per channel: f / (1 - rho (1 - f)), rho the
    face's colour ``colours`` (N, 3) in [0, 1] taken as its albedo, f the share of the pore's sphere the face
    cuts away (``openings`` (N,), PORE_OPENINGS): a pore's light bounces off its own walls, so a light crumb's
    pores are lighter than a dark one's, and warmer than its face (its darker channels lose more)."""
    f = openings[:, None]
    return f / (1 - colours * (1 - f))


def fine_structure(granular: np.ndarray, porous: np.ndarray, covariances: np.ndarray, depth: np.ndarray,
                   focal: float, colours: np.ndarray) -> FineStructure:
    """The grains of sand or snow and the pores of crumb drawn on each particle once its material flows, sized
    from the material (GRAIN_DIAMETER, PORE_DIAMETERS), not from the lattice (seeded: the same for every run).

    A grain or pore of diameter d is drawn at max(d, FINE_PX z / focal), z the particle's distance ``depth``
    (P,), m, at rest and ``focal`` the frames' focal length, px: a round Gaussian whose full width at half
    maximum is that diameter, of opacity 1. With splat's dilation (DILATION_PX2) its alpha sums to
    a = 2 pi (sigma^2 + DILATION_PX2 (z / focal)^2) over the picture, the area it covers. The particle is a
    ball of its grain's volume (``covariances`` (P, 3, 3) m^2, grain_shapes), of alpha-1/2 radius r.

    Sand and snow (``granular`` (P,) bool): pi (GRAIN_REACH r)^2 / a grains, about one over each point of the
    disc they lie in, each of brightness 1 + s n, n a normal number cut at +-2:
    s = GRAIN_SHADE min(1, d / p)^GRAIN_SHADE_FALLOFF / FINE_BLUR, p a pixel's width there, so that a pixel's
    brightness spreads as the gravel's where a pixel spans as many grains (p / d). Crumb (``porous``): pores of
    log-uniform diameters over PORE_SHARE of the particle's share of a face (its volume's power 2/3), each of
    its colour ``colours`` (P, 3) in [0, 1] times pore_shades. At most FINE_PER_PARTICLE on a particle; none on
    the others."""
    rng = np.random.default_rng(3)
    P = len(depth)
    px = depth / focal  # m a pixel at each particle
    floor = FINE_PX * px
    radius = GRAIN_EDGE_SIGMAS * np.abs(np.linalg.det(covariances)) ** (1 / 6)
    grain = np.maximum(GRAIN_DIAMETER, floor)
    low, high = np.log(PORE_DIAMETERS)
    # E[max(d, floor)^2] of d log-uniform on PORE_DIAMETERS
    cut = np.clip(np.log(np.maximum(floor, 1e-12)), low, high)
    pore_square = (floor ** 2 * (cut - low) + (np.exp(2 * high) - np.exp(2 * cut)) / 2) / (high - low)
    covers = lambda square: 2 * np.pi * (square / FWHM_SIGMAS ** 2 + splat.DILATION_PX2 * px ** 2)  # noqa: E731
    count = np.where(granular, np.ceil(np.pi * (GRAIN_REACH * radius) ** 2 / covers(grain ** 2)),
                     np.where(porous, np.ceil(PORE_SHARE * (4 / 3 * np.pi * radius ** 3) ** (2 / 3)
                                              / covers(pore_square)), 0))
    count = np.minimum(count, FINE_PER_PARTICLE).astype(np.int64)
    owner = np.repeat(np.arange(P), count)
    M = len(owner)
    angle, reach = rng.uniform(0, 2 * np.pi, M), np.sqrt(rng.uniform(0, 1, M))
    reach *= np.where(granular[owner], GRAIN_REACH, 1.0)
    place = reach[:, None] * np.stack([np.cos(angle), np.sin(angle)], 1)
    pore = np.maximum(np.exp(rng.uniform(low, high, M)), floor[owner])
    diameter = np.where(granular[owner], grain[owner], pore)
    spread = GRAIN_SHADE * np.minimum(1, GRAIN_DIAMETER / px[owner]) ** GRAIN_SHADE_FALLOFF / FINE_BLUR
    shade = 1 + spread * np.clip(rng.standard_normal(M), -2, 2)
    factor = np.where(granular[owner, None], shade[:, None],
                      pore_shades(colours[owner], rng.uniform(*PORE_OPENINGS, M)))
    return FineStructure(owner, place, diameter / FWHM_SIGMAS, factor)


def fine_features(means: torch.Tensor, covariances: torch.Tensor, colours: torch.Tensor, weight: torch.Tensor,
                  fine: FineStructure, front: torch.Tensor, camera: splat.Camera) -> tuple[torch.Tensor, ...]:
    """The grains and pores (fine_structure, its fields as tensors) of the particles whose ``weight`` (P,) in
    [0, 1] is at least 1/255 (how far their material flows, where the frame shows them), drawn on the surface
    the frame shows: (C, 3) means (m), (C, 3, 3) covariances (m^2), (C,) opacities (the weight) and (C, 3)
    colours.

    Of each particle (means (P, 3), covariances (P, 3, 3), colours (P, 3) in [0, 1], as drawn this frame), a
    grain or pore lies at its ``place`` in the particle's alpha-1/2 ellipse as the camera's axes see it, across
    the particle's ray. Where the particles cover that pixel (``front`` (H, W), the camera depth z, m, of what
    their render shows there, alpha-weighted; NaN where their alpha is at most 1/2), it is texture of the
    surface there: drawn only if its particle lies within its own reach along the view of that depth, and moved
    along its ray to a twentieth of that reach in front of it, so that neither its own particle nor a
    neighbour at the surface covers it (splat sorts by camera depth); elsewhere (a grain spilled past a heap's
    edge) it stays at its particle's depth. Its colour is the particle's times its factor, no channel past 1
    (a brighter grain keeps its hue)."""
    drawn = torch.nonzero(weight[fine.owner] >= 1 / 255)[:, 0]
    owner = fine.owner[drawn]
    grain = covariances[owner]
    world_to_camera = torch.as_tensor(camera.world_to_camera, dtype=means.dtype, device=means.device)
    axes = world_to_camera[:2, :3]  # the picture's right and down, world frame
    centre = to_camera(means[owner], world_to_camera)
    view = centre / centre.norm(dim=1, keepdim=True).clamp_min(1e-12)  # camera frame
    across = axes @ grain @ axes.T  # (C, 2, 2) the particle's picture, m^2
    a, b, c = across[:, 0, 0].clamp_min(0).sqrt(), across[:, 1, 0], across[:, 1, 1]
    lower = torch.where(a > 0, b / a.clamp_min(1e-30), 0.0)
    root = torch.stack([torch.stack([a, torch.zeros_like(a)], 1),
                        torch.stack([lower, (c - lower ** 2).clamp_min(0).sqrt()], 1)], 1)
    place = fine.place[drawn].to(means.dtype)
    offset = torch.nn.functional.pad(GRAIN_EDGE_SIGMAS * (root @ place[:, :, None])[..., 0], (0, 1))
    point = centre + offset - (offset * view).sum(1, keepdim=True) * view
    reach_view = GRAIN_EDGE_SIGMAS * torch.einsum("pi,pij,pj->p", view @ world_to_camera[:3, :3], grain,
                                                  view @ world_to_camera[:3, :3]).clamp_min(0).sqrt()
    uv = project_points(point, torch.as_tensor(camera.K, dtype=means.dtype, device=means.device))
    col, row = uv[:, 0].floor().long(), uv[:, 1].floor().long()
    inside = (col >= 0) & (col < camera.width) & (row >= 0) & (row < camera.height)
    surface = torch.where(inside, front[row.clamp(0, camera.height - 1), col.clamp(0, camera.width - 1)].to(
        means.dtype), torch.nan)
    covered = surface.isfinite()
    kept = ~covered | (centre[:, 2] - surface <= reach_view)
    depth = torch.where(covered, surface, centre[:, 2]) - 0.05 * reach_view
    point = point * (depth / point[:, 2].clamp_min(1e-12))[:, None]
    R, t = world_to_camera[:3, :3], world_to_camera[:3, 3]
    sigma, factor = fine.sigma[drawn].to(grain.dtype), fine.factor[drawn].to(colours.dtype)
    colour = colours[owner] * factor
    return (((point - t) @ R)[kept], (sigma[:, None, None] ** 2 * torch.eye(3, dtype=grain.dtype,
                                                                          device=grain.device))[kept],
            (weight[owner] * INTERIOR_OPACITY)[kept], (colour / colour.amax(1, keepdim=True).clamp_min(1))[kept])


def undilated(means: torch.Tensor, covariances: torch.Tensor, hard: torch.Tensor, camera: splat.Camera) -> torch.Tensor:
    """(P, 3, 3) m^2: the covariances (P, 3, 3) of the particles at means (P, 3), world, m, with splat's
    dilation (splat.DILATION_PX2 added to every projected covariance) taken back out of the hard grains, by
    their weight ``hard`` (P,) in [0, 1] (how far their material flows): splat.DILATION_PX2 (z / f)^2 off
    every axis, at most 3/4 of the smallest.

    The dilation is an antialiasing filter for soft Gaussians. It grows a hard grain's picture, whose edge
    is at alpha 1/2, by about 0.3 px / its radius in px: a grain 1.2 px across is drawn 2 px across, and at
    2 px a lattice spacing the pieces of a torn ball are joined across a gap of a pixel."""
    weight = torch.nonzero(hard > 0)[:, 0]
    if len(weight) == 0:
        return covariances
    z = to_camera(means[weight], camera.world_to_camera)[:, 2].clamp_min(1e-9)
    dilation = splat.DILATION_PX2 * (z / float(camera.K[0, 0])) ** 2
    grains = covariances[weight]
    smallest = torch.linalg.eigvalsh(grains)[:, 0].clamp_min(0)
    taken = hard[weight].to(grains.dtype) * torch.minimum(dilation.to(grains.dtype), 0.75 * smallest)
    eye = torch.eye(3, dtype=grains.dtype, device=grains.device)
    out = covariances.clone()
    out[weight] = grains - taken[:, None, None] * eye
    return out


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


def transmittance_layers(means: torch.Tensor, covariances: torch.Tensor, opacities: torch.Tensor,
                         depths: torch.Tensor, camera: splat.Camera) -> torch.Tensor:
    """(L, H, W) the transmittance of these Gaussians in front of each camera depth ``depths`` (L,), m.

    splat composites each pixel front to back in order of the Gaussians' camera depth, so the
    blending weights of the Gaussians nearer than a depth z sum to 1 - T(z): one render whose
    channel l is 1 for the Gaussians nearer than depths[l] gives all L at once (LAYERS_PER_RENDER
    channels a render). Forward renders only: the same bytes on every run and thread count.
    """
    z = to_camera(means, camera.world_to_camera)[:, 2]
    layers = []
    for group in depths.split(LAYERS_PER_RENDER):
        nearer = (z[:, None] < group[None, :].to(z.dtype)).to(opacities.dtype)
        nearer = torch.nn.functional.pad(nearer, (0, LAYERS_PER_RENDER - len(group)))  # one kernel for all
        covered = splat.rasterize(means, opacities, nearer, camera, covariances=covariances).features
        layers.append((1 - covered[..., :len(group)]).clamp(0, 1).permute(2, 0, 1))
    return torch.cat(layers)


def exposure(positions: torch.Tensor, sigma: torch.Tensor, means: torch.Tensor, covariances: torch.Tensor,
             opacities: torch.Tensor, layer_depth: float, camera: splat.Camera) -> torch.Tensor:
    """(N,) for each particle at positions (N, 3) (world, m), rendered round of standard deviation
    sigma (N,), m, with opacity INTERIOR_OPACITY: the mean over its footprint, weighted by its own
    alpha, of the transmittance in front of it of the other Gaussians (means, covariances,
    opacities; those at positions among them). That is what it adds to the render over what it
    would add alone. It is read at the nearest depth layer (of ``layer_depth`` m) in front of the
    particle, so what lies within a layer in front of it is not counted: an upper bound."""
    device, N = positions.device, len(positions)
    in_camera = to_camera(positions, camera.world_to_camera)
    z = in_camera[:, 2]
    nearest = float(z.min())
    layer = ((z - nearest) / layer_depth).floor().long()
    depths = nearest + layer_depth * torch.arange(int(layer.max()) + 1, device=device, dtype=z.dtype)
    transmittance = transmittance_layers(means, covariances, opacities, depths, camera)
    K = torch.as_tensor(camera.K, dtype=positions.dtype, device=device)
    uv = project_points(in_camera, K)
    sigma_px2 = (sigma * K[0, 0] / z.clamp_min(1e-9)) ** 2 + splat.DILATION_PX2
    half = int(math.ceil(float(REACH_SIGMAS * sigma_px2.max().sqrt()))) + 1
    steps = torch.arange(-half, half + 1, device=device)
    offsets = torch.stack(torch.meshgrid(steps, steps, indexing="xy"), -1).reshape(-1, 2)
    size = torch.tensor([camera.width, camera.height], device=device)
    exposed = torch.zeros(N, dtype=transmittance.dtype, device=device)
    for chunk in torch.arange(N, device=device).split(4096):
        pixel = uv[chunk].floor().long()[:, None] + offsets[None]  # (n, k, 2) col, row
        from_centre = pixel.to(uv.dtype) + 0.5 - uv[chunk, None]
        alpha = (min(INTERIOR_OPACITY, 0.99) * torch.exp(-0.5 * (from_centre ** 2).sum(-1) / sigma_px2[chunk, None]))
        alpha = torch.where(alpha >= 1 / 255, alpha, 0.0).to(transmittance.dtype)
        col, row = pixel[..., 0].clamp(0, camera.width - 1), pixel[..., 1].clamp(0, camera.height - 1)
        # off the image nothing hides it
        seen = torch.where(((pixel >= 0) & (pixel < size)).all(-1), transmittance[layer[chunk, None], row, col], 1.0)
        exposed[chunk] = (alpha * seen).sum(1) / alpha.sum(1).clamp_min(1e-12)
    return exposed


def hidden_at_rest(rest_positions: torch.Tensor, sigma: torch.Tensor, spacing: torch.Tensor,
                   surface_means: torch.Tensor, surface_covariances: torch.Tensor, surface_opacities: torch.Tensor,
                   camera: splat.Camera) -> tuple[torch.Tensor, torch.Tensor]:
    """(N,) each fill particle's standard deviation (m) narrowed so that it stays hidden behind the
    surface at rest, and (N,) bool whether it does (those that do not are transparent at rest).

    First each particle is narrowed so that its footprint, out to REACH_SIGMAS of its projected
    standard deviation (with splat's dilation), stays on pixels where the surface's rest alpha is at
    least OPAQUE_ALPHA (0 where its centre is off them). Then, rendered together with the surface at
    rest, any particle that still shows (its exposure, the transmittance in front of it over its
    footprint, above HIDDEN_TRANSMITTANCE: where the surface is translucent, or its Gaussians lie
    behind the particle) is taken out, and again for what that uncovers, up to HIDING_ROUNDS times.
    Forward renders only (:func:`exposure`): the same bytes on every run and thread count.

    Args:
        rest_positions: (N, 3) world, m; sigma: (N,) their standard deviation from the lattice, m;
            spacing: (N,) their lattice's spacing, m (the exposure's depth layers: half the finest).
        surface_means, surface_covariances, surface_opacities: the G surface Gaussians at rest.
    """
    device = rest_positions.device
    with torch.no_grad():
        surface = splat.rasterize(surface_means, surface_opacities, torch.zeros_like(surface_means[:, :1]), camera,
                                  covariances=surface_covariances)
        K = torch.as_tensor(camera.K, dtype=rest_positions.dtype, device=device)
        in_camera = to_camera(rest_positions, camera.world_to_camera)
        uv = project_points(in_camera, K)
        opaque = (surface.alpha >= OPAQUE_ALPHA).cpu().numpy().astype(np.uint8)
        # px from each opaque pixel's centre to the nearest pixel that is not (0 on those)
        room = torch.as_tensor(cv2.distanceTransform(opaque, cv2.DIST_L2, cv2.DIST_MASK_PRECISE), device=device)
        col = uv[:, 0].floor().long()
        row = uv[:, 1].floor().long()
        inside = (col >= 0) & (col < camera.width) & (row >= 0) & (row < camera.height) & (in_camera[:, 2] > 0)
        col, row = col.clamp(0, camera.width - 1), row.clamp(0, camera.height - 1)
        room_px = torch.where(inside, room[row, col] - 0.5, 0.0)  # from the particle's pixel's edge
        behind = in_camera.norm(dim=1) > surface.depth[row, col] / surface.alpha[row, col].clamp_min(OPAQUE_ALPHA)
        px_per_m = K[0, 0] / in_camera[:, 2].clamp_min(1e-9)
        fits_px2 = (room_px.clamp_min(0) / REACH_SIGMAS) ** 2 - splat.DILATION_PX2
        hidden = inside & behind & (fits_px2 > 0)
        sigma = torch.where(hidden, torch.minimum(sigma, fits_px2.clamp_min(0).sqrt() / px_per_m), 0.0)
        eye = torch.eye(3, dtype=surface_covariances.dtype, device=device)
        layer_depth = 0.5 * float(spacing.min()) if len(spacing) else 1.0
        for _ in range(HIDING_ROUNDS):
            kept = torch.nonzero(hidden)[:, 0]
            if len(kept) == 0:
                break
            exposed = exposure(
                rest_positions[kept], sigma[kept],
                torch.cat([surface_means, rest_positions[kept].to(surface_means.dtype)]),
                torch.cat([surface_covariances, sigma[kept].to(eye.dtype)[:, None, None] ** 2 * eye]),
                torch.cat([surface_opacities, torch.full((len(kept),), INTERIOR_OPACITY, dtype=surface_opacities.dtype,
                                                         device=device)]), layer_depth, camera)
            showing = kept[exposed > HIDDEN_TRANSMITTANCE]
            if len(showing) == 0:
                break
            hidden[showing] = False
    return torch.where(hidden, sigma, 0.0), hidden
