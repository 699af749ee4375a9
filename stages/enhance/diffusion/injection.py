"""Installing the video attention processors and the residual-feature injection on a UNet.

Nothing in the UNet is replaced: self-attention layers get a :class:`VideoAttnProcessor`
(cross-attention keeps its own), and the decoder's residual blocks get forward hooks.
Leaving the context restores the original processors and removes the hooks.
"""
from __future__ import annotations

from contextlib import contextmanager
from functools import partial
from typing import Iterator

from .attention import SamplingState, VideoAttnProcessor, from_coarse


def _inject_features(state: SamplingState, module, inputs, output):
    """Forward hook: the enhanced branch's residual-block output becomes the coarse branch's, f_e <- f_c."""
    if state.inject_features and state.branches > 1:
        return from_coarse(output, state.branches)
    return None


@contextmanager
def video_attention(unet, state: SamplingState) -> Iterator[SamplingState]:
    """Within the context, ``unet`` runs its self-attention and decoder residual blocks as ``state`` says.

    Injection reaches the decoder only (``up_blocks``), as in the paper; keyframe attention
    and propagation act on every self-attention layer.
    """
    original = unet.attn_processors
    unet.set_attn_processor({
        name: VideoAttnProcessor(state, name.removesuffix(".processor"), in_decoder=name.startswith("up_blocks"))
        if name.endswith("attn1.processor") else processor
        for name, processor in original.items()})
    hooks = [resnet.register_forward_hook(partial(_inject_features, state))
             for block in unet.up_blocks for resnet in block.resnets]
    try:
        yield state
    finally:
        for hook in hooks:
            hook.remove()
        unet.set_attn_processor(original)
