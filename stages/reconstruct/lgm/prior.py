"""``reconstruct.prior: lgm`` for one object: crop, four views, splatter images, Gaussians in the input camera."""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import cv2
import numpy as np
import torch
import torch.nn.functional as F

from schemas import InputError

from ..lift import Gaussians
from .loading import find_lgm, find_multiview, load_lgm, load_multiview
from .multiview import DIFFUSION_STEPS, GUIDANCE, MultiViewModels, sample_views
from .placement import place, seen_from_camera
from .rays import plucker_embedding, view_poses
from .splatter import decode, prune
from .unet import LGM

log = logging.getLogger("physmotion.reconstruct")

BORDER = 0.2
"""The object's bounding box fills the view but this share on each side (LGM's and ImageDream's inputs)."""
IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)
"""Per-channel mean and standard deviation of ImageNet's RGB in [0,1], by which LGM's input is normalised."""
MIN_GAUSSIANS = 4
"""Fewer placed Gaussians than this enclose no volume."""


def object_view(photo: np.ndarray, mask: np.ndarray, size: int, border: float = BORDER) -> np.ndarray:
    """(size,size,3) float32 in [0,1]: the masked object of ``photo`` (H,W,3 u8) on white, its bounding box centred
    and scaled to (1 - 2 border) size along its longer side."""
    rows, cols = np.nonzero(mask)
    top, bottom, left, right = rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
    fitted = (1 - 2 * border) * size / max(bottom - top, right - left)
    h, w = max(1, round((bottom - top) * fitted)), max(1, round((right - left) * fitted))
    rgb = cv2.resize(photo[top:bottom, left:right].astype(np.float32) / 255, (w, h), interpolation=cv2.INTER_AREA)
    alpha = cv2.resize(mask[top:bottom, left:right].astype(np.float32), (w, h), interpolation=cv2.INTER_AREA)[..., None]
    view = np.ones((size, size, 3), np.float32)
    y, x = (size - h) // 2, (size - w) // 2
    view[y:y + h, x:x + w] = rgb * alpha + (1 - alpha)
    return view


def lgm_input(views: np.ndarray, input_size: int) -> torch.Tensor:
    """(1, 4, 9, S, S): the views (4,H,W,3 in [0,1]) resized to ``input_size``, normalised as ImageNet, with their
    Pluecker embeddings (LGM's cameras, ``rays.py``)."""
    images = torch.from_numpy(np.ascontiguousarray(views)).permute(0, 3, 1, 2).float()
    images = F.interpolate(images, size=(input_size, input_size), mode="bilinear", align_corners=False)
    mean, std = torch.tensor(IMAGENET_MEAN)[:, None, None], torch.tensor(IMAGENET_STD)[:, None, None]
    return torch.cat([(images - mean) / std, plucker_embedding(view_poses(), input_size)], dim=1)[None]


@dataclass
class LearnedPrior:
    """LGM and the multi-view model, found on this machine and loaded once for all objects."""

    lgm: LGM
    multiview: MultiViewModels
    device: str

    @staticmethod
    def load(scene_file: Path, device: str, lgm_flag: Optional[Path] = None,
             multiview_flag: Optional[Path] = None) -> "LearnedPrior":
        """Both models from local files (``loading.py``); InputError naming what is missing, before any work."""
        weights, folder = find_lgm(lgm_flag, scene_file), find_multiview(multiview_flag, scene_file)
        return LearnedPrior(load_lgm(weights, device), load_multiview(folder, device), device)

    @property
    def view_size(self) -> int:
        """The multi-view model's image side in pixels: its latent side times the VAE's downsampling (256)."""
        vae = self.multiview.vae.config
        return self.multiview.unet.config.image_size * 2 ** (len(vae.block_out_channels) - 1)

    def views(self, image: np.ndarray) -> np.ndarray:
        """The four views (4,S,S,3) of the object in ``image`` (``object_view``), LGM's order."""
        started = time.perf_counter()

        def progress(step: int, steps: int) -> None:
            if step == 1 or step % 5 == 0 or step == steps:
                spent = time.perf_counter() - started
                log.info("multi-view diffusion: step %d/%d, %.0f s, about %.0f s left", step, steps, spent,
                         spent / step * (steps - step))

        return sample_views(self.multiview, image, steps=DIFFUSION_STEPS, guidance=GUIDANCE, size=image.shape[0],
                            progress=progress)

    @torch.no_grad()
    def gaussians(self, photo: np.ndarray, mask: np.ndarray, K: np.ndarray, size_m: float, front: np.ndarray,
                  object_id: int) -> Gaussians:
        """The object's Gaussians in the input camera ``K`` from its ``mask`` (H,W bool) of ``photo`` (H,W,3 u8)."""
        views = self.views(object_view(photo, mask, self.view_size))
        log.info("object %d: LGM on the 4 views at %d px (%s; on a CPU minutes)", object_id,
                 self.lgm.config.input_size, self.device)
        started = time.perf_counter()
        inputs = lgm_input(views, self.lgm.config.input_size).to(self.device, next(self.lgm.parameters()).dtype)
        cloud = prune(decode(self.lgm(inputs)[0]))
        log.info("object %d: LGM gave %d Gaussians in %.1f s", object_id, len(cloud), time.perf_counter() - started)
        return place(cloud, mask, K, size_m, front, object_id)


def learned_objects(prior: LearnedPrior, scene_file: Path, photo: np.ndarray, labels: np.ndarray,
                    fronts: list[np.ndarray], K: np.ndarray, sizes_m: list[float],
                    budget: int) -> tuple[Gaussians, np.ndarray]:
    """Every object's learned Gaussians in the camera ``K``: (Gaussians, (G,) bool which the photograph sees).
    ``fronts``: the prior's camera-space front depths (H,W) per object; at most
    ``budget`` Gaussians in all (a fixed random subset of each object's where more)."""
    parts = []
    for k, (front, size_m) in enumerate(zip(fronts, sizes_m)):
        placed = prior.gaussians(photo, labels == k + 1, K, size_m, front, k)
        if len(placed) < MIN_GAUSSIANS:
            raise InputError(scene_file, f"objects[{k}]", f"LGM left {len(placed)} Gaussians of the object on its "
                             "mask (transparent, or outside the mask once placed)", "check the object's mask or box; "
                             "or use reconstruct.prior: symmetric")
        log.info("object %d: %d learned Gaussians placed", k, len(placed))
        parts.append(placed)
    share = budget // max(1, len(parts))
    generator = np.random.default_rng(0)
    parts = [part if len(part) <= share else part.select(np.sort(generator.choice(len(part), share, replace=False)))
             for part in parts]
    seen = np.concatenate([seen_from_camera(part, K, labels == k + 1, size_m)
                           for k, (part, size_m) in enumerate(zip(parts, sizes_m))])
    return Gaussians.concatenate(parts), seen
