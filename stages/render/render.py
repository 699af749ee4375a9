"""Coarse frames: the simulated particles through splat, from the input camera (paper Sec. 3.2).

Every particle is rendered: the G surface Gaussians as reconstructed, and the
fill particles behind them as Gaussians of the interior's material
(interior.py). Particle k at frame t sits at x_k(t) with covariance
F_k H_k F_k^T (H_k its rest covariance, F_k its deformation gradient from the
simulation). Beside the colour we render, in a second pass voted by what the
frame itself shows, each particle's affine map back into the photograph at rest,
its surface normal now, its visibility at rest (source_map.py; 0 for the
interior, which the photograph never saw) and whether it is surface or interior.
Their blend gives ``source_uv`` (where each pixel's surface was in the
photograph; for a surface the photograph never saw, the point of the photograph
in front of it, whose colour the reconstruction gave it), ``source_coherence``
(how smoothly the photograph maps onto the frame there, how well the surface in
front agrees on where each pixel came from, and how much of it is surface
rather than interior), ``source_confidence`` (how visible the surface was at
rest, times the coherence) and ``normal``: the flow enhancement reads the
photograph through them and re-shades it.
"""
from __future__ import annotations

import logging
from typing import NamedTuple

import numpy as np
import torch

import splat
from schemas.artifacts import CoarseArtifact, GaussiansArtifact, TrajectoriesArtifact
from schemas.camera import project_points
from schemas.materials import PRESETS
from schemas.video import even_size

from .interior import (ELASTIC, GRAIN_SIGMA, GRANULAR, INTERIOR_OPACITY, POROUS, FineStructure, Mixing,
                       crumb_colours, fine_features, fine_structure, fitted_photograph, grain_offsets, grain_shapes,
                       hidden_at_rest, lattice_spacing, rest_ray_colours, surface_under, undilated)
from .silhouette import STILL_PX, TURN_TOWARDS, narrowed_to_mask
from .source_map import (AFFINE_CHANNELS, MIN_ALPHA, MIN_VOTE, MOMENT_CHANNELS, affine_source_maps, coherence,
                         facing_normals, full_camera, inverse_deformation, map_moments, rest_visibility,
                         source_points, source_roughness, source_spread, surface_normals, to_camera, visibility)

log = logging.getLogger("physmotion.render")


def render_camera(gaussians: GaussiansArtifact, width: int) -> splat.Camera:
    """The input camera at ``width`` pixels (capped at the photograph's, rounded to even sizes for H.264)."""
    w, h = even_size(min(width, gaussians.width), round(gaussians.height * min(width, gaussians.width) / gaussians.width))
    K = gaussians.K.copy()
    K[:2] *= w / gaussians.width
    return splat.Camera(torch.as_tensor(K), torch.as_tensor(gaussians.world_to_camera), w, h)


class Particles(NamedTuple):
    """Every particle of the trajectories as rendered: the G Gaussians, then the fill particles
    (interior.py). Tensors (P, ...) on the render device.

    rest_means (P, 3), m; rest_covariances (P, 3, 3), m^2; grain_offsets (P, 3), m, where a grain is
    drawn from its particle (interior.grain_offsets); grain_covariances (P, 3, 3), m^2,
    grain_opacities (P,) and grain_colors (P, 3), the shape, opacity and colour a particle takes as
    its material flows (interior.Mixing): a hard grain of the lattice's size, in the photograph's colour on
    its rest ray, a porous solid's interior in its crumb's (interior.grain_shapes; its rest covariance, opacity
    and colour where its object has no lattice); opacities (P,); opaque_at_rest (P,) 0 for a fill particle that
    would show at rest (interior.hidden_at_rest), which is transparent until its material flows, else 1; colors
    (P, 3) at rest (a fill particle: the surface's in front of it at rest, interior.fitted_photograph, or a
    porous solid's crumb, interior.crumb_colours); rest_seen (P,) visibility in the photograph
    (source_map.rest_visibility; 0 for the interior); rest_normals (P, 3) world frame (the interior
    takes the normal of the surface it lies under); surface (P,) 1 for a Gaussian, 0 for the interior;
    grains (P,) 1 for a particle of an object with a lattice, a hard grain once its material flows
    (interior.undilated), else 0; fine the grains of sand or snow and the pores of a porous solid drawn on
    the particles of an object with a lattice once their material flows (interior.fine_structure, its fields
    as tensors); narrowing (P,) and fading (P,) the factors on a Gaussian's size and opacity that keep it
    within a pixel of its object's mask once it moves (silhouette.narrowed_to_mask; 1 for the interior);
    rest_pixels (P, 2) where each particle stands in the frames at rest (output pixels); rest_facing (P,) in
    [0, 1] how squarely each particle faces the camera at rest (facing_towards): a Gaussian turned further
    towards it than that (silhouette.TURN_TOWARDS) is narrowed less; camera the frames'.
    """

    rest_means: torch.Tensor
    rest_covariances: torch.Tensor
    grain_offsets: torch.Tensor
    grain_covariances: torch.Tensor
    mixing: Mixing
    opacities: torch.Tensor
    grain_opacities: torch.Tensor
    opaque_at_rest: torch.Tensor
    colors: torch.Tensor
    grain_colors: torch.Tensor
    rest_seen: torch.Tensor
    rest_normals: torch.Tensor
    surface: torch.Tensor
    grains: torch.Tensor
    fine: FineStructure
    narrowing: torch.Tensor
    fading: torch.Tensor
    rest_pixels: torch.Tensor
    rest_facing: torch.Tensor
    camera: splat.Camera

    def at(self, F: torch.Tensor, positions: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """(P, 3) drawn positions (m), (P, 3, 3) covariances, (P,) opacities, (P, 3) colours and (P,)
        surface weights of a frame whose particles are at ``positions`` (P, 3) with deformation
        gradients ``F`` (P, 3, 3); call once per frame, in order (Mixing keeps its past). A Gaussian that
        reaches past its object's mask is narrowed to it (narrowing, fading) by 1 - exp(-(m / STILL_PX)^2),
        m how far (px) its picture has moved from where it stood at rest: at rest pm-enhance shows the
        photograph beside the object, and a Gaussian standing as in the photograph draws its silhouette's
        pixels as it was fitted to them. The surface weight is 1 for a Gaussian that
        is still a patch of the photographed surface, falling to 0 as it turns into a grain of
        flowing material (whose colour then stands for the material, not for its place in the
        photograph), and 0 for the interior."""
        mixed = self.mixing(positions, F)
        # narrowed to the mask as far as it has moved from where it stood in the photograph, while it still
        # faces the camera as it did there (turned towards it, its reach past the mask lies over the body)
        K = torch.as_tensor(self.camera.K, dtype=positions.dtype, device=positions.device)
        ray = to_camera(positions, self.camera.world_to_camera)
        moved_px = (project_points(ray, K) - self.rest_pixels).norm(dim=1)
        facing = facing_towards(self.rest_normals, positions, self.camera, inverse_deformation(F), ray)
        turned = (facing - self.rest_facing).clamp_min(0)
        moved = ((1 - torch.exp(-(moved_px / STILL_PX) ** 2)) * torch.exp(-(turned / TURN_TOWARDS) ** 2)).to(
            self.narrowing.dtype)
        size = 1 - moved * (1 - self.narrowing)
        rest = size[:, None, None] ** 2 * self.rest_covariances
        shape = (1 - mixed[:, None, None]) * rest + mixed[:, None, None] * self.grain_covariances
        colors = ((1 - mixed[:, None]) * self.colors + mixed[:, None] * self.grain_colors).clamp(0, 1)
        fading = 1 - moved * (1 - self.fading)
        opacities = (1 - mixed) * self.opacities * fading * self.opaque_at_rest + mixed * self.grain_opacities
        drawn = positions + mixed[:, None] * self.grain_offsets.to(positions.dtype)
        return drawn, F @ shape @ F.transpose(1, 2), opacities, colors, self.surface * (1 - mixed)


def facing_towards(normals: torch.Tensor, means: torch.Tensor, camera: splat.Camera,
                   F_inverse: torch.Tensor | None = None, ray: torch.Tensor | None = None) -> torch.Tensor:
    """(P,) in [0, 1]: how squarely each particle's surface (rest normals (P, 3), world frame, carried by the
    deformation, F^-T n, at means (P, 3), m) faces the camera, |n . d| with d the unit ray to it: 0 edge-on,
    at the silhouette; 1 facing it.

    Args:
        F_inverse: (P, 3, 3) source_map.inverse_deformation of each particle's F; None at rest (the identity).
        ray: (P, 3) the means in the camera frame (m), where the caller has them already.
    """
    if F_inverse is None:
        F_inverse = torch.eye(3, dtype=means.dtype, device=means.device).expand(len(means), 3, 3)
    if ray is None:
        ray = to_camera(means, camera.world_to_camera)
    facing = facing_normals(normals, means, F_inverse, camera.world_to_camera)
    return (-(facing * ray).sum(1) / ray.norm(dim=1).clamp_min(1e-12)).clamp(0, 1)


def rendered_particles(gaussians: GaussiansArtifact, trajectories: TrajectoriesArtifact, camera: splat.Camera,
                       device: str) -> Particles:
    """The Gaussians and the interior of the trajectories, as rendered (see Particles)."""
    t = lambda a: torch.as_tensor(a, device=device)  # noqa: E731
    G = gaussians.means.shape[0]
    means, opacities, colors = t(gaussians.means), t(gaussians.opacities), t(gaussians.colors)
    covariances = splat.covariances_from_scales_rotations(t(gaussians.scales), t(gaussians.rotations))
    # the photograph's objects end at their mask: what a Gaussian draws past it is the background's
    narrowing, fading = narrowed_to_mask(means, covariances, gaussians.object_id, gaussians.mask,
                                         full_camera(gaussians))
    rest_seen = rest_visibility(means, covariances, opacities, gaussians)
    normals = surface_normals(means)
    fill = ~trajectories.is_gaussian
    under = t(surface_under(trajectories.rest_positions[fill], trajectories.object_id[fill], gaussians.means,
                            gaussians.object_id, gaussians.opacities))
    fill_means = t(trajectories.rest_positions[fill]).to(means.dtype)
    spacing = t(lattice_spacing(trajectories.lattice_spacing, trajectories.is_gaussian,
                                trajectories.object_id)).to(means.dtype)
    sigma, hidden = hidden_at_rest(fill_means, GRAIN_SIGMA * spacing[G:], spacing[G:], means, covariances, opacities,
                                   camera)
    N = len(sigma)
    granular = np.isin(trajectories.material_id, [PRESETS.index(p) for p in GRANULAR])
    porous = np.isin(trajectories.material_id, [PRESETS.index(p) for p in POROUS])
    elastic = np.isin(trajectories.material_id, [PRESETS.index(p) for p in ELASTIC])
    on_rest_ray = t(rest_ray_colours(trajectories.rest_positions.astype(np.float64), trajectories.object_id,
                                     gaussians.photo, gaussians.mask, gaussians.K,
                                     gaussians.world_to_camera)).to(colors.dtype)
    # broken porous material (fracture, foam) shows its crumb; any other interior the colour of the surface in
    # front of it, as the fit draws it: the photograph on its ray may hold a highlight's single pixel, which the
    # fit averages away
    crumb = t(crumb_colours(trajectories.object_id[fill], gaussians.photo, gaussians.mask)).to(colors.dtype)
    fitted = fitted_photograph(means, covariances, opacities, colors, full_camera(gaussians))
    in_front = t(rest_ray_colours(trajectories.rest_positions[fill].astype(np.float64), trajectories.object_id[fill],
                                  fitted, gaussians.mask, gaussians.K, gaussians.world_to_camera)).to(colors.dtype)
    fill_colors = torch.where(t(porous[G:])[:, None], crumb, in_front)
    log.info("%d Gaussians and %d interior particles, %d of them transparent until their material flows "
             "(they would show at rest, at the rim or behind translucent surface)", G, N, N - int(hidden.sum()))
    eye = torch.eye(3, dtype=covariances.dtype, device=device)
    rest_covariances = torch.cat([covariances, sigma[:, None, None] ** 2 * eye])
    opacities = torch.cat([opacities, torch.full((N,), INTERIOR_OPACITY, dtype=opacities.dtype, device=device)])
    grain_shape, grain_opacities = grain_shapes(spacing.cpu().numpy(), granular)
    has_lattice = spacing.isfinite()
    rest_colors = torch.cat([colors, fill_colors])
    # a grain shows the material at its place: a surface Gaussian's own colour may hold the background it was
    # fitted beside (the silhouette's), the photograph 2 px inside its object's does not; a crumb is its object's
    grain_from = torch.where(t(porous & ~trajectories.is_gaussian)[:, None], rest_colors, on_rest_ray)
    rest_means = torch.cat([means, fill_means])
    lattice = has_lattice.cpu().numpy()
    fine = fine_structure(granular & lattice, porous & lattice, grain_shape,
                          to_camera(rest_means, camera.world_to_camera)[:, 2].cpu().numpy(), float(camera.K[0, 0]),
                          grain_from.cpu().numpy())
    return Particles(
        rest_means=rest_means, rest_covariances=rest_covariances,
        # a heap's grains lie anywhere in their cells; a torn solid's stay on its lattice, so that its pieces'
        # outlines stay where the material tore
        grain_offsets=torch.where(t(granular)[:, None], t(grain_offsets(spacing.cpu().numpy())), 0.0),
        grain_covariances=torch.where(has_lattice[:, None, None], t(grain_shape).to(covariances.dtype),
                                      rest_covariances),
        # an elastic solid never flows (inf: no lattice to flow past)
        mixing=Mixing(rest_means, trajectories.object_id, torch.where(t(elastic), torch.inf, spacing)),
        opacities=opacities,
        grain_opacities=torch.where(has_lattice, t(grain_opacities).to(opacities.dtype), opacities),
        opaque_at_rest=torch.cat([torch.ones(G, device=device), hidden.to(opacities.dtype)]),
        colors=rest_colors,
        grain_colors=grain_from,
        rest_seen=torch.cat([rest_seen, torch.zeros(N, dtype=rest_seen.dtype, device=device)]),
        rest_normals=torch.cat([normals, normals[under]]),
        surface=torch.cat([torch.ones(G, device=device), torch.zeros(N, device=device)]),
        grains=has_lattice.to(opacities.dtype),
        fine=FineStructure(*(t(a) for a in fine)),
        narrowing=torch.cat([narrowing, torch.ones(N, dtype=narrowing.dtype, device=device)]),
        fading=torch.cat([fading, torch.ones(N, dtype=fading.dtype, device=device)]),
        rest_pixels=project_points(to_camera(rest_means, camera.world_to_camera),
                                   torch.as_tensor(camera.K, dtype=rest_means.dtype, device=device)),
        rest_facing=facing_towards(torch.cat([normals, normals[under]]), rest_means, camera),
        camera=camera)


def render_video(gaussians: GaussiansArtifact, trajectories: TrajectoriesArtifact, width: int,
                 device: str) -> CoarseArtifact:
    """Render every frame of the trajectories; see the module docstring for the channels."""
    G = gaussians.means.shape[0]
    if int(trajectories.is_gaussian.sum()) != G or not trajectories.is_gaussian[:G].all():
        raise ValueError(f"trajectories hold {int(trajectories.is_gaussian.sum())} Gaussians, gaussians.h5 {G}")
    t = lambda a: torch.as_tensor(a, device=device)  # noqa: E731
    camera = render_camera(gaussians, width)
    scale = camera.width / gaussians.width  # photo pixels -> output pixels
    particles = rendered_particles(gaussians, trajectories, camera, device)
    rest_means, rest_seen, rest_normals = particles.rest_means, particles.rest_seen, particles.rest_normals
    log.info("%.0f%% of the Gaussians visible in the photograph; rendering %d frames at %dx%d",
             100 * float((rest_seen[:G] > 0.5).float().mean()), trajectories.positions.shape[0],
             camera.width, camera.height)

    T = trajectories.positions.shape[0]
    out = {k: [] for k in ("rgb", "alpha", "depth", "source_uv", "source_coherence", "source_confidence", "normal")}
    with torch.no_grad():
        for frame in range(T):
            F, means = t(trajectories.F[frame]), t(trajectories.positions[frame])
            means, covariances, opacities, colors, surface_weights = particles.at(F, means)
            covariances = undilated(means, covariances, particles.grains * particles.mixing.so_far, camera)
            features = torch.cat([colors, surface_weights[:, None].to(colors.dtype)], 1)
            camera_z = to_camera(means, camera.world_to_camera)[:, 2:].to(colors.dtype)
            bodies = splat.rasterize(means, opacities, torch.cat([features, camera_z], 1), camera,
                                     covariances=covariances)
            # Only the surface in front decides a pixel's source: what leaks through it from behind
            # (the far side, which maps to elsewhere in the photograph) would scatter the map.
            seen_now = visibility(bodies, means, covariances, camera)[:, None]
            # the colour pass draws the grains of sand and snow and the pores of crumb on the flowing particles
            # on the surface the frame shows (those further behind it lie under the grains in front)
            showing = particles.mixing.so_far * (seen_now[:, 0] > 0.5).to(opacities.dtype)
            front = torch.where(bodies.alpha > 0.5, bodies.features[..., 4] / bodies.alpha.clamp_min(0.5), torch.nan)
            fine_means, fine_covariances, fine_opacities, fine_colors = fine_features(
                means, covariances, colors, showing, particles.fine, front, camera)
            render = bodies if len(fine_means) == 0 else splat.rasterize(
                torch.cat([means, fine_means]), torch.cat([opacities, fine_opacities]),
                torch.cat([features, torch.nn.functional.pad(fine_colors, (0, 1))]), camera,
                covariances=torch.cat([covariances, fine_covariances]))
            alpha = render.alpha
            # (the particles' own render carries their camera depth in a fifth channel)
            rgb, surface_weight = render.features[..., :4].split([3, 1], -1)
            covered = alpha >= MIN_ALPHA
            votes = seen_now.clamp_min(MIN_VOTE)
            F_inverse = inverse_deformation(F)
            normals = facing_normals(rest_normals, means, F_inverse, gaussians.world_to_camera)
            maps = affine_source_maps(rest_means, means, normals, F_inverse, gaussians, camera.K)
            moments = map_moments(maps).to(votes.dtype)
            maps = maps.to(votes.dtype)
            # The spread of sources is taken over the surface in front alone (unfloored votes): a
            # per cent of the far side, leaking through from a source across the object, would
            # otherwise read as disagreement.
            voting = torch.cat([votes * torch.cat([maps, normals, rest_seen[:, None], torch.ones_like(votes)], 1),
                                seen_now * torch.cat([maps, moments, torch.ones_like(votes)], 1)], 1)
            channels = splat.rasterize(means, opacities, voting, camera, covariances=covariances).features
            voted_maps, normal, seen, voted, front_maps, front_moments, front_votes = channels.split(
                [AFFINE_CHANNELS, 3, 1, 1, AFFINE_CHANNELS, MOMENT_CHANNELS, 1], -1)
            voted = voted[..., 0].clamp_min(MIN_ALPHA)
            source_uv = torch.where(covered[..., None], source_points(voted_maps, voted), torch.nan)
            normal = normal / normal.norm(dim=-1, keepdim=True).clamp_min(1e-12)
            seen_fraction = (seen[..., 0] / voted).clamp(0, 1)
            front_votes = front_votes[..., 0]
            spread = source_spread(front_moments, front_votes, source_points(front_maps, front_votes))
            # how much of what the pixel shows is surface, by the colour pass's own blending weights;
            # where nothing is covered there is no interior in front either
            surface_share = torch.where(covered, (surface_weight[..., 0] / alpha.clamp_min(MIN_ALPHA)).clamp(0, 1), 1.0)
            smooth = torch.where(covered, coherence(source_roughness(source_uv) * scale, spread * scale,
                                                    surface_share), 0.0)
            out["rgb"].append((rgb.clamp(0, 1) * 255 + 0.5).to(torch.uint8))
            out["alpha"].append(alpha)
            out["depth"].append(render.depth)
            out["source_uv"].append(source_uv)
            out["source_coherence"].append(smooth)
            out["source_confidence"].append(torch.where(covered, seen_fraction * smooth, 0.0))
            out["normal"].append(torch.where(covered[..., None], normal, torch.nan))
            surface = alpha > 0.5
            share = lambda x: 100 * float(x[surface].gt(0.5).float().mean()) if surface.any() else 0.0  # noqa: E731
            log.info("frame %d/%d rendered; of the surface %.0f%% maps smoothly from the photograph, %.0f%% was "
                     "seen in it", frame + 1, T, share(smooth), share(seen_fraction))
    arrays = {k: torch.stack(v).cpu().numpy() for k, v in out.items()}
    return CoarseArtifact(**arrays, K=camera.K, width=camera.width,
                          height=camera.height, fps=float(trajectories.fps))
