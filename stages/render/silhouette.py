"""The objects end at their silhouette: the Gaussians that reach past it are narrowed to it.

A reconstruction fits the photograph's silhouette pixels, which mix the object with its background, with
Gaussians whose footprints reach a few pixels past the objects' mask: on the clay example the surface's
render has alpha above 1/2 up to 4 px beyond it, the tails of the Gaussians along the silhouette stacked.
At rest pm-enhance shows the photograph there, but once the object moves that fringe moves with it: a soft
band in the colour the source map reads beyond the mask. :func:`narrowed_to_mask` finds how far to shrink
each Gaussian that reaches past its object's mask, at rest in the photograph's view, so that it reaches no
further than SILHOUETTE_TOLERANCE_PX past it (its alpha there a tenth of its opacity at most; splat's own
dilation of 0.3 px^2 comes on top). The render narrows a Gaussian as it moves (render.Particles.at): at
rest it draws the silhouette's pixels it was fitted to, and the coarse frame 0 stays the reconstruction's.
"""
from __future__ import annotations

import math

import numpy as np
import torch
from scipy import ndimage

import splat
from schemas.camera import project_points

from .source_map import to_camera

SILHOUETTE_TOLERANCE_PX = 1.0
"""Pixels past the mask (photograph's resolution) to which a Gaussian may reach: the silhouette's own pixels
are split between the object and its background."""
TENTH_SIGMAS = math.sqrt(2 * math.log(10))
"""Standard deviations out from a Gaussian's centre at which its alpha falls to a tenth of its opacity (2.1):
how far it may reach past the mask (interior.REACH_SIGMAS is the reach to splat's cut-off, alpha 1/255)."""
MAX_WINDOW_PX = 16
"""Half the side of the largest window of pixels read around a Gaussian's centre (px)."""
STILL_PX = 0.5
"""How far (output px) a Gaussian's picture moves from where it stood at rest over which it is narrowed:
1 - exp(-(m / STILL_PX)^2), as pm-enhance judges a pixel to stand still (compositing.standing_still): the twin
of stages/enhance/compositing.py's STILL_PX, kept equal to it (a stage imports no other)."""
TURN_TOWARDS = 0.25
"""How much more squarely than at rest (|n . d|, n its surface normal, d the ray to it) a moved Gaussian may
face the camera and still be narrowed (render.Particles.at: by exp(-(excess / TURN_TOWARDS)^2)). Turned
towards the camera a silhouette Gaussian lies over the body: turned by theta about an axis in the picture,
a body R px in radius brings its silhouette R (1 - cos theta) inwards, over a 3 px fringe at R = 50 px from
theta = 20 degrees on (|n . d| = sin theta = 0.34)."""
BISECTIONS = 12
"""Halvings of the interval of a Gaussian's size factor (to 1/4096)."""


def projected_covariances(means: torch.Tensor, covariances: torch.Tensor, camera: splat.Camera) -> torch.Tensor:
    """(G, 2, 2) px^2: each Gaussian's (means (G, 3), world, m; covariances (G, 3, 3), m^2) own covariance in
    the picture, J R C R^T J^T, J the pinhole's derivative at its centre (without splat's dilation).

    splat.project's EWA projection is not reused: it returns only the dilated covariance's inverse (its
    conic), in float32, where narrowed_to_mask scales the covariance itself before it adds the dilation; and
    its FOV_CLAMP changes only Gaussians centred outside the picture, which narrowed_to_mask leaves as they
    are."""
    R = torch.as_tensor(np.asarray(camera.world_to_camera)[:3, :3], dtype=means.dtype, device=means.device)
    x = to_camera(means, camera.world_to_camera)
    z = x[:, 2].clamp_min(1e-9)
    fx, fy = float(camera.K[0, 0]), float(camera.K[1, 1])
    J = torch.zeros((len(means), 2, 3), dtype=means.dtype, device=means.device)
    J[:, 0, 0], J[:, 0, 2] = fx / z, -fx * x[:, 0] / z ** 2
    J[:, 1, 1], J[:, 1, 2] = fy / z, -fy * x[:, 1] / z ** 2
    M = J @ R
    return M @ covariances @ M.transpose(1, 2)


def narrowed_to_mask(means: torch.Tensor, covariances: torch.Tensor, object_id: np.ndarray, labels: np.ndarray,
                     camera: splat.Camera) -> tuple[torch.Tensor, torch.Tensor]:
    """(G,) in [0, 1] the factor on each Gaussian's size (its covariance times its square), and (G,) in [0, 1]
    the factor on its opacity, that keep its alpha at most a tenth of its opacity (TENTH_SIGMAS) at every pixel
    centre more than SILHOUETTE_TOLERANCE_PX past its own object's mask (beyond it), at rest in the
    photograph's view, as splat draws it (its projected covariance f^2 S plus the dilation D).

    The size factor is the largest f with min over the pixels beyond of d^T (f^2 S + D)^-1 d at least
    TENTH_SIGMAS^2 (bisection; d from its centre). Where the dilation alone reaches further (a Gaussian within
    the tolerance past the mask, whose antialiased dot spills over), f is 0 and the opacity is scaled to a
    tenth there; one whose centre's pixel lies beyond is faded to 0 (tenths stacked along a limb, front and
    back, add up to its alpha). Pixels are read within MAX_WINDOW_PX of the centre. A Gaussian whose centre lies outside the
    picture, or of an object the mask does not show, is left as it is.

    Args:
        means (G, 3), m; covariances (G, 3, 3), m^2: world frame, at rest. object_id: (G,).
        labels: (H, W) 0 background, k + 1 object k (gaussians.h5's mask); camera: the photograph's.
    """
    device, dtype = means.device, means.dtype
    K = torch.as_tensor(np.asarray(camera.K), dtype=dtype, device=device)
    uv = project_points(to_camera(means, camera.world_to_camera), K)
    S = projected_covariances(means, covariances, camera)
    D = splat.DILATION_PX2 * torch.eye(2, dtype=dtype, device=device)
    H, W = labels.shape
    size = torch.ones(len(means), dtype=dtype, device=device)
    fade = torch.ones(len(means), dtype=dtype, device=device)
    for k in np.unique(object_id):
        own = labels == k + 1
        if not own.any():
            continue
        # a pixel centre more than the tolerance past the edge lies over tolerance + 1/2 from every centre on it
        beyond = torch.as_tensor(ndimage.distance_transform_edt(~own) > SILHOUETTE_TOLERANCE_PX + 0.5, device=device)
        members = torch.as_tensor(np.flatnonzero(object_id == k), device=device)
        for chunk in members.split(1024):
            widest = torch.linalg.eigvalsh(S[chunk] + D)[:, 1].clamp_min(0).sqrt()
            half = min(MAX_WINDOW_PX, int(math.ceil(TENTH_SIGMAS * float(widest.max()))) + 1)
            steps = torch.arange(-half, half + 1, device=device)
            offsets = torch.stack(torch.meshgrid(steps, steps, indexing="xy"), -1).reshape(-1, 2)
            pixel = uv[chunk].floor().long()[:, None] + offsets[None]  # (n, k, 2) col, row
            d = pixel.to(dtype) + 0.5 - uv[chunk, None]
            in_picture = ((pixel >= 0) & (pixel < torch.tensor([W, H], device=device))).all(-1)
            past = in_picture & beyond[pixel[..., 1].clamp(0, H - 1), pixel[..., 0].clamp(0, W - 1)]
            centre_in = in_picture[:, len(offsets) // 2]
            past &= centre_in[:, None]

            def nearest(f: torch.Tensor) -> torch.Tensor:
                inverse = torch.linalg.inv(f[:, None, None] ** 2 * S[chunk] + D)
                metric = torch.einsum("nki,nij,nkj->nk", d, inverse, d)
                return torch.where(past, metric, torch.inf).amin(1)

            low = torch.zeros(len(chunk), dtype=dtype, device=device)
            high = torch.ones(len(chunk), dtype=dtype, device=device)
            fits = nearest(high) >= TENTH_SIGMAS ** 2
            for _ in range(BISECTIONS):
                middle = (low + high) / 2
                ok = nearest(middle) >= TENTH_SIGMAS ** 2
                low, high = torch.where(ok, middle, low), torch.where(ok, high, middle)
            size[chunk] = torch.where(fits, 1.0, low)
            # alpha at the nearest pixel beyond of the dilation's dot alone, over the opacity
            spill = torch.exp(-0.5 * nearest(torch.zeros_like(low)))
            # one whose centre's own pixel lies beyond is none of the object: faded dots stack along a limb
            centre_beyond = past[:, len(offsets) // 2]
            fade[chunk] = torch.where(fits, 1.0, torch.where(centre_beyond, 0.0, (0.1 / spill).clamp(max=1.0)))
    return size, fade
