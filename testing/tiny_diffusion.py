"""A tiny Stable-Diffusion-2.1-shaped model with random weights, for tests and benchmarks (no downloads).

Same block layout as SD 2.1 (three cross-attention down blocks and a plain one,
mirrored up blocks, linear projections in the transformers, two layers per
block), with a few channels; two ControlNets whose zero-convolutions are
perturbed so that the control images matter; a word-level tokenizer built in
memory. ``full_size_components`` gives SD 2.1's real shapes with random weights.
"""
from __future__ import annotations

from pathlib import Path

import torch

from stages.enhance.diffusion.components import Components

SD21_SCHEDULER = dict(beta_start=0.00085, beta_end=0.012, beta_schedule="scaled_linear", clip_sample=False,
                      set_alpha_to_one=False, steps_offset=1, num_train_timesteps=1000)
SD21_UNET = dict(block_out_channels=(320, 640, 1280, 1280), attention_head_dim=(5, 10, 20, 20),
                 cross_attention_dim=1024, norm_num_groups=32)
TINY_UNET = dict(block_out_channels=(16, 16, 32, 32), attention_head_dim=(2, 2, 4, 4),
                 cross_attention_dim=32, norm_num_groups=8)
WORDS = ("a an the of on in photo red blue green cup bread chair jelly wooden table ball toy").split()


def sd21_unet(shape: dict = TINY_UNET, sample_size: int = 16):
    from diffusers import UNet2DConditionModel

    return UNet2DConditionModel(
        sample_size=sample_size, in_channels=4, out_channels=4, layers_per_block=2, use_linear_projection=True,
        down_block_types=("CrossAttnDownBlock2D",) * 3 + ("DownBlock2D",),
        up_block_types=("UpBlock2D",) + ("CrossAttnUpBlock2D",) * 3, **shape)


def full_size_unet():
    """SD 2.1's UNet (865 M parameters) with random weights, at 768 px (96 x 96 latents)."""
    return sd21_unet(SD21_UNET, sample_size=96)


def _tokenizer():
    from tokenizers import Tokenizer, models, pre_tokenizers, processors
    from transformers import PreTrainedTokenizerFast

    special = ["<|startoftext|>", "<|endoftext|>", "<|unk|>"]
    vocab = {w: i for i, w in enumerate(special + list(WORDS))}
    tok = Tokenizer(models.WordLevel(vocab, unk_token="<|unk|>"))
    tok.pre_tokenizer = pre_tokenizers.Whitespace()
    tok.post_processor = processors.TemplateProcessing(
        single="<|startoftext|> $A <|endoftext|>", special_tokens=[("<|startoftext|>", 0), ("<|endoftext|>", 1)])
    return PreTrainedTokenizerFast(tokenizer_object=tok, bos_token=special[0], eos_token=special[1],
                                   unk_token=special[2], pad_token=special[1], model_max_length=16)


def _controlnet(unet, seed: int):
    from diffusers import ControlNetModel

    net = ControlNetModel.from_unet(unet, conditioning_embedding_out_channels=(8, 8, 8, 8))
    gen = torch.Generator().manual_seed(seed)
    with torch.no_grad():  # a trained ControlNet's zero-convolutions are no longer zero
        for conv in [*net.controlnet_down_blocks, net.controlnet_mid_block, net.controlnet_cond_embedding.conv_out]:
            conv.weight.copy_(0.05 * torch.randn(conv.weight.shape, generator=gen))
    return net


def tiny_components(prediction_type: str = "v_prediction", seed: int = 0) -> Components:
    """A random tiny model; 64 x 64 px images give 8 x 8 latents (image sides: multiples of 64)."""
    from diffusers import AutoencoderKL, DDIMScheduler, MultiControlNetModel
    from transformers import CLIPTextConfig, CLIPTextModel

    torch.manual_seed(seed)
    unet = sd21_unet()
    vae = AutoencoderKL(in_channels=3, out_channels=3, latent_channels=4, block_out_channels=(8, 8, 16, 16),
                        down_block_types=("DownEncoderBlock2D",) * 4, up_block_types=("UpDecoderBlock2D",) * 4,
                        layers_per_block=1, norm_num_groups=4, sample_size=64)
    text = CLIPTextModel(CLIPTextConfig(vocab_size=len(WORDS) + 3, hidden_size=32, intermediate_size=37,
                                        num_hidden_layers=2, num_attention_heads=2, max_position_embeddings=16,
                                        projection_dim=32, bos_token_id=0, eos_token_id=1, pad_token_id=1))
    components = Components(vae=vae, text_encoder=text, tokenizer=_tokenizer(), unet=unet,
                            controlnet=MultiControlNetModel([_controlnet(unet, seed + 1), _controlnet(unet, seed + 2)]),
                            scheduler=DDIMScheduler(prediction_type=prediction_type, **SD21_SCHEDULER))
    for model in (vae, text, unet, components.controlnet):
        model.eval()
    return components


def full_size_components(device: str) -> Components:
    """SD 2.1's UNet, VAE and two ControlNets at full size with random weights, for timing; fp16 on CUDA.

    The text encoder has SD 2.1's width but one layer: it runs once per video.
    """
    from diffusers import AutoencoderKL, ControlNetModel, DDIMScheduler, MultiControlNetModel
    from transformers import CLIPTextConfig, CLIPTextModel

    dtype = torch.float16 if device.startswith("cuda") else torch.float32
    unet = full_size_unet()
    controlnet = MultiControlNetModel([ControlNetModel.from_unet(unet) for _ in range(2)])
    vae = AutoencoderKL(block_out_channels=(128, 256, 512, 512), down_block_types=("DownEncoderBlock2D",) * 4,
                        up_block_types=("UpDecoderBlock2D",) * 4, layers_per_block=2, latent_channels=4,
                        sample_size=768)
    text = CLIPTextModel(CLIPTextConfig(vocab_size=len(WORDS) + 3, hidden_size=1024, intermediate_size=4096,
                                        num_hidden_layers=1, num_attention_heads=16, max_position_embeddings=16,
                                        bos_token_id=0, eos_token_id=1, pad_token_id=1))
    for model in (unet, controlnet, text):
        model.to(device, dtype).eval()
    return Components(vae=vae.to(device).eval(), text_encoder=text, tokenizer=_tokenizer(), unet=unet,
                      controlnet=controlnet, scheduler=DDIMScheduler(prediction_type="v_prediction", **SD21_SCHEDULER))


def save_tiny_models(components: Components, folder: Path) -> dict:
    """Save as the real models are laid out: an SD folder and two ControlNet folders. Returns the three paths."""
    from diffusers import StableDiffusionPipeline

    pipe = StableDiffusionPipeline(vae=components.vae, text_encoder=components.text_encoder,
                                   tokenizer=components.tokenizer, unet=components.unet,
                                   scheduler=components.scheduler, safety_checker=None, feature_extractor=None,
                                   requires_safety_checker=False)
    paths = {"stable_diffusion": folder / "sd21", "controlnet_depth": folder / "controlnet_depth",
             "controlnet_canny": folder / "controlnet_canny"}
    pipe.save_pretrained(paths["stable_diffusion"])
    for net, name in zip(components.controlnet.nets, ("controlnet_depth", "controlnet_canny")):
        net.save_pretrained(paths[name])
    return paths
