"""Finding the diffusion weights on this machine and loading them, from local files only.

Three models are needed: Stable Diffusion 2.1 (a diffusers folder), a depth
ControlNet and a Canny ControlNet for SD 2.1. Each is looked up, first found
wins, in: scene.yaml ``enhance.diffusion.models``, its environment variable,
the models file (``$PHYSMOTION_MODELS_FILE``, else
``~/.config/physmotion/models.yaml``, with the same keys), and the local
Hugging Face cache. Nothing is ever downloaded.
"""
from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional

import torch
import yaml

from schemas import InputError
from schemas.diffusion import DiffusionModels

from .components import Components

log = logging.getLogger("physmotion.diffusion")


@dataclass(frozen=True)
class ModelSpec:
    env: str
    repo: str  # Hugging Face repository id whose local cache is searched (and to download from elsewhere)
    models: tuple[str, ...]  # sub-folders holding config.json and weights ("" = the folder itself)
    layout: str
    extras: tuple[str, ...] = ()  # further files or folders that must exist


MODELS: Dict[str, ModelSpec] = {
    "stable_diffusion": ModelSpec(
        "PHYSMOTION_SD_PATH", "stabilityai/stable-diffusion-2-1",
        ("unet", "vae", "text_encoder"),
        "a diffusers folder: model_index.json, scheduler/, tokenizer/, text_encoder/, unet/, vae/ "
        "(each model folder with config.json and *.safetensors or *.bin)",
        ("scheduler/scheduler_config.json", "tokenizer")),
    "controlnet_depth": ModelSpec(
        "PHYSMOTION_CONTROLNET_DEPTH", "thibaud/controlnet-sd21-depth-diffusers", ("",),
        "config.json and diffusion_pytorch_model.safetensors (or .bin)"),
    "controlnet_canny": ModelSpec(
        "PHYSMOTION_CONTROLNET_CANNY", "thibaud/controlnet-sd21-canny-diffusers", ("",),
        "config.json and diffusion_pytorch_model.safetensors (or .bin)"),
}


def _models_file() -> Path:
    default = Path(os.environ.get("XDG_CONFIG_HOME", Path.home() / ".config")) / "physmotion" / "models.yaml"
    return Path(os.environ.get("PHYSMOTION_MODELS_FILE", default))


def _missing_parts(folder: Path, spec: ModelSpec) -> List[str]:
    """The parts of ``folder`` that lack a config or weights; empty when the folder is complete."""
    missing = []
    for part in spec.models:
        sub = folder / part
        has_weights = any(sub.glob("*.safetensors")) or any(sub.glob("*.bin"))
        if not (sub / "config.json").is_file() or not has_weights:
            missing.append(f"{part or '.'} (config.json + weights)")
    return missing + [extra for extra in spec.extras if not (folder / extra).exists()]


def _cached_snapshot(repo: str) -> Optional[Path]:
    from huggingface_hub import snapshot_download

    try:
        return Path(snapshot_download(repo, local_files_only=True))
    except Exception:  # not in the cache (the hub raises several types for that)
        return None


def resolve_model_paths(models: DiffusionModels, scene_file: Path) -> Dict[str, Path]:
    """The folder of each model, checked complete.

    Raises:
        InputError: naming every model that was not found, where it was looked for,
            the layout expected and how to supply it.
    """
    from_file = {}
    if _models_file().is_file():
        from_file = yaml.safe_load(_models_file().read_text()) or {}
    found, problems = {}, []
    for name, spec in MODELS.items():
        candidates = [
            (f"scene.yaml enhance.diffusion.models.{name}", getattr(models, name), scene_file.parent),
            (f"${spec.env}", os.environ.get(spec.env), Path.cwd()),
            (f"{_models_file()} key {name}", from_file.get(name), _models_file().parent),
            (f"the Hugging Face cache ({spec.repo})", _cached_snapshot(spec.repo), Path.cwd()),
        ]
        looked = []
        for where, value, base in candidates:
            if value is None:
                continue
            folder = Path(value).expanduser()
            folder = folder if folder.is_absolute() else base / folder
            missing = _missing_parts(folder, spec)
            if not missing:
                found[name] = folder
                break
            looked.append(f"{folder} from {where} lacks {', '.join(missing)}")
        else:
            looked_text = "; ".join(looked) if looked else "no path given and not in the Hugging Face cache"
            problems.append(f"{name} ({looked_text}; expected {spec.layout}; "
                            f"e.g. `huggingface-cli download {spec.repo} --local-dir DIR` on a machine with "
                            f"network, then set enhance.diffusion.models.{name}: DIR, ${spec.env}=DIR or "
                            f"'{name}: DIR' in {_models_file()})")
    if problems:
        raise InputError(scene_file, "enhance.diffusion.models",
                         "the diffusion backend is missing model weights: " + " | ".join(problems),
                         "supply each missing model as described, or use enhance.backend: flow, which needs no "
                         "weights")
    return found


def load_components(models: DiffusionModels, scene_file: Path, device: str, lora_dir: Optional[Path] = None,
                    dtype: Optional[torch.dtype] = None) -> Components:
    """Load SD 2.1, the depth and Canny ControlNets and optionally a LoRA onto ``device``.

    ``dtype`` defaults to half precision on CUDA, single on CPU. The VAE stays in single
    precision: its decoder overflows float16 at 768 px.
    """
    from diffusers import AutoencoderKL, ControlNetModel, DDIMScheduler, MultiControlNetModel, UNet2DConditionModel
    from transformers import AutoTokenizer, CLIPTextModel

    paths = resolve_model_paths(models, scene_file)
    dtype = dtype or (torch.float16 if device.startswith("cuda") else torch.float32)
    sd = paths["stable_diffusion"]
    log.info("loading Stable Diffusion from %s, ControlNets from %s and %s", sd, paths["controlnet_depth"],
             paths["controlnet_canny"])
    local = dict(local_files_only=True)
    typed = dict(local, torch_dtype=dtype)
    components = Components(
        vae=AutoencoderKL.from_pretrained(sd, subfolder="vae", **local).to(device),
        text_encoder=CLIPTextModel.from_pretrained(sd, subfolder="text_encoder", **typed).to(device),
        tokenizer=AutoTokenizer.from_pretrained(sd, subfolder="tokenizer", **local),
        unet=UNet2DConditionModel.from_pretrained(sd, subfolder="unet", **typed).to(device),
        controlnet=MultiControlNetModel([ControlNetModel.from_pretrained(paths[name], **typed).to(device)
                                         for name in ("controlnet_depth", "controlnet_canny")]),
        scheduler=DDIMScheduler.from_pretrained(sd, subfolder="scheduler", **local),
    )
    if lora_dir is not None:
        from .lora import load_lora

        load_lora(components.unet, lora_dir)
    return components
