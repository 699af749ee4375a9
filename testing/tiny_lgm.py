"""Tiny random-weight LGM and ImageDream models with the real architectures, saved in the published layouts.

``save_tiny_lgm`` writes what the published LGM checkpoint is (one safetensors
file, keys ``unet.*`` and ``conv.*``) plus a ``config.json`` with the small
widths; ``save_tiny_multiview`` writes a diffusers folder laid out as the
published ImageDream one (model_index.json naming MVDreamPipeline's classes,
unet/ vae/ text_encoder/ tokenizer/ image_encoder/ feature_extractor/
scheduler/). Nothing is downloaded. 32 px views, 16 px splatter images.
"""
from __future__ import annotations

import json
from pathlib import Path

import torch

from stages.reconstruct.lgm.multiview import MultiViewUNetModel
from stages.reconstruct.lgm.unet import LGM, LGMConfig

TINY_LGM = LGMConfig(input_size=32, down_channels=(8, 16, 16, 32), down_attention=(False, False, True, True),
                     up_channels=(32, 16, 16), up_attention=(True, True, False), attention_heads=2, norm_groups=4)
TINY_MULTIVIEW_UNET = dict(image_size=16, model_channels=16, channel_mult=(1, 2, 2, 2), num_head_channels=8,
                           context_dim=32, ip_dim=4, norm_num_groups=8, ip_embedding_dim=32, ip_resampler_heads=2,
                           ip_resampler_dim_head=8, ip_resampler_depth=1)
PUBLISHED_INDEX = {"unet": ("mv_unet", "MultiViewUNetModel"), "vae": ("diffusers", "AutoencoderKL"),
                   "text_encoder": ("transformers", "CLIPTextModel"), "tokenizer": ("transformers", "CLIPTokenizer"),
                   "image_encoder": ("transformers", "CLIPVisionModel"),
                   "feature_extractor": ("transformers", "CLIPImageProcessor"),
                   "scheduler": ("diffusers", "DDIMScheduler")}
"""model_index.json's entries in the published folder (ashawkey/imagedream-ipmv-diffusers)."""
IMAGEDREAM_SCHEDULER = dict(beta_start=0.00085, beta_end=0.012, beta_schedule="scaled_linear", clip_sample=False,
                            set_alpha_to_one=False, steps_offset=1, num_train_timesteps=1000,
                            prediction_type="epsilon")


def save_tiny_lgm(folder: Path, seed: int = 0, config: LGMConfig = TINY_LGM) -> Path:
    """A tiny LGM in ``folder`` as model_fp16_fixrot.safetensors (float16, as published) + config.json; returns
    the folder."""
    from safetensors.torch import save_file

    torch.manual_seed(seed)
    folder.mkdir(parents=True, exist_ok=True)
    model = LGM(config)
    save_file({k: v.half().contiguous() for k, v in model.state_dict().items()},
              str(folder / "model_fp16_fixrot.safetensors"))
    (folder / "config.json").write_text(json.dumps(config.as_json()))
    return folder


def save_tiny_multiview(folder: Path, seed: int = 0) -> Path:
    """A tiny ImageDream folder in diffusers' layout; returns the folder."""
    from diffusers import AutoencoderKL, DDIMScheduler
    from transformers import (CLIPImageProcessor, CLIPTextConfig, CLIPTextModel, CLIPVisionConfig,
                              CLIPVisionModel)

    from testing.tiny_diffusion import WORDS, _tokenizer

    torch.manual_seed(seed)
    parts = {
        "unet": MultiViewUNetModel(**TINY_MULTIVIEW_UNET),
        "vae": AutoencoderKL(in_channels=3, out_channels=3, latent_channels=4, block_out_channels=(8, 16),
                             down_block_types=("DownEncoderBlock2D",) * 2, up_block_types=("UpDecoderBlock2D",) * 2,
                             layers_per_block=1, norm_num_groups=4, sample_size=32),
        "text_encoder": CLIPTextModel(CLIPTextConfig(
            vocab_size=len(WORDS) + 3, hidden_size=32, intermediate_size=37, num_hidden_layers=2,
            num_attention_heads=2, max_position_embeddings=16, bos_token_id=0, eos_token_id=1, pad_token_id=1)),
        "tokenizer": _tokenizer(),
        "image_encoder": CLIPVisionModel(CLIPVisionConfig(hidden_size=32, intermediate_size=37, num_hidden_layers=2,
                                                          num_attention_heads=2, image_size=32, patch_size=8)),
        "feature_extractor": CLIPImageProcessor(size={"shortest_edge": 32}, crop_size={"height": 32, "width": 32}),
        "scheduler": DDIMScheduler(**IMAGEDREAM_SCHEDULER),
    }
    for name, part in parts.items():
        part.save_pretrained(folder / name)
    index = {"_class_name": "MVDreamPipeline", "_diffusers_version": "0.25.0", "requires_safety_checker": False}
    index.update({name: list(entry) for name, entry in PUBLISHED_INDEX.items()})
    (folder / "model_index.json").write_text(json.dumps(index, indent=2))
    return folder
