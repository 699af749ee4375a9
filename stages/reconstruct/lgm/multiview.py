"""ImageDream's multi-view UNet (Wang & Shi 2023, on MVDream, Shi et al. 2023) and its sampler.

The network is Stable Diffusion 2.1's UNet (ResBlocks, one transformer per
attention level, linear projections) with three changes, written here from the
papers and the published checkpoint's layout (the module names are the
checkpoint's keys, ``input_blocks.1.1.transformer_blocks.0.attn1.to_q.weight``...):

- the self-attention of every transformer attends over the tokens of all the
  frames (views) of one object at once, which makes the views agree;
- each frame's camera (its camera_to_world, flattened to 16 numbers) passes
  through a two-layer MLP and is added to the timestep embedding;
- image conditioning: the input photograph's CLIP image tokens (penultimate
  hidden states) pass through a perceiver resampler to ``ip_dim`` tokens that
  every cross-attention reads through its own key/value projections (added to
  the text branch), and the photograph's VAE latent replaces the noisy latent
  of a fifth frame whose camera is all zeros.

``sample_views`` runs DDIM with classifier-free guidance (the negative branch
has zero image tokens and a zero image latent) and returns the four views.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Optional

import numpy as np
import torch
import torch.nn.functional as F
from diffusers import ConfigMixin, ModelMixin
from diffusers.configuration_utils import register_to_config
from torch import nn

from .rays import AZIMUTHS_DEG, ELEVATION_DEG, orbit_pose

INPUT_VIEW_FRAME = 1
"""ImageDream's frames sit at azimuths 0, 90, 180, 270 of its own frame; the one at 90 faces the photograph, so
LGM's views (input first) are frames 1, 2, 3, 0."""
DIFFUSION_STEPS = 30
"""DDIM steps of ImageDream's sampling (its published setting)."""
GUIDANCE = 5.0
"""Classifier-free guidance scale on image and text together (ImageDream's published setting)."""


def frame_cameras(elevation_deg: float = ELEVATION_DEG, with_image: bool = True) -> torch.Tensor:
    """(4 or 5, 16) camera inputs: camera_to_world on a unit orbit in Blender's axes (z up), flattened row-major;
    a fifth row of zeros for the photograph's frame."""
    rows = []
    for azimuth in AZIMUTHS_DEG:
        pose = orbit_pose(elevation_deg, azimuth, radius=1.0)
        pose[2] *= -1  # OpenGL (y up) -> Blender (z up): (x, y, z) -> (x, -z, y)
        pose[[1, 2]] = pose[[2, 1]]
        rows.append(pose.reshape(16))
    if with_image:
        rows.append(np.zeros(16))
    return torch.tensor(np.stack(rows), dtype=torch.float32)


def timestep_embedding(timesteps: torch.Tensor, dim: int, max_period: float = 10000.0) -> torch.Tensor:
    """(N,) -> (N, dim) sinusoids, cosines first (LDM's order)."""
    half = dim // 2
    freqs = torch.exp(-math.log(max_period) * torch.arange(half, dtype=torch.float32, device=timesteps.device) / half)
    args = timesteps.float()[:, None] * freqs[None]
    return torch.cat([torch.cos(args), torch.sin(args)], dim=-1)


def _attention(q: torch.Tensor, k: torch.Tensor, v: torch.Tensor, heads: int) -> torch.Tensor:
    """Multi-head attention of (B, N, C) queries on (B, M, C) keys and values."""
    batch, count, channels = q.shape
    split = lambda t: t.reshape(batch, t.shape[1], heads, channels // heads).transpose(1, 2)  # noqa: E731
    out = F.scaled_dot_product_attention(split(q), split(k), split(v))
    return out.transpose(1, 2).reshape(batch, count, channels)


class CrossAttention(nn.Module):
    """to_q/to_k/to_v without bias, to_out.0 with; with ``ip_tokens`` the last that many context tokens are the
    image's, read through to_k_ip/to_v_ip and added."""

    def __init__(self, dim: int, context_dim: int, heads: int, ip_tokens: int = 0):
        super().__init__()
        self.heads, self.ip_tokens = heads, ip_tokens
        self.to_q = nn.Linear(dim, dim, bias=False)
        self.to_k = nn.Linear(context_dim, dim, bias=False)
        self.to_v = nn.Linear(context_dim, dim, bias=False)
        if ip_tokens:
            self.to_k_ip = nn.Linear(context_dim, dim, bias=False)
            self.to_v_ip = nn.Linear(context_dim, dim, bias=False)
        self.to_out = nn.Sequential(nn.Linear(dim, dim), nn.Dropout(0.0))

    def forward(self, x: torch.Tensor, context: Optional[torch.Tensor] = None) -> torch.Tensor:
        context = x if context is None else context
        q = self.to_q(x)
        if self.ip_tokens:
            image, context = context[:, -self.ip_tokens:], context[:, :-self.ip_tokens]
        out = _attention(q, self.to_k(context), self.to_v(context), self.heads)
        if self.ip_tokens:
            out = out + _attention(q, self.to_k_ip(image), self.to_v_ip(image), self.heads)
        return self.to_out(out)


class GEGLU(nn.Module):
    def __init__(self, dim: int, inner: int):
        super().__init__()
        self.proj = nn.Linear(dim, 2 * inner)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        value, gate = self.proj(x).chunk(2, dim=-1)
        return value * F.gelu(gate)


class FeedForward(nn.Module):
    def __init__(self, dim: int):
        super().__init__()
        self.net = nn.Sequential(GEGLU(dim, 4 * dim), nn.Dropout(0.0), nn.Linear(4 * dim, dim))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)


class TransformerBlock(nn.Module):
    """Self-attention across all frames of an object, cross-attention to text (and image), GEGLU MLP."""

    def __init__(self, dim: int, heads: int, context_dim: int, ip_tokens: int):
        super().__init__()
        self.attn1 = CrossAttention(dim, dim, heads)
        self.ff = FeedForward(dim)
        self.attn2 = CrossAttention(dim, context_dim, heads, ip_tokens)
        self.norm1, self.norm2, self.norm3 = nn.LayerNorm(dim), nn.LayerNorm(dim), nn.LayerNorm(dim)

    def forward(self, x: torch.Tensor, context: torch.Tensor, frames: int) -> torch.Tensor:
        batch_frames, tokens, channels = x.shape
        joint = x.reshape(batch_frames // frames, frames * tokens, channels)
        x = (self.attn1(self.norm1(joint)) + joint).reshape(batch_frames, tokens, channels)
        x = self.attn2(self.norm2(x), context) + x
        return self.ff(self.norm3(x)) + x


class SpatialTransformer(nn.Module):
    def __init__(self, channels: int, heads: int, context_dim: int, depth: int, ip_tokens: int, groups: int):
        super().__init__()
        self.norm = nn.GroupNorm(groups, channels, eps=1e-6)
        self.proj_in = nn.Linear(channels, channels)
        self.transformer_blocks = nn.ModuleList([TransformerBlock(channels, heads, context_dim, ip_tokens)
                                                 for _ in range(depth)])
        self.proj_out = nn.Linear(channels, channels)

    def forward(self, x: torch.Tensor, context: torch.Tensor, frames: int) -> torch.Tensor:
        batch, channels, height, width = x.shape
        h = self.proj_in(self.norm(x).reshape(batch, channels, height * width).transpose(1, 2))
        for block in self.transformer_blocks:
            h = block(h, context, frames)
        return self.proj_out(h).transpose(1, 2).reshape(x.shape) + x


class ResBlock(nn.Module):
    def __init__(self, channels: int, emb_channels: int, out_channels: int, groups: int):
        super().__init__()
        self.in_layers = nn.Sequential(nn.GroupNorm(groups, channels), nn.SiLU(),
                                       nn.Conv2d(channels, out_channels, 3, padding=1))
        self.emb_layers = nn.Sequential(nn.SiLU(), nn.Linear(emb_channels, out_channels))
        self.out_layers = nn.Sequential(nn.GroupNorm(groups, out_channels), nn.SiLU(), nn.Dropout(0.0),
                                        nn.Conv2d(out_channels, out_channels, 3, padding=1))
        self.skip_connection = nn.Identity() if out_channels == channels else nn.Conv2d(channels, out_channels, 1)

    def forward(self, x: torch.Tensor, emb: torch.Tensor) -> torch.Tensor:
        h = self.in_layers(x) + self.emb_layers(emb)[..., None, None]
        return self.skip_connection(x) + self.out_layers(h)


class Downsample(nn.Module):
    def __init__(self, channels: int):
        super().__init__()
        self.op = nn.Conv2d(channels, channels, 3, stride=2, padding=1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.op(x)


class Upsample(nn.Module):
    def __init__(self, channels: int):
        super().__init__()
        self.conv = nn.Conv2d(channels, channels, 3, padding=1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.conv(F.interpolate(x, scale_factor=2.0, mode="nearest"))


class Step(nn.ModuleList):
    """One entry of input_blocks/middle_block/output_blocks: layers applied in order, each given what it reads."""

    def forward(self, x: torch.Tensor, emb: torch.Tensor, context: torch.Tensor, frames: int) -> torch.Tensor:
        for layer in self:
            if isinstance(layer, ResBlock):
                x = layer(x, emb)
            elif isinstance(layer, SpatialTransformer):
                x = layer(x, context, frames)
            else:
                x = layer(x)
        return x


class PerceiverAttention(nn.Module):
    def __init__(self, dim: int, dim_head: int, heads: int):
        super().__init__()
        self.heads = heads
        self.norm1, self.norm2 = nn.LayerNorm(dim), nn.LayerNorm(dim)
        self.to_q = nn.Linear(dim, dim_head * heads, bias=False)
        self.to_kv = nn.Linear(dim, 2 * dim_head * heads, bias=False)
        self.to_out = nn.Linear(dim_head * heads, dim, bias=False)

    def forward(self, features: torch.Tensor, latents: torch.Tensor) -> torch.Tensor:
        features, latents = self.norm1(features), self.norm2(latents)
        k, v = self.to_kv(torch.cat([features, latents], dim=1)).chunk(2, dim=-1)
        return self.to_out(_attention(self.to_q(latents), k, v, self.heads))


class Resampler(nn.Module):
    """Learned query tokens that read the image tokens through ``depth`` perceiver layers."""

    def __init__(self, dim: int, depth: int, dim_head: int, heads: int, queries: int, embedding_dim: int,
                 output_dim: int):
        super().__init__()
        self.latents = nn.Parameter(torch.randn(1, queries, dim) / dim ** 0.5)
        self.proj_in = nn.Linear(embedding_dim, dim)
        self.proj_out = nn.Linear(dim, output_dim)
        self.norm_out = nn.LayerNorm(output_dim)
        self.layers = nn.ModuleList([nn.ModuleList([
            PerceiverAttention(dim, dim_head, heads),
            nn.Sequential(nn.LayerNorm(dim), nn.Linear(dim, 4 * dim, bias=False), nn.GELU(),
                          nn.Linear(4 * dim, dim, bias=False))]) for _ in range(depth)])

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        latents = self.latents.expand(features.shape[0], -1, -1)
        features = self.proj_in(features)
        for attention, mlp in self.layers:
            latents = attention(features, latents) + latents
            latents = mlp(latents) + latents
        return self.norm_out(self.proj_out(latents))


class MultiViewUNetModel(ModelMixin, ConfigMixin):
    """ImageDream's UNet; the defaults are the published checkpoint's (ip_* and norm_num_groups: fixed there)."""

    @register_to_config
    def __init__(self, image_size: int = 32, in_channels: int = 4, out_channels: int = 4, model_channels: int = 320,
                 num_res_blocks: int = 2, attention_resolutions: tuple = (4, 2, 1), channel_mult: tuple = (1, 2, 4, 4),
                 num_head_channels: int = 64, transformer_depth: int = 1, context_dim: int = 1024,
                 camera_dim: int = 16, ip_dim: int = 16, ip_weight: float = 1.0, norm_num_groups: int = 32,
                 ip_embedding_dim: int = 1280, ip_resampler_heads: int = 12, ip_resampler_dim_head: int = 64,
                 ip_resampler_depth: int = 4):
        super().__init__()
        groups, emb = norm_num_groups, 4 * model_channels
        self.image_embed = Resampler(context_dim, ip_resampler_depth, ip_resampler_dim_head, ip_resampler_heads,
                                     ip_dim, ip_embedding_dim, context_dim) if ip_dim else None
        self.time_embed = nn.Sequential(nn.Linear(model_channels, emb), nn.SiLU(), nn.Linear(emb, emb))
        self.camera_embed = nn.Sequential(nn.Linear(camera_dim, emb), nn.SiLU(), nn.Linear(emb, emb))

        def transformer(channels: int) -> SpatialTransformer:
            return SpatialTransformer(channels, channels // num_head_channels, context_dim, transformer_depth, ip_dim,
                                      groups)

        self.input_blocks = nn.ModuleList([Step([nn.Conv2d(in_channels, model_channels, 3, padding=1)])])
        widths, width, scale = [model_channels], model_channels, 1
        for level, mult in enumerate(channel_mult):
            for _ in range(num_res_blocks):
                layers = [ResBlock(width, emb, mult * model_channels, groups)]
                width = mult * model_channels
                if scale in attention_resolutions:
                    layers.append(transformer(width))
                self.input_blocks.append(Step(layers))
                widths.append(width)
            if level != len(channel_mult) - 1:
                self.input_blocks.append(Step([Downsample(width)]))
                widths.append(width)
                scale *= 2
        self.middle_block = Step([ResBlock(width, emb, width, groups), transformer(width),
                                  ResBlock(width, emb, width, groups)])
        self.output_blocks = nn.ModuleList()
        for level, mult in reversed(list(enumerate(channel_mult))):
            for i in range(num_res_blocks + 1):
                layers = [ResBlock(width + widths.pop(), emb, mult * model_channels, groups)]
                width = mult * model_channels
                if scale in attention_resolutions:
                    layers.append(transformer(width))
                if level and i == num_res_blocks:
                    layers.append(Upsample(width))
                    scale //= 2
                self.output_blocks.append(Step(layers))
        self.out = nn.Sequential(nn.GroupNorm(groups, width), nn.SiLU(), nn.Conv2d(model_channels, out_channels, 3,
                                                                                   padding=1))

    def forward(self, x: torch.Tensor, timesteps: torch.Tensor, context: torch.Tensor, camera: torch.Tensor,
                frames: int, image_tokens: Optional[torch.Tensor] = None,
                image_latents: Optional[torch.Tensor] = None) -> torch.Tensor:
        """Noise prediction (N F, 4, h, w) for latents x (N F, 4, h, w) of N objects with F frames each; timesteps
        (N F,); context (N F, L, context_dim) text tokens; camera (N F, camera_dim); with ip_dim, image_tokens
        (N F, T, ip_embedding_dim) and image_latents (N, 4, h, w), the latter put into each object's last frame."""
        emb = self.time_embed(timestep_embedding(timesteps, self.config.model_channels).to(x.dtype))
        emb = emb + self.camera_embed(camera.to(x.dtype))
        if self.image_embed is not None:
            x = x.clone()
            x[frames - 1::frames] = image_latents
            context = torch.cat([context, self.image_embed(image_tokens)], dim=1)
        skips, h = [], x
        for step in self.input_blocks:
            h = step(h, emb, context, frames)
            skips.append(h)
        h = self.middle_block(h, emb, context, frames)
        for step in self.output_blocks:
            h = step(torch.cat([h, skips.pop()], dim=1), emb, context, frames)
        return self.out(h)


@dataclass
class MultiViewModels:
    """The multi-view diffusion model's parts (a diffusers folder, ``loading.py``)."""

    unet: MultiViewUNetModel
    vae: Any
    text_encoder: Any
    tokenizer: Any
    image_encoder: Any
    feature_extractor: Any
    scheduler: Any


@torch.no_grad()
def sample_views(models: MultiViewModels, image: np.ndarray, steps: int = DIFFUSION_STEPS, guidance: float = GUIDANCE,
                 size: int = 256, seed: int = 0, progress: Optional[Callable[[int, int], None]] = None) -> np.ndarray:
    """Four views (4, size, size, 3) float32 in [0,1] of the object in ``image`` (H,W,3 float32 in [0,1], the
    object centred on white), LGM's order: the view facing the photograph, then azimuths 90, 180, 270.

    ImageDream's settings: an empty prompt, ``guidance`` on image and text together, ``steps`` DDIM steps."""
    unet, vae = models.unet, models.vae
    device, dtype = unet.device, unet.dtype
    frames = len(AZIMUTHS_DEG) + 1
    pixels = models.feature_extractor((image * 255).round().astype(np.uint8), return_tensors="pt").pixel_values
    tokens = models.image_encoder(pixels.to(device, models.image_encoder.dtype),
                                  output_hidden_states=True).hidden_states[-2].to(dtype)
    picture = torch.from_numpy(image).permute(2, 0, 1)[None].to(device, vae.dtype) * 2 - 1
    picture = F.interpolate(picture, (size, size), mode="bilinear", align_corners=False)
    image_latent = (vae.encode(picture).latent_dist.mode() * vae.config.scaling_factor).to(dtype)
    ids = models.tokenizer([""], padding="max_length", max_length=models.tokenizer.model_max_length,
                           truncation=True, return_tensors="pt").input_ids
    text = models.text_encoder(ids.to(device))[0].to(dtype)
    context = text.expand(2 * frames, -1, -1)
    image_tokens = torch.cat([torch.zeros_like(tokens).expand(frames, -1, -1), tokens.expand(frames, -1, -1)])
    image_latents = torch.cat([torch.zeros_like(image_latent), image_latent])
    camera = frame_cameras().to(device, dtype).repeat(2, 1)
    scale = 2 ** (len(vae.config.block_out_channels) - 1)
    generator = torch.Generator(device="cpu").manual_seed(seed)
    latents = torch.randn((frames, vae.config.latent_channels, size // scale, size // scale), generator=generator)
    scheduler = models.scheduler
    scheduler.set_timesteps(steps, device=device)
    latents = latents.to(device, dtype) * scheduler.init_noise_sigma
    for i, t in enumerate(scheduler.timesteps):
        model_input = scheduler.scale_model_input(torch.cat([latents, latents]), t)
        noise = unet(model_input, t.expand(2 * frames).to(device), context, camera, frames, image_tokens,
                     image_latents)
        unconditional, conditional = noise.chunk(2)
        noise = unconditional + guidance * (conditional - unconditional)
        latents = scheduler.step(noise, t, latents).prev_sample
        if progress is not None:
            progress(i + 1, steps)
    decoded = vae.decode(latents[:len(AZIMUTHS_DEG)].to(vae.dtype) / vae.config.scaling_factor).sample
    views = (decoded / 2 + 0.5).clamp(0, 1).permute(0, 2, 3, 1).float().cpu().numpy()
    order = [(INPUT_VIEW_FRAME + k) % len(AZIMUTHS_DEG) for k in range(len(AZIMUTHS_DEG))]
    return views[order]
