"""LoRA personalisation of the UNet on the segmented object and its extra views
(paper Sec. 3.4.1 and 4.1: 1500 steps at learning rate 1e-6), through peft."""
from __future__ import annotations

import logging
from pathlib import Path
from typing import List, Sequence

import cv2
import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from schemas import InputError
from schemas.diffusion import LoraSettings

from .components import Components
from .conditioning import to_tensor

log = logging.getLogger("physmotion.diffusion")

TARGET_MODULES = ["to_q", "to_k", "to_v", "to_out.0"]  # every attention projection, as diffusers' LoRA scripts
WEIGHTS = "pytorch_lora_weights.safetensors"
MARGIN = 0.1  # of the object's size, kept around it in the crop


def _square(image: np.ndarray, size: int) -> np.ndarray:
    """The largest centred square of ``image``, resized to ``size`` x ``size``."""
    h, w = image.shape[:2]
    s = min(h, w)
    top, left = (h - s) // 2, (w - s) // 2
    return cv2.resize(image[top:top + s, left:left + s], (size, size), interpolation=cv2.INTER_AREA)


def object_image(photo: np.ndarray, mask: np.ndarray, size: int) -> np.ndarray:
    """The segmented objects of the photograph on white, in a square around them, (size, size, 3) u8."""
    ys, xs = np.nonzero(mask)
    if len(ys) == 0:
        raise ValueError("the mask is empty")
    cy, cx = (ys.min() + ys.max()) / 2, (xs.min() + xs.max()) / 2
    half = (1 + 2 * MARGIN) * max(ys.max() - ys.min(), xs.max() - xs.min()) / 2 + 1
    white = np.where(mask[..., None] > 0, photo, 255).astype(np.uint8)
    # Pad with white so that the square may reach beyond the photograph.
    pad = int(np.ceil(half)) + 1
    white = cv2.copyMakeBorder(white, pad, pad, pad, pad, cv2.BORDER_CONSTANT, value=(255, 255, 255))
    top, left = int(round(cy - half)) + pad, int(round(cx - half)) + pad
    side = int(round(2 * half))
    return _square(white[top:top + side, left:left + side], size)


def training_images(photo: np.ndarray, mask: np.ndarray, extra_views: Sequence[np.ndarray], size: int) -> np.ndarray:
    """(N, size, size, 3) u8: the object from the photograph, then each extra view (RGB u8) squared."""
    return np.stack([object_image(photo, mask, size)] + [_square(v, size) for v in extra_views])


def add_lora(unet, rank: int) -> List[torch.nn.Parameter]:
    """Freeze the UNet and give its attention projections a rank-``rank`` LoRA; returns the trainable parameters."""
    from peft import LoraConfig

    unet.requires_grad_(False)
    unet.add_adapter(LoraConfig(r=rank, lora_alpha=rank, init_lora_weights="gaussian", target_modules=TARGET_MODULES))
    return [p for p in unet.parameters() if p.requires_grad]


def diffusion_loss(components: Components, latents: torch.Tensor, text: torch.Tensor,
                   generator: torch.Generator) -> torch.Tensor:
    """The denoising loss the model was trained with: MSE to the noise or to v, per prediction_type.

    latents: (B, 4, h, w) clean; text: (B, tokens, dim); noise and timesteps drawn from ``generator``.
    """
    scheduler = components.scheduler
    noise = torch.randn(latents.shape, generator=generator).to(latents)
    t = torch.randint(0, scheduler.config.num_train_timesteps, (latents.shape[0],), generator=generator)
    t = t.to(latents.device)
    noisy = scheduler.add_noise(latents, noise, t)
    target = noise if scheduler.config.prediction_type == "epsilon" else scheduler.get_velocity(latents, noise, t)
    prediction = components.unet(noisy, t, encoder_hidden_states=text).sample
    return F.mse_loss(prediction.float(), target.float())


def train_lora(components: Components, images: np.ndarray, prompt: str, settings: LoraSettings,
               seed: int = 0) -> List[float]:
    """Train a LoRA on ``images`` (N, H, W, 3) u8 captioned with ``prompt``, one image per step.

    Returns the loss of every step.
    """
    parameters = add_lora(components.unet, settings.rank)
    optimizer = torch.optim.AdamW(parameters, lr=settings.learning_rate)
    latents = torch.cat([components.encode_images(to_tensor(image[None]).to(components.device)) for image in images])
    text = components.encode_prompt(prompt)
    generator = torch.Generator().manual_seed(seed)
    losses = []
    components.unet.train()
    for step in (bar := tqdm(range(settings.steps), desc="LoRA", unit="step")):
        i = int(torch.randint(len(latents), (1,), generator=generator))
        loss = diffusion_loss(components, latents[i:i + 1], text, generator)
        loss.backward()
        optimizer.step()
        optimizer.zero_grad(set_to_none=True)
        losses.append(loss.item())
        bar.set_postfix(loss=f"{np.mean(losses[-50:]):.4f}")
    components.unet.eval()
    return losses


def save_lora(unet, folder: Path) -> Path:
    """Write the UNet's LoRA to ``folder``/pytorch_lora_weights.safetensors (diffusers' layout)."""
    unet.save_lora_adapter(folder, weight_name=WEIGHTS)
    return folder / WEIGHTS


def load_lora(unet, folder: Path) -> None:
    """Add the LoRA saved by :func:`save_lora` to ``unet``."""
    if not (Path(folder) / WEIGHTS).is_file():
        raise InputError(folder, None, f"no {WEIGHTS} in this folder", "pass the folder pm-lora wrote, or rerun pm-lora")
    log.info("loading LoRA from %s", folder)
    unet.load_lora_adapter(str(folder), weight_name=WEIGHTS, prefix=None, local_files_only=True)
