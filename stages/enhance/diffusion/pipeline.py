"""The diffusion backend from artifacts to frames (paper Sec. 3.4): what pm-invert and pm-enhance run.

    blended frames I_j = alpha * coarse + (1 - alpha) * background       (Sec. 3.4.1, blended_frames)
    controls: normalised inverse depth of the render, Canny edges of I_j
    latents.h5 = DDIM+ inversion of I_j                                   (pm-invert)
    video = coarse + enhanced sampling from latents.h5, decoded           (pm-enhance)
"""
from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import List, Optional

import numpy as np
import torch

from schemas import InputError
from schemas.artifacts import CoarseArtifact, GaussiansArtifact, LatentsArtifact, scheduler_json
from schemas.diffusion import DiffusionSettings

from ..compositing import Backdrop, blend_over_background, resize_to, standing_still, unpremultiply
from .components import Components
from .conditioning import canny_control, inverse_depth_control, model_size, to_tensor, to_u8
from .inversion import inverse_scheduler, invert_video, stored_timesteps
from .models import load_components
from .sampling import sample, sampling_timesteps

log = logging.getLogger("physmotion.diffusion")


@dataclass
class VideoInputs:
    """What the model sees of the coarse video, at the model's size (height, width multiples of 64)."""

    blended: np.ndarray  # (T, H, W, 3) u8: coarse frames over the inpainted background
    depth: np.ndarray  # (T, H, W) f32 in [0, 1]: normalised inverse depth
    canny: np.ndarray  # (T, H, W) f32 in {0, 1}

    def controls(self, components: Components) -> List[torch.Tensor]:
        """Depth and Canny control images, each (T, 3, H, W), on the components' device."""
        return [to_tensor(c).to(components.device, components.dtype) for c in (self.depth, self.canny)]


def blended_frames(coarse: CoarseArtifact, gaussians: GaussiansArtifact) -> np.ndarray:
    """(T, h, w, 3) u8 at the coarse frames' size: each render over its backdrop (compositing.Backdrop), the
    photograph beside the objects where they stand as at rest, with the render's fringe beyond their mask
    trimmed there as the flow backend trims it."""
    h, w = coarse.alpha.shape[1:]
    backdrop = Backdrop(resize_to(gaussians.photo, w, h), resize_to(gaussians.background, w, h), gaussians.mask,
                        coarse.alpha[0])
    scale = w / gaussians.width  # photograph pixels -> output pixels
    frames = np.empty((len(coarse.alpha), h, w, 3), np.uint8)
    for t, (rgb, alpha, source_uv) in enumerate(zip(coarse.rgb, coarse.alpha, coarse.source_uv)):
        uv = source_uv * scale
        still = standing_still(uv)
        frames[t] = blend_over_background(unpremultiply(rgb, alpha), backdrop.objects_alpha(alpha, uv, still),
                                          backdrop(alpha, still))
    return frames


def video_inputs(coarse: CoarseArtifact, gaussians: GaussiansArtifact, settings: DiffusionSettings) -> VideoInputs:
    h, w = coarse.alpha.shape[1:]
    height, width = model_size(h, w, settings.resolution)
    blended = np.stack([resize_to(f, width, height) for f in blended_frames(coarse, gaussians)])
    depth = np.stack([resize_to(d, width, height) for d in inverse_depth_control(coarse.depth, coarse.alpha)])
    return VideoInputs(blended, depth, canny_control(blended, settings.canny_thresholds))


def _components(scene, lora_dir: Optional[Path], device: str) -> Components:
    settings = scene.enhance.diffusion
    if settings.lora.enabled and lora_dir is None:
        raise InputError(scene.file, "enhance.diffusion.lora.enabled", "LoRA personalisation is on but no LoRA "
                         "folder was given", "run pm-lora and pass its output with --lora, or set enabled: false")
    return load_components(settings.models, scene.file, device, lora_dir)


def invert_frames(components: Components, inputs: VideoInputs, prompt: str,
                  settings: DiffusionSettings) -> LatentsArtifact:
    """DDIM+ inversion of every blended frame (CFG 1, ControlNets on), all timesteps kept."""
    scheduler = inverse_scheduler(components, settings.inversion_total_steps, settings.inversion_stride)
    clean = torch.cat([components.encode_images(to_tensor(chunk).to(components.device))
                       for chunk in np.array_split(inputs.blended, -(-len(inputs.blended) // settings.frame_batch))])
    inverted = invert_video(components, clean, components.encode_prompt(prompt), inputs.controls(components),
                            settings.controlnet_scale, scheduler, settings.frame_batch)
    return LatentsArtifact(latents=inverted.float().numpy().astype(np.float16),
                           timesteps=np.array(stored_timesteps(scheduler), dtype=np.int64),
                           scheduler=scheduler_json(dict(components.scheduler.config)), prompt=prompt)


def _check_latents(latents: LatentsArtifact, components: Components, inputs: VideoInputs, prompt: str,
                   settings: DiffusionSettings) -> None:
    """The latents must come from this video, this model and this prompt, at the timesteps sampling visits."""
    expected = (len(inputs.blended), 4, inputs.blended.shape[1] // 8, inputs.blended.shape[2] // 8)
    found = (latents.latents.shape[0],) + latents.latents.shape[2:]
    ours = json.loads(scheduler_json(dict(components.scheduler.config)))
    theirs = json.loads(latents.scheduler)
    problem = None
    if found != expected:
        problem = f"latents of shape {found} (frames, channels, h/8, w/8) but this video needs {expected}"
    elif latents.prompt != prompt:
        problem = f"inverted with the prompt {latents.prompt!r}, not {prompt!r}"
    elif any(theirs.get(k) != ours.get(k) for k in ("prediction_type", "beta_schedule", "beta_start", "beta_end",
                                                     "num_train_timesteps")):
        problem = "inverted with another model's noise schedule"
    else:
        try:
            sampling_timesteps(components, settings.steps, latents.timesteps.tolist())
        except ValueError as err:
            problem = str(err)
    if problem:
        raise InputError("latents.h5", None, problem, "rerun pm-invert with this scene and these models "
                         "(enhance.diffusion.steps must divide the inverted step count)")


def enhance_frames(components: Components, inputs: VideoInputs, latents: LatentsArtifact, prompt: str,
                   settings: DiffusionSettings) -> np.ndarray:
    """Enhanced frames (T, H, W, 3) u8 at the model's size, sampled from the inverted latents."""
    _check_latents(latents, components, inputs, prompt, settings)
    clean = sample(components, torch.from_numpy(latents.latents), latents.timesteps.tolist(),
                   inputs.controls(components), components.encode_prompt(prompt),
                   components.encode_prompt(settings.negative_prompt), settings)
    return np.concatenate([to_u8(components.decode_latents(chunk)) for chunk in clean.split(settings.frame_batch)])


def make_latents(scene, coarse: CoarseArtifact, gaussians: GaussiansArtifact, lora_dir: Optional[Path],
                 device: str) -> LatentsArtifact:
    """pm-invert's work: the DDIM+ inverted latents of the scene's blended coarse video."""
    settings = scene.enhance.diffusion
    components = _components(scene, lora_dir, device)
    return invert_frames(components, video_inputs(coarse, gaussians, settings), scene.prompt, settings)


def enhance_video(scene, coarse: CoarseArtifact, gaussians: GaussiansArtifact, latents: LatentsArtifact,
                  lora_dir: Optional[Path], device: str) -> np.ndarray:
    """pm-enhance's diffusion backend: the enhanced video (T, h, w, 3) u8 at the coarse frames' size."""
    settings = scene.enhance.diffusion
    components = _components(scene, lora_dir, device)
    frames = enhance_frames(components, video_inputs(coarse, gaussians, settings), latents, scene.prompt, settings)
    h, w = coarse.alpha.shape[1:]
    return np.stack([resize_to(f, w, h) for f in frames])
