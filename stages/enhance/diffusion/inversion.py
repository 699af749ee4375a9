"""DDIM+ inversion (paper Sec. 3.4.1, appendix A.2.2): each blended frame, with its ControlNet
controls and the prompt at CFG scale 1, is carried deterministically from its clean latent up
the noise levels, and every intermediate latent is kept so that sampling can replay them.
"""
from __future__ import annotations

import logging
from typing import List, Sequence

import torch
from tqdm import tqdm

from .components import Components

log = logging.getLogger("physmotion.diffusion")

CLEAN = -1  # the timestep recorded for the clean latent (index 0 of the stored latents)


def inverse_scheduler(components: Components, total_steps: int, stride: int):
    """DDIMInverseScheduler mirroring the components' DDIM scheduler: steps of ``stride`` training
    timesteps, up to (not including) ``total_steps``."""
    from diffusers import DDIMInverseScheduler

    train_steps = components.scheduler.config.num_train_timesteps
    if total_steps > train_steps or train_steps % stride:
        raise ValueError(f"inversion needs total_steps <= {train_steps} and a stride dividing {train_steps}")
    scheduler = DDIMInverseScheduler.from_config(components.scheduler.config)
    scheduler.set_timesteps(train_steps // stride)
    scheduler.timesteps = scheduler.timesteps[scheduler.timesteps < total_steps]
    return scheduler


@torch.no_grad()
def invert(components: Components, latents: torch.Tensor, text: torch.Tensor, controls: Sequence[torch.Tensor],
           control_scale: float, scheduler) -> torch.Tensor:
    """Invert a batch of clean latents.

    Args:
        latents: (B, 4, h, w) clean latents.
        text: (1, tokens, dim) prompt embedding (CFG 1: the prompt alone).
        controls: depth and Canny images, each (B, 3, 8h, 8w).
        scheduler: from :func:`inverse_scheduler`.
    Returns:
        (B, S + 1, 4, h, w): the clean latents, then the latent at each of the S timesteps.
    """
    text = text.expand(latents.shape[0], -1, -1)
    trajectory: List[torch.Tensor] = [latents]
    for t in scheduler.timesteps:
        # The model is evaluated at the latent we have and the timestep we go to: the exact
        # inverse of a DDIM sampling step whenever the prediction changes little within a step.
        output = components.predict(trajectory[-1], int(t), text, controls, control_scale)
        trajectory.append(scheduler.step(output, int(t), trajectory[-1]).prev_sample)
    return torch.stack(trajectory, dim=1)


def invert_video(components: Components, latents: torch.Tensor, text: torch.Tensor,
                 controls: Sequence[torch.Tensor], control_scale: float, scheduler,
                 frame_batch: int) -> torch.Tensor:
    """:func:`invert` over a whole video (T, 4, h, w), ``frame_batch`` frames at a time, on the CPU
    when done: (T, S + 1, 4, h, w)."""
    out = []
    batches = range(0, latents.shape[0], frame_batch)
    for start in tqdm(batches, desc="DDIM+ inversion", unit="batch"):
        frames = slice(start, start + frame_batch)
        out.append(invert(components, latents[frames], text, [c[frames] for c in controls], control_scale,
                          scheduler).cpu())
        log.debug("inverted frames %d-%d", start, min(start + frame_batch, latents.shape[0]) - 1)
    return torch.cat(out)


def stored_timesteps(scheduler) -> List[int]:
    """The timestep of each stored latent: CLEAN, then the inversion's timesteps, ascending."""
    return [CLEAN] + [int(t) for t in scheduler.timesteps]
