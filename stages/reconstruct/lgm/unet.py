"""LGM's network: an asymmetric U-Net with cross-view self-attention, and a 1x1 output convolution.

Written from the LGM paper (Tang et al., ECCV 2024, Sec. 3.2 and Fig. 2) and the
published checkpoint's layout; the module names are the checkpoint's keys
(``unet.down_blocks.3.attns.0.attn.qkv.weight``, ``conv.weight``, ...).

Each view's 9 input channels (RGB normalised by ImageNet's mean and deviation,
and the 6-channel Pluecker embedding) go through residual blocks; at the deep,
coarse levels a self-attention block attends over the tokens of all views at
once, which is how the views exchange information. The decoder has fewer
levels than the encoder, so the output (14 channels, ``splatter.py``) is
coarser than the input: 256 px in, 128 px out for the published "big" model.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Optional

import torch
import torch.nn.functional as F
from torch import nn

IN_CHANNELS = 9
"""RGB and the Pluecker embedding per pixel."""
OUT_CHANNELS = 14
"""Per pixel: position 3, opacity 1, scale 3, rotation 4, colour 3 (splatter.py)."""


@dataclass(frozen=True)
class LGMConfig:
    """The architecture; the defaults are the published "big" model (model_fp16_fixrot.safetensors)."""

    input_size: int = 256
    down_channels: tuple[int, ...] = (64, 128, 256, 512, 1024, 1024)
    down_attention: tuple[bool, ...] = (False, False, False, True, True, True)
    mid_attention: bool = True
    up_channels: tuple[int, ...] = (1024, 1024, 512, 256, 128)
    up_attention: tuple[bool, ...] = (True, True, True, False, False)
    layers_per_block: int = 2
    attention_heads: int = 16
    norm_groups: int = 32
    views: int = 4

    @property
    def splat_size(self) -> int:
        """Output side in pixels: the input halves at each down block but the last, doubles at each up
        block but the last."""
        return self.input_size * 2 ** (len(self.up_channels) - 1) // 2 ** (len(self.down_channels) - 1)

    def as_json(self) -> dict:
        return asdict(self)

    @staticmethod
    def from_json(values: dict) -> "LGMConfig":
        known = {k: tuple(v) if isinstance(v, list) else v for k, v in values.items()
                 if k in LGMConfig.__dataclass_fields__}
        return LGMConfig(**known)


SKIP_SCALE = math.sqrt(0.5)
"""Every residual sum is scaled by this, keeping activations at unit variance through the depth."""


class MultiViewAttention(nn.Module):
    """Group norm, then multi-head self-attention over the tokens of all ``views`` of one object; residual."""

    def __init__(self, channels: int, heads: int, groups: int, views: int):
        super().__init__()
        self.heads, self.views = heads, views
        self.norm = nn.GroupNorm(groups, channels, eps=1e-5)
        self.attn = _SelfAttention(channels, heads)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        batch_views, channels, height, width = x.shape
        batch = batch_views // self.views
        tokens = self.norm(x).reshape(batch, self.views, channels, height * width).permute(0, 1, 3, 2)
        tokens = self.attn(tokens.reshape(batch, self.views * height * width, channels))
        tokens = tokens.reshape(batch, self.views, height * width, channels).permute(0, 1, 3, 2)
        return (tokens.reshape(x.shape) + x) * SKIP_SCALE


class _SelfAttention(nn.Module):
    """qkv without bias, output projection with bias (the checkpoint's ``attn.qkv``, ``attn.proj``)."""

    def __init__(self, channels: int, heads: int):
        super().__init__()
        self.heads = heads
        self.qkv = nn.Linear(channels, 3 * channels, bias=False)
        self.proj = nn.Linear(channels, channels)

    def forward(self, tokens: torch.Tensor) -> torch.Tensor:
        batch, count, channels = tokens.shape
        q, k, v = self.qkv(tokens).reshape(batch, count, 3, self.heads, channels // self.heads).permute(2, 0, 3, 1, 4)
        out = F.scaled_dot_product_attention(q, k, v)
        return self.proj(out.transpose(1, 2).reshape(batch, count, channels))


class ResidualBlock(nn.Module):
    """norm-SiLU-conv twice, a 1x1 shortcut where the width changes; the sum scaled by SKIP_SCALE."""

    def __init__(self, in_channels: int, out_channels: int, groups: int):
        super().__init__()
        self.norm1 = nn.GroupNorm(groups, in_channels, eps=1e-5)
        self.conv1 = nn.Conv2d(in_channels, out_channels, 3, padding=1)
        self.norm2 = nn.GroupNorm(groups, out_channels, eps=1e-5)
        self.conv2 = nn.Conv2d(out_channels, out_channels, 3, padding=1)
        self.shortcut = nn.Conv2d(in_channels, out_channels, 1) if in_channels != out_channels else nn.Identity()

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = self.conv1(F.silu(self.norm1(x)))
        h = self.conv2(F.silu(self.norm2(h)))
        return (h + self.shortcut(x)) * SKIP_SCALE


def _layers(config: LGMConfig, widths: list[tuple[int, int]], attention: bool) -> tuple[nn.ModuleList, Optional[nn.ModuleList]]:
    nets = nn.ModuleList([ResidualBlock(cin, cout, config.norm_groups) for cin, cout in widths])
    attns = nn.ModuleList([MultiViewAttention(cout, config.attention_heads, config.norm_groups, config.views)
                           for _, cout in widths]) if attention else None
    return nets, attns


class DownBlock(nn.Module):
    """Residual (+ attention) layers, each output kept for the decoder; then a stride-2 convolution."""

    def __init__(self, config: LGMConfig, in_channels: int, out_channels: int, attention: bool, downsample: bool):
        super().__init__()
        widths = [(in_channels if i == 0 else out_channels, out_channels) for i in range(config.layers_per_block)]
        self.nets, self.attns = _layers(config, widths, attention)
        self.downsample = nn.Conv2d(out_channels, out_channels, 3, stride=2, padding=1) if downsample else None

    def forward(self, x: torch.Tensor, skips: list[torch.Tensor]) -> torch.Tensor:
        for i, net in enumerate(self.nets):
            x = net(x)
            x = self.attns[i](x) if self.attns is not None else x
            skips.append(x)
        if self.downsample is not None:
            x = self.downsample(x)
            skips.append(x)
        return x


class MidBlock(nn.Module):
    """Residual, attention, residual at the coarsest level."""

    def __init__(self, config: LGMConfig, channels: int):
        super().__init__()
        self.nets = nn.ModuleList([ResidualBlock(channels, channels, config.norm_groups) for _ in range(2)])
        self.attns = nn.ModuleList([MultiViewAttention(channels, config.attention_heads, config.norm_groups,
                                                       config.views)]) if config.mid_attention else None

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = self.nets[0](x)
        x = self.attns[0](x) if self.attns is not None else x
        return self.nets[1](x)


class UpBlock(nn.Module):
    """Layers that each concatenate the newest unused encoder output; then 2x nearest upsampling + a conv."""

    def __init__(self, config: LGMConfig, in_channels: int, skip_channels: list[int], out_channels: int,
                 attention: bool, upsample: bool):
        super().__init__()
        widths = [((in_channels if i == 0 else out_channels) + skip, out_channels) for i, skip in enumerate(skip_channels)]
        self.nets, self.attns = _layers(config, widths, attention)
        self.upsample = nn.Conv2d(out_channels, out_channels, 3, padding=1) if upsample else None

    def forward(self, x: torch.Tensor, skips: list[torch.Tensor]) -> torch.Tensor:
        for i, net in enumerate(self.nets):
            x = net(torch.cat([x, skips.pop()], dim=1))
            x = self.attns[i](x) if self.attns is not None else x
        if self.upsample is not None:
            x = self.upsample(F.interpolate(x, scale_factor=2.0, mode="nearest"))
        return x


class AsymmetricUNet(nn.Module):
    """(B*V, 9, S, S) -> (B*V, 14, splat_size, splat_size); the decoder stops before the input resolution."""

    def __init__(self, config: LGMConfig):
        super().__init__()
        down, up = config.down_channels, config.up_channels
        self.conv_in = nn.Conv2d(IN_CHANNELS, down[0], 3, padding=1)
        stack = [down[0]]  # the widths of the encoder outputs the decoder has yet to use
        blocks, width = [], down[0]
        for i, channels in enumerate(down):
            last = i == len(down) - 1
            blocks.append(DownBlock(config, width, channels, config.down_attention[i], downsample=not last))
            stack += [channels] * config.layers_per_block + ([] if last else [channels])
            width = channels
        self.down_blocks = nn.ModuleList(blocks)
        self.mid_block = MidBlock(config, width)
        blocks = []
        for i, channels in enumerate(up):
            skips = [stack.pop() for _ in range(config.layers_per_block + 1)]
            blocks.append(UpBlock(config, width, skips, channels, config.up_attention[i],
                                  upsample=i != len(up) - 1))
            width = channels
        self.up_blocks = nn.ModuleList(blocks)
        self.norm_out = nn.GroupNorm(config.norm_groups, width, eps=1e-5)
        self.conv_out = nn.Conv2d(width, OUT_CHANNELS, 3, padding=1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = self.conv_in(x)
        skips = [x]
        for block in self.down_blocks:
            x = block(x, skips)
        x = self.mid_block(x)
        for block in self.up_blocks:
            x = block(x, skips)
        return self.conv_out(F.silu(self.norm_out(x)))


class LGM(nn.Module):
    """LGM's Gaussian network: ``forward`` maps (B, V, 9, S, S) to the raw splatter images (B, V, 14, s, s)."""

    def __init__(self, config: LGMConfig = LGMConfig()):
        super().__init__()
        if not (len(config.down_channels) == len(config.down_attention)
                and len(config.up_channels) == len(config.up_attention)
                and len(config.up_channels) <= len(config.down_channels)):
            raise ValueError(f"inconsistent LGM architecture {config}")
        self.config = config
        self.unet = AsymmetricUNet(config)
        self.conv = nn.Conv2d(OUT_CHANNELS, OUT_CHANNELS, 1)

    def forward(self, views: torch.Tensor) -> torch.Tensor:
        batch, count, channels, height, width = views.shape
        if count != self.config.views or channels != IN_CHANNELS:
            raise ValueError(f"LGM takes (B, {self.config.views}, {IN_CHANNELS}, S, S), got {tuple(views.shape)}")
        out = self.conv(self.unet(views.reshape(batch * count, channels, height, width)))
        return out.reshape(batch, count, OUT_CHANNELS, *out.shape[-2:])
