"""The geometry-aware optimisation through splat (paper section 3.3, appendix A.2.1).

Colour supervision (Eq. 10) on the input view only; the hard-depth loss
(Eq. 7-9) on the input view and every extra view, on positions only; the
paper's schedule scaled to ``iterations``: learning rates x0.1 halfway, hard
depth every 10 iterations after the first sixth (paper: 3000, 1500, 500).
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Optional

import numpy as np
import torch

import splat

from .lift import Gaussians
from .losses import color_loss, hard_depth_loss

log = logging.getLogger("physmotion.reconstruct")

LOSS_TERMS = ["total", "color", "silhouette", "hard_depth"]
SHOWN_PX = 0.5
"""A held Gaussian whose compositing weights in the input view sum to this many pixels fits its colour there;
one shown less keeps the colour it was lifted with."""


@dataclass
class Settings:
    """Optimisation settings; learning rates are per Adam step, in each parameter's own units."""

    iterations: int = 600
    lr_means: float = 1e-4        # metres
    lr_scales: float = 1e-3       # log metres
    lr_rotations: float = 1e-3    # quaternion components
    lr_opacities: float = 1e-3    # logits
    lr_colors: float = 1e-3       # sRGB in [0,1]
    dssim_weight: float = 0.2     # lambda of Eq. 10
    silhouette_weight: float = 0.1  # L1 between rendered alpha and the mask (the foreground's alpha)
    hard_depth: bool = True
    hard_depth_weight: float = 0.1
    hard_depth_every: int = 10
    delta: float = 0.95           # hard-depth opacity (Eq. 8)
    prune_opacity: float = 0.05   # Gaussians below this opacity are dropped at the end
    log_every: int = 50

    @property
    def decay_at(self) -> int:
        return self.iterations // 2

    @property
    def hard_depth_from(self) -> int:
        return self.iterations // 6


@dataclass
class View:
    """One supervised view at its optimisation resolution.

    target_rgb: (H,W,3) foreground over black, premultiplied by target_alpha; None for extra views
        (colour supervision is on the input view only).
    target_alpha: (H,W) object coverage in [0,1]; None for extra views.
    prior_depth: (H,W) metres along the ray (any scale and offset: the loss is patch-normalised).
    valid: (H,W) bool, where the hard-depth loss compares.
    crop: (rows, cols) slices around the object where the colour loss is evaluated (the rest is black in
        both images, and the silhouette term covers it).
    """

    camera: splat.Camera
    prior_depth: torch.Tensor
    valid: torch.Tensor
    target_rgb: Optional[torch.Tensor] = None
    target_alpha: Optional[torch.Tensor] = None
    crop: tuple[slice, slice] = (slice(None), slice(None))


def colour_target(rendered: torch.Tensor, view: View) -> torch.Tensor:
    """The colour each pixel of ``view`` is supervised towards (H,W,3): the photograph on the object's pixels,
    and off them the render itself, so colour gives no gradient there.

    Off the object the photograph's foreground is black: Gaussians reaching a pixel or two past the outline
    would be darkened to match it, and show as a dark ring once the object moves. Their reach is the
    silhouette term's to correct.
    """
    off_object = (view.target_alpha <= 0)[..., None]
    return torch.where(off_object, rendered.detach(), view.target_rgb)


class _Parameters(torch.nn.Module):
    """The optimised tensors in unconstrained form: log scales, opacity logits."""

    def __init__(self, g: Gaussians, device: str):
        super().__init__()
        as_param = lambda a: torch.nn.Parameter(torch.tensor(a, dtype=torch.float32, device=device))  # noqa: E731
        self.means = as_param(g.means)
        self.log_scales = as_param(np.log(g.scales))
        self.rotations = as_param(g.rotations)
        self.opacity_logits = as_param(np.log(g.opacities / (1 - g.opacities)))
        self.colors = as_param(g.colors)

    def render(self, camera: splat.Camera, hard_depth: bool = False, delta: float = 0.95) -> splat.Render:
        return splat.rasterize(self.means, torch.sigmoid(self.opacity_logits), self.colors, camera,
                               scales=torch.exp(self.log_scales), rotations=self.rotations,
                               hard_depth=hard_depth, delta=delta)

    def to_gaussians(self, object_id: np.ndarray) -> Gaussians:
        with torch.no_grad():
            rotations = torch.nn.functional.normalize(self.rotations, dim=1)
            return Gaussians(self.means.cpu().numpy().astype(np.float64),
                             torch.exp(self.log_scales).cpu().numpy().astype(np.float64),
                             rotations.cpu().numpy().astype(np.float64),
                             torch.sigmoid(self.opacity_logits).cpu().numpy().astype(np.float64),
                             self.colors.clamp(0, 1).cpu().numpy().astype(np.float64), object_id)


def shown_pixels(params: _Parameters, camera: splat.Camera) -> torch.Tensor:
    """(G,) how many pixels' worth of each Gaussian the camera shows: the sum over the image of its
    compositing weight (opacity times transmittance), the rendered colour's derivative by its colour."""
    params.colors.grad = None
    params.render(camera).features[..., 0].sum().backward()
    weight = params.colors.grad[:, 0].detach().clone()
    params.zero_grad(set_to_none=True)
    return weight


def gradient_mask(free: np.ndarray, device: str) -> torch.Tensor:
    """(G,1) float32 on ``device``: 1 for the Gaussians whose parameter is optimised (free (G,) bool), 0 for
    the held ones, to multiply that parameter's gradient by."""
    return torch.tensor(free, device=device)[:, None].float()


def optimize(initial: Gaussians, views: list[View], settings: Settings, device: str = "cpu",
             seed: int = 0, held: Optional[np.ndarray] = None) -> tuple[Gaussians, np.ndarray]:
    """Optimise ``initial`` against ``views`` (views[0] the input view, with colour).

    ``held`` (G,) bool: Gaussians whose means stay as given, and their colours too unless the input view
    shows them (their other parameters are optimised): faces no view sees, which colour supervision reaches
    only through the faces in front of them, where Adam scales a vanishing gradient up to a full step and
    drifts them to any colour.

    Returns:
        The optimised Gaussians, transparent ones pruned, and the loss history
        (iterations, len(LOSS_TERMS)) float32; hard_depth is NaN where it was not evaluated.
    """
    params = _Parameters(initial, device)
    groups = [{"params": [params.means], "lr": settings.lr_means},
              {"params": [params.log_scales], "lr": settings.lr_scales},
              {"params": [params.rotations], "lr": settings.lr_rotations},
              {"params": [params.opacity_logits], "lr": settings.lr_opacities},
              {"params": [params.colors], "lr": settings.lr_colors}]
    optimizer = torch.optim.Adam(groups, eps=1e-15)
    rng = np.random.default_rng(seed)
    history = np.full((settings.iterations, len(LOSS_TERMS)), np.nan, np.float32)
    started = time.perf_counter()
    input_view = views[0]
    if held is not None:
        shown = shown_pixels(params, input_view.camera).cpu().numpy() >= SHOWN_PX
        means_free, colour_free = gradient_mask(~held, device), gradient_mask(~held | shown, device)
    for it in range(settings.iterations):
        if it == settings.decay_at:
            for group in optimizer.param_groups:
                group["lr"] *= 0.1
        render = params.render(input_view.camera)
        target = colour_target(render.features, input_view)
        color = color_loss(render.features[input_view.crop], target[input_view.crop], settings.dssim_weight)
        silhouette = (render.alpha - input_view.target_alpha).abs().mean()
        total = color + settings.silhouette_weight * silhouette
        hard = None
        if settings.hard_depth and it >= settings.hard_depth_from and it % settings.hard_depth_every == 0:
            hard = sum(hard_depth_loss(params.render(v.camera, True, settings.delta).depth, v.prior_depth, v.valid, rng)
                       for v in views)
            total = total + settings.hard_depth_weight * hard
        optimizer.zero_grad(set_to_none=True)
        total.backward()
        if held is not None:  # a zero gradient from the start leaves Adam's moments, and so the step, at zero
            params.means.grad *= means_free
            params.colors.grad *= colour_free
        optimizer.step()
        with torch.no_grad():
            params.colors.clamp_(0, 1)
        history[it, :3] = [total.item(), color.item(), silhouette.item()]
        if hard is not None:
            history[it, 3] = hard.item()
        if (it + 1) % settings.log_every == 0 or it + 1 == settings.iterations:
            recent = history[max(0, it + 1 - settings.log_every):it + 1]
            log.info("iteration %d/%d: loss %.5f (colour %.5f, silhouette %.5f, hard depth %s), %.1f s",
                     it + 1, settings.iterations, recent[:, 0].mean(), recent[:, 1].mean(), recent[:, 2].mean(),
                     f"{np.nanmean(recent[:, 3]):.4f}" if np.isfinite(recent[:, 3]).any() else "off",
                     time.perf_counter() - started)
    result = params.to_gaussians(initial.object_id)
    keep = (result.opacities >= settings.prune_opacity) & np.isfinite(result.means).all(1)
    log.info("pruned %d of %d Gaussians (opacity below %.2f)", int((~keep).sum()), len(result),
             settings.prune_opacity)
    return result.select(keep), history
