"""Self-attention over a video batch with coarse-to-enhanced injection, keyframe extended
attention and keyframe propagation (paper Sec. 3.4.2, Eq. 12-15).

The UNet sees a batch laid out branch-major, ``branches * frames`` items: branch 0 is
the coarse branch (the inverted latents replayed), branches 1.. the enhanced branch
(unconditional and conditional halves of classifier-free guidance). One
:class:`SamplingState`, shared by every processor, says what the next UNet call does.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Literal

import torch
import torch.nn.functional as F

from .keyframes import propagate

Pass = Literal["plain", "keyframes", "propagate"]


@dataclass
class SamplingState:
    """Set by the sampler before each UNet call; read by the processors and hooks.

    pass_kind:
        plain: ordinary per-frame self-attention in every branch.
        keyframes: the batch holds exactly the keyframes; the enhanced branch attends jointly
            over all of them (Eq. 12-13) and every layer records its outputs.
        propagate: the enhanced branch's output is carried from the recorded keyframe outputs
            (Eq. 14-15); the coarse branch attends as usual.
    """

    branches: int = 1
    pass_kind: Pass = "plain"
    inject_features: bool = False  # residual-block outputs of the decoder: coarse -> enhanced
    inject_qk: bool = False  # self-attention queries and keys of the decoder: coarse -> enhanced
    frames: List[int] = field(default_factory=list)  # video frame of each batch item within a branch
    keyframes: List[int] = field(default_factory=list)
    recorded: Dict[str, torch.Tensor] = field(default_factory=dict)  # layer -> (branches, K, tokens, channels)


def _heads(attn, x: torch.Tensor) -> torch.Tensor:
    """(B, N, heads * d) -> (B, heads, N, d)."""
    return x.view(x.shape[0], -1, attn.heads, x.shape[-1] // attn.heads).transpose(1, 2)


def _output(attn, x: torch.Tensor) -> torch.Tensor:
    """(B, heads, N, d) attention result -> (B, N, C) block output, as the stock processor projects it."""
    x = x.transpose(1, 2).reshape(x.shape[0], -1, x.shape[1] * x.shape[3])
    return attn.to_out[1](attn.to_out[0](x)) / attn.rescale_output_factor


def from_coarse(x: torch.Tensor, branches: int) -> torch.Tensor:
    """Every branch's copy of ``x`` replaced by the coarse branch's."""
    return x[: x.shape[0] // branches].repeat(branches, *([1] * (x.ndim - 1)))


def _joint_attention(q: torch.Tensor, k: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Extended attention (Eq. 12-13): each frame's queries over the keys and values of all frames.

    q, k, v: (frames, heads, N, d) of one branch -> (frames, heads, N, d).
    """
    f, h, n, d = q.shape
    joint = [x.transpose(0, 1).reshape(1, h, f * n, d) for x in (q, k, v)]
    return F.scaled_dot_product_attention(*joint).view(h, f, n, d).transpose(0, 1)


class VideoAttnProcessor:
    """Replaces the stock processor of a UNet self-attention layer (``attn1``).

    With pass_kind "plain" and no injection it computes exactly what diffusers'
    AttnProcessor2_0 computes. SD's self-attention layers have no spatial or group
    norm, no residual connection and no mask, so those paths are not handled.
    """

    def __init__(self, state: SamplingState, layer: str, in_decoder: bool):
        self.state, self.layer, self.in_decoder = state, layer, in_decoder

    def __call__(self, attn, hidden_states: torch.Tensor, encoder_hidden_states=None, attention_mask=None,
                 temb=None, **kwargs) -> torch.Tensor:
        state = self.state
        q, k, v = (_heads(attn, proj(hidden_states)) for proj in (attn.to_q, attn.to_k, attn.to_v))
        if state.inject_qk and self.in_decoder and state.branches > 1:
            q, k = from_coarse(q, state.branches), from_coarse(k, state.branches)
        if state.pass_kind == "plain":
            return _output(attn, F.scaled_dot_product_attention(q, k, v))

        b, f = state.branches, q.shape[0] // state.branches
        q, k, v = (x.view(b, f, *x.shape[1:]) for x in (q, k, v))
        coarse = _output(attn, F.scaled_dot_product_attention(q[0], k[0], v[0]))  # (f, N, C)
        if state.pass_kind == "keyframes":
            enhanced = torch.stack([_output(attn, _joint_attention(q[i], k[i], v[i])) for i in range(1, b)])
            out = torch.cat([coarse[None], enhanced])
            state.recorded[self.layer] = out
            return out.flatten(0, 1)
        recorded = state.recorded[self.layer]
        enhanced = torch.stack([propagate(j, state.keyframes, coarse[i], recorded[0], recorded[1:])
                                for i, j in enumerate(state.frames)], dim=1)  # (b - 1, f, N, C)
        return torch.cat([coarse[None], enhanced]).flatten(0, 1)
