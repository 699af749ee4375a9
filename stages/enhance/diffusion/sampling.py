"""DDIM+ sampling (paper Sec. 3.4.2): a coarse branch replaying the inverted latents and an
enhanced branch, run together in one UNet batch, with injection from coarse to enhanced and
keyframe attention in the enhanced branch.
"""
from __future__ import annotations

from typing import List, Sequence

import numpy as np
import torch
from tqdm import tqdm

from schemas.diffusion import DiffusionSettings

from .attention import SamplingState
from .components import Components
from .injection import video_attention
from .keyframes import draw_keyframes

BRANCHES = 3  # coarse, enhanced unconditional, enhanced conditional


def sampling_timesteps(components: Components, steps: int, stored: Sequence[int]):
    """A DDIM scheduler set to ``steps`` steps, and its timesteps from the highest inverted one down.

    Raises:
        ValueError: a sampling timestep has no inverted latent to replay.
    """
    from diffusers import DDIMScheduler

    scheduler = DDIMScheduler.from_config(components.scheduler.config)
    scheduler.set_timesteps(steps)
    timesteps = [int(t) for t in scheduler.timesteps if t <= max(stored)]
    missing = sorted(set(timesteps) - set(stored))
    if missing:
        raise ValueError(f"{steps} sampling steps visit timesteps {missing[:5]}... that were not inverted; "
                         f"the sampling step count must divide the inverted step count {len(stored) - 1}")
    return scheduler, timesteps


@torch.no_grad()
def sample(components: Components, inverted: torch.Tensor, stored: Sequence[int], controls: Sequence[torch.Tensor],
           prompt: torch.Tensor, negative: torch.Tensor, settings: DiffusionSettings) -> torch.Tensor:
    """Enhanced clean latents of a video.

    Args:
        inverted: (T, S + 1, 4, h, w) inverted latents (any device); ``stored`` their timesteps.
        controls: depth and Canny images, each (T, 3, 8h, 8w), on the components' device.
        prompt, negative: (1, tokens, dim) embeddings of the prompt and the negative prompt.
    Returns:
        (T, 4, h, w) latents at t = 0.
    """
    device, dtype = components.device, components.dtype
    scheduler, timesteps = sampling_timesteps(components, settings.steps, stored)
    index = {t: i for i, t in enumerate(stored)}
    n_frames = inverted.shape[0]
    rng = np.random.default_rng(settings.seed)
    enhanced = inverted[:, index[timesteps[0]]].to(device, dtype)
    state = SamplingState(branches=BRANCHES)

    def guided_output(coarse: torch.Tensor, t: int, frames: List[int]) -> torch.Tensor:
        """One UNet call on ``frames`` of the three branches; the enhanced branch's CFG output."""
        state.frames = frames
        f = len(frames)
        latents = torch.cat([coarse[frames], enhanced[frames], enhanced[frames]])
        text = torch.cat([prompt.expand(f, -1, -1), negative.expand(f, -1, -1), prompt.expand(f, -1, -1)])
        out = components.predict(latents, t, text, [c[frames].repeat(BRANCHES, 1, 1, 1) for c in controls],
                                 settings.controlnet_scale).view(BRANCHES, f, *latents.shape[1:])
        return out[1] + settings.guidance_scale * (out[2] - out[1])

    with video_attention(components.unet, state):
        for i, t in enumerate(tqdm(timesteps, desc="DDIM+ sampling", unit="step")):
            state.inject_features = i < settings.tau_f * len(timesteps)
            state.inject_qk = i < settings.tau_a * len(timesteps)
            state.keyframes = draw_keyframes(n_frames, settings.keyframe_window, rng)
            coarse = inverted[:, index[t]].to(device, dtype)
            state.pass_kind = "keyframes"  # records the keyframes' attention outputs in every layer
            guided_output(coarse, t, state.keyframes)
            state.pass_kind = "propagate"
            output = torch.cat([guided_output(coarse, t, list(range(s, min(s + settings.frame_batch, n_frames))))
                                for s in range(0, n_frames, settings.frame_batch)])
            state.recorded.clear()
            enhanced = scheduler.step(output, t, enhanced).prev_sample
    return enhanced
