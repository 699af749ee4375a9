"""Finding LGM's and the multi-view model's weights on this machine and loading them; nothing is downloaded.

Each is looked up, first found wins: the command-line flag, the environment
variable, the local Hugging Face cache (``huggingface_hub``'s cache lookup only,
never the network). Before loading, every weight's name and shape is checked
against the architecture (LGM: the published "big" configuration, or a
``config.json`` beside the weights; the multi-view UNet: its ``unet/config.json``,
whose keys must be the published ones), and the multi-view folder's
``model_index.json`` must name the published component classes.
"""
from __future__ import annotations

import inspect
import json
import logging
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import torch

from schemas import InputError

from .multiview import MultiViewModels, MultiViewUNetModel
from .unet import LGM, LGMConfig

log = logging.getLogger("physmotion.reconstruct")

LGM_REPO = "ashawkey/LGM"
LGM_FILES = ("model_fp16_fixrot.safetensors", "model_fp16.safetensors", "model.safetensors")
"""The published checkpoints, newest first; any one of them in a folder will do."""
LGM_ENV = "PHYSMOTION_LGM_MODEL"
MULTIVIEW_REPO = "ashawkey/imagedream-ipmv-diffusers"
MULTIVIEW_ENV = "PHYSMOTION_MULTIVIEW_MODEL"
MULTIVIEW_COMPONENTS = {
    "unet": "MultiViewUNetModel", "vae": "AutoencoderKL", "text_encoder": "CLIPTextModel",
    "tokenizer": ("CLIPTokenizer", "CLIPTokenizerFast", "PreTrainedTokenizerFast"),
    "image_encoder": "CLIPVisionModel", "feature_extractor": "CLIPImageProcessor", "scheduler": "DDIMScheduler"}
"""model_index.json's class for each component of the published ImageDream folder."""
MULTIVIEW_UNET_KEYS = ("image_size", "in_channels", "out_channels", "model_channels", "num_res_blocks",
                       "attention_resolutions", "channel_mult", "num_head_channels", "transformer_depth",
                       "context_dim", "camera_dim", "ip_dim")
"""The keys a published ImageDream unet/config.json holds: a folder whose config lacks one is not ImageDream's."""
LGM_HOWTO = (f"download the LGM checkpoint on a machine with network (`huggingface-cli download {LGM_REPO} "
             f"{LGM_FILES[0]} --local-dir DIR`), copy DIR here and pass --lgm-model DIR or set ${LGM_ENV}=DIR; "
             "or use reconstruct.prior: symmetric, which needs no weights")
MULTIVIEW_HOWTO = (f"download ImageDream in diffusers' layout on a machine with network (`huggingface-cli download "
                   f"{MULTIVIEW_REPO} --local-dir DIR`), copy DIR here and pass --multiview-model DIR or set "
                   f"${MULTIVIEW_ENV}=DIR; or use reconstruct.prior: symmetric, which needs no weights")


@dataclass(frozen=True)
class Candidate:
    where: str       # how the path was found, for the message
    path: Path


def _from_cache(repo: str, filename: Optional[str] = None) -> Optional[Path]:
    """A file (or the snapshot folder) of ``repo`` in the local Hugging Face cache, else None; no network."""
    try:
        from huggingface_hub import snapshot_download, try_to_load_from_cache
    except ImportError:
        return None
    if filename is not None:
        found = try_to_load_from_cache(repo, filename)
        return Path(found) if isinstance(found, str) else None
    try:
        return Path(snapshot_download(repo, local_files_only=True))
    except Exception:  # not cached: the hub raises several types for that
        return None


def _candidates(flag: Optional[Path], env: str, cached: list[Optional[Path]], repo: str) -> list[Candidate]:
    found = [Candidate("the command line", flag)] if flag is not None else []
    if os.environ.get(env):
        found.append(Candidate(f"${env}", Path(os.environ[env])))
    found += [Candidate(f"the Hugging Face cache ({repo})", path) for path in cached if path is not None]
    return found


def _none_found(scene_file: Path, what: str, looked: list[str], expects: str, howto: str) -> InputError:
    places = "; ".join(looked) if looked else "no flag, no environment variable, nothing in the Hugging Face cache"
    return InputError(scene_file, "reconstruct.prior", f"prior lgm needs the {what}, which is not on this machine "
                      f"(looked at: {places}; expected {expects})", howto)


def safetensors_shapes(path: Path) -> dict[str, tuple[int, ...]]:
    """Name -> shape of every tensor in a safetensors file, read from its header only."""
    from safetensors import safe_open

    with safe_open(str(path), framework="pt") as handle:
        return {key: tuple(handle.get_slice(key).get_shape()) for key in handle.keys()}


def architecture_mismatch(expected: dict[str, tuple[int, ...]], found: dict[str, tuple[int, ...]]) -> Optional[str]:
    """None when ``found`` has exactly the names and shapes of ``expected``; else a sentence naming a few."""
    missing = sorted(set(expected) - set(found))
    unexpected = sorted(set(found) - set(expected))
    wrong = sorted(k for k in set(expected) & set(found) if tuple(expected[k]) != tuple(found[k]))
    if not (missing or unexpected or wrong):
        return None
    parts = [f"{len(missing)} missing (e.g. {', '.join(missing[:3])})" if missing else "",
             f"{len(unexpected)} unexpected (e.g. {', '.join(unexpected[:3])})" if unexpected else "",
             "wrong shapes: " + ", ".join(f"{k} {found[k]} instead of {expected[k]}" for k in wrong[:3]) if wrong else ""]
    return "its weights do not fit the architecture: " + "; ".join(p for p in parts if p)


def meta_shapes(module_factory) -> dict[str, tuple[int, ...]]:
    """Name -> shape of the parameters of the module ``module_factory()`` builds, without allocating them."""
    with torch.device("meta"):
        return {key: tuple(value.shape) for key, value in module_factory().state_dict().items()}


def _lgm_file(path: Path) -> Optional[Path]:
    if path.is_file():
        return path
    return next((path / name for name in LGM_FILES if (path / name).is_file()), None)


def lgm_config(weights: Path) -> LGMConfig:
    """The published "big" configuration, or the one in ``config.json`` beside the weights."""
    config_file = weights.parent / "config.json"
    return LGMConfig.from_json(json.loads(config_file.read_text())) if config_file.is_file() else LGMConfig()


def find_lgm(flag: Optional[Path], scene_file: Path) -> Path:
    """The LGM checkpoint file, checked against its architecture; InputError when none fits."""
    cached = [_from_cache(LGM_REPO, name) for name in LGM_FILES]
    looked = []
    for candidate in _candidates(flag, LGM_ENV, cached, LGM_REPO):
        weights = _lgm_file(candidate.path)
        if weights is None:
            looked.append(f"{candidate.path} from {candidate.where}: no {' or '.join(LGM_FILES)}")
            continue
        try:
            problem = architecture_mismatch(meta_shapes(lambda: LGM(lgm_config(weights))), safetensors_shapes(weights))
        except Exception as err:  # an unreadable header or config: the user's file is at fault
            problem = f"it cannot be read ({err})"
        if problem is None:
            return weights
        looked.append(f"{weights} from {candidate.where}: {problem}")
    raise _none_found(scene_file, "LGM checkpoint", looked, f"a safetensors file ({', '.join(LGM_FILES)}) of the published "
                      "'big' LGM: 415 M parameters, keys unet.* and conv.*", LGM_HOWTO)


def load_lgm(weights: Path, device: str) -> LGM:
    """LGM in eval mode on ``device`` (half precision on CUDA, single on the CPU) from a checked checkpoint."""
    from safetensors.torch import load_file

    model = LGM(lgm_config(weights))
    model.load_state_dict(load_file(str(weights)))
    dtype = torch.float16 if device.startswith("cuda") else torch.float32
    log.info("loaded LGM from %s (%.0f M parameters)", weights, sum(p.numel() for p in model.parameters()) / 1e6)
    return model.to(device, dtype).eval()


def multiview_problem(folder: Path) -> Optional[str]:
    """None when ``folder`` is a complete ImageDream folder in diffusers' layout whose UNet weights fit; else why."""
    index_file = folder / "model_index.json"
    if not index_file.is_file():
        return "no model_index.json"
    try:
        index = json.loads(index_file.read_text())
    except ValueError as err:
        return f"model_index.json is not JSON ({err})"
    for part, classes in MULTIVIEW_COMPONENTS.items():
        entry = index.get(part)
        named = entry[1] if isinstance(entry, list) and len(entry) == 2 else None
        if named not in ((classes,) if isinstance(classes, str) else classes):
            return f"model_index.json names {part} as {named!r}, not {classes!r}"
        has_config = any((folder / part / name).is_file() for name in
                         ("config.json", "scheduler_config.json", "preprocessor_config.json", "tokenizer_config.json"))
        if not has_config:
            return f"{part}/ has no configuration file"
    for part in ("unet", "vae", "text_encoder", "image_encoder"):
        if not any((folder / part).glob("*.safetensors")):
            return f"{part}/ has no *.safetensors weights"
    try:
        config = json.loads((folder / "unet" / "config.json").read_text())
    except ValueError as err:
        return f"unet/config.json is not JSON ({err})"
    absent = [key for key in MULTIVIEW_UNET_KEYS if key not in config]
    if absent:
        return f"unet/config.json lacks {', '.join(absent)} (the published MultiViewUNetModel's keys)"
    weights = next((folder / "unet").glob("*.safetensors"))
    known = inspect.signature(MultiViewUNetModel.__init__).parameters
    arguments = {key: value for key, value in config.items() if key in known}  # e.g. LDM's use_checkpoint: unused
    try:
        return architecture_mismatch(meta_shapes(lambda: MultiViewUNetModel(**arguments)), safetensors_shapes(weights))
    except Exception as err:  # an unreadable header or impossible sizes: the user's files are at fault
        return f"unet/ cannot be read or built ({err})"


def find_multiview(flag: Optional[Path], scene_file: Path) -> Path:
    """The ImageDream folder, checked; InputError when none is complete."""
    looked = []
    for candidate in _candidates(flag, MULTIVIEW_ENV, [_from_cache(MULTIVIEW_REPO)], MULTIVIEW_REPO):
        problem = multiview_problem(candidate.path)
        if problem is None:
            return candidate.path
        looked.append(f"{candidate.path} from {candidate.where}: {problem}")
    raise _none_found(scene_file, "multi-view diffusion model (ImageDream)", looked, "a diffusers folder: model_index.json "
                      "(MVDreamPipeline), unet/ (MultiViewUNetModel), vae/, text_encoder/, tokenizer/, image_encoder/ "
                      "(CLIPVisionModel), feature_extractor/, scheduler/", MULTIVIEW_HOWTO)


def load_multiview(folder: Path, device: str) -> MultiViewModels:
    """ImageDream's parts on ``device`` (half precision on CUDA, single on the CPU) from a checked folder."""
    from diffusers import AutoencoderKL, DDIMScheduler
    from transformers import AutoTokenizer, CLIPImageProcessor, CLIPTextModel, CLIPVisionModel

    dtype = torch.float16 if device.startswith("cuda") else torch.float32
    local = dict(local_files_only=True)
    models = MultiViewModels(
        unet=MultiViewUNetModel.from_pretrained(folder, subfolder="unet", torch_dtype=dtype, **local),
        vae=AutoencoderKL.from_pretrained(folder, subfolder="vae", torch_dtype=dtype, **local),
        text_encoder=CLIPTextModel.from_pretrained(folder, subfolder="text_encoder", torch_dtype=dtype, **local),
        tokenizer=AutoTokenizer.from_pretrained(folder, subfolder="tokenizer", **local),
        image_encoder=CLIPVisionModel.from_pretrained(folder, subfolder="image_encoder", torch_dtype=dtype, **local),
        feature_extractor=CLIPImageProcessor.from_pretrained(folder, subfolder="feature_extractor", **local),
        scheduler=DDIMScheduler.from_pretrained(folder, subfolder="scheduler", **local))
    for model in (models.unet, models.vae, models.text_encoder, models.image_encoder):
        model.to(device).eval()
    log.info("loaded the multi-view diffusion model from %s", folder)
    return models
