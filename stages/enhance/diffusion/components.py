"""The loaded models of one run and the few calls the algorithm makes on them."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import torch


@dataclass
class Components:
    """Stable Diffusion 2.1 with two ControlNets (depth first, Canny second).

    Latents are in the UNet's scaled space (VAE latent times ``scaling_factor``);
    images are float tensors (B, 3, H, W) in [0, 1] with H and W multiples of 8.
    """

    vae: Any  # AutoencoderKL
    text_encoder: Any  # CLIPTextModel
    tokenizer: Any
    unet: Any  # UNet2DConditionModel
    controlnet: Any  # MultiControlNetModel([depth, canny])
    scheduler: Any  # DDIMScheduler: its config (betas, prediction type) defines inversion and sampling

    @property
    def device(self) -> torch.device:
        return self.unet.device

    @property
    def dtype(self) -> torch.dtype:
        return self.unet.dtype

    @torch.no_grad()
    def encode_prompt(self, text: str) -> torch.Tensor:
        """Text embedding (1, tokens, dim) of ``text``, padded to the tokenizer's length."""
        ids = self.tokenizer(text, padding="max_length", max_length=self.tokenizer.model_max_length,
                             truncation=True, return_tensors="pt").input_ids
        return self.text_encoder(ids.to(self.device))[0].to(self.dtype)

    @torch.no_grad()
    def encode_images(self, images: torch.Tensor) -> torch.Tensor:
        """Latents (B, 4, H/8, W/8) of images (B, 3, H, W) in [0, 1]; the posterior mean, so deterministic."""
        posterior = self.vae.encode(images.to(self.vae.device, self.vae.dtype) * 2 - 1).latent_dist
        return (posterior.mean * self.vae.config.scaling_factor).to(self.dtype)

    @torch.no_grad()
    def decode_latents(self, latents: torch.Tensor) -> torch.Tensor:
        """Images (B, 3, H, W) in [0, 1] of latents (B, 4, H/8, W/8)."""
        images = self.vae.decode(latents.to(self.vae.dtype) / self.vae.config.scaling_factor).sample
        return ((images + 1) / 2).clamp(0, 1)

    @torch.no_grad()
    def predict(self, latents: torch.Tensor, timestep: int, text: torch.Tensor,
                controls: Sequence[torch.Tensor], control_scale: float) -> torch.Tensor:
        """The UNet's output (noise or v, as the scheduler's prediction_type says) with ControlNet guidance.

        Args:
            latents: (B, 4, h, w).
            text: (B, tokens, dim) text embeddings.
            controls: depth and Canny images, each (B, 3, 8h, 8w) in [0, 1].
        """
        down, mid = self.controlnet(latents, timestep, encoder_hidden_states=text,
                                    controlnet_cond=[c.to(self.dtype) for c in controls],
                                    conditioning_scale=[control_scale] * len(controls), return_dict=False)
        return self.unet(latents, timestep, encoder_hidden_states=text, down_block_additional_residuals=down,
                         mid_block_additional_residual=mid).sample
