"""Object masks from the photograph: mask files, boxes refined by GrabCut or SAM, image alpha.

The result is one label image (H,W) u8: 0 background, k+1 for object k, as
gaussians.h5 stores it in /image/mask.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Sequence

import cv2
import numpy as np
from scipy import ndimage

from schemas import InputError
from schemas.images import read_hints, read_image

from .geometry import working_size
from .local_model import load_local_model

log = logging.getLogger("physmotion.reconstruct")

GRABCUT_ITERATIONS = 5
GRABCUT_CONTEXT = 0.25
"""GrabCut learns the background's colours from this much of the box's longest side around it, not from
the whole photograph, whose far parts may hold look-alikes of the object: with the whole photograph,
the coins photograph's other coins made every coin background, and the rocket's mask took in the sky."""
GRABCUT_MAX_PX = 1024
"""GrabCut runs on a copy at most this long: its time grows faster than the pixel count (a 1804 x 1200
photograph took 54 s, its 1024 px copy 15 s; the masks agree to IoU 0.95), while the optimisation
works at reconstruct.resolution and the video at render.width, far below it."""
DEFAULT_BOX_MARGIN = 0.05
"""Without mask, box or alpha, GrabCut starts from the image less this fraction at each border."""
MIN_BOX_FILL = 0.005
"""A segmentation that keeps less of its box than this has lost the object: GrabCut takes all outside
the box for background, so a box that cuts through the object (or one drawn on another size of the
photograph) leaves it a few stray pixels. A pencil lying diagonally across its box fills a few per cent."""


@dataclass(frozen=True)
class ObjectSpec:
    """How one object is to be segmented (objects[k] of scene.yaml)."""

    mask: Optional[Path] = None
    box: Optional[tuple[float, float, float, float]] = None
    hints: Optional[Path] = None


def read_photo(path: Path) -> tuple[np.ndarray, Optional[np.ndarray]]:
    """The photograph as RGB u8 (H,W,3) and its alpha (H,W) u8, None when it has none or it is all opaque."""
    raw = read_image(path)
    if raw is None:
        raise InputError(path, None, "cannot read this file as an image", "give a PNG or JPEG file")
    if raw.dtype != np.uint8:  # 16-bit PNGs: keep the top byte
        raw = (raw // 257).astype(np.uint8) if raw.dtype == np.uint16 else np.clip(raw, 0, 255).astype(np.uint8)
    if raw.ndim == 2:
        raw = cv2.cvtColor(raw, cv2.COLOR_GRAY2BGR)
    rgb = cv2.cvtColor(raw[..., :3], cv2.COLOR_BGR2RGB)
    alpha = raw[..., 3] if raw.shape[2] == 4 else None
    if alpha is not None and alpha.min() == 255:
        alpha = None
    return rgb, alpha


def largest_component(mask: np.ndarray) -> np.ndarray:
    """The largest 8-connected component of a boolean mask (H,W); GrabCut leaves specks."""
    labels, count = ndimage.label(mask, structure=np.ones((3, 3)))
    if count <= 1:
        return mask.astype(bool)
    sizes = np.bincount(labels.ravel())[1:]
    return labels == 1 + int(np.argmax(sizes))


Hints = tuple[np.ndarray, np.ndarray]
"""(object, background) strokes as boolean masks (H,W), from schemas.images.read_hints."""


def grabcut(photo: np.ndarray, box: Sequence[float], hints: Optional[Hints] = None) -> np.ndarray:
    """Boolean mask (H,W) of the object inside ``box`` [x0,y0,x1,y1] (pixels), by GrabCut.

    GrabCut sees the box and GRABCUT_CONTEXT of its size around it, at most GRABCUT_MAX_PX long.
    ``hints`` are strokes the user drew (pm-setup's page, objects[].hints): their pixels are certain
    object or certain background, and the box grows to take in object strokes drawn outside it.
    """
    height, width = photo.shape[:2]
    if hints is not None and hints[0].any():
        ys, xs = np.nonzero(hints[0])
        box = (min(box[0], xs.min()), min(box[1], ys.min()), max(box[2], xs.max() + 1), max(box[3], ys.max() + 1))
    margin = GRABCUT_CONTEXT * max(box[2] - box[0], box[3] - box[1])
    cx0, cy0 = max(0, int(np.floor(box[0] - margin))), max(0, int(np.floor(box[1] - margin)))
    cx1, cy1 = min(width, int(np.ceil(box[2] + margin))), min(height, int(np.ceil(box[3] + margin)))
    crop = photo[cy0:cy1, cx0:cx1]
    w, h = working_size(cx1 - cx0, cy1 - cy0, GRABCUT_MAX_PX)
    scale = w / (cx1 - cx0)
    small = cv2.resize(crop, (w, h), interpolation=cv2.INTER_AREA) if scale < 1 else crop
    x0, y0 = int(np.floor((box[0] - cx0) * scale)), int(np.floor((box[1] - cy0) * scale))
    x1, y1 = min(w, int(np.ceil((box[2] - cx0) * scale))), min(h, int(np.ceil((box[3] - cy0) * scale)))
    # What GC_INIT_WITH_RECT starts from (outside the box background, inside probably object), then the strokes.
    labels = np.full((h, w), cv2.GC_BGD, np.uint8)
    labels[y0:y1, x0:x1] = cv2.GC_PR_FGD
    if hints is not None:
        for strokes, label in zip(hints, (cv2.GC_FGD, cv2.GC_BGD)):
            # INTER_AREA then any coverage: a one-pixel stroke survives the shrink to the working size
            covered = cv2.resize(strokes[cy0:cy1, cx0:cx1].astype(np.float32), (w, h), interpolation=cv2.INTER_AREA)
            labels[covered > 0] = label
    bgd, fgd = np.zeros((1, 65), np.float64), np.zeros((1, 65), np.float64)
    cv2.setRNGSeed(0)  # GrabCut's k-means initialisation draws from OpenCV's RNG
    cv2.grabCut(cv2.cvtColor(small, cv2.COLOR_RGB2BGR), labels, None, bgd, fgd, GRABCUT_ITERATIONS,
                cv2.GC_INIT_WITH_MASK)
    inside = ((labels == cv2.GC_FGD) | (labels == cv2.GC_PR_FGD)).astype(np.float32)
    if scale < 1:
        inside = cv2.resize(inside, (cx1 - cx0, cy1 - cy0), interpolation=cv2.INTER_LINEAR)
    mask = np.zeros((height, width), bool)
    mask[cy0:cy1, cx0:cx1] = inside > 0.5
    if hints is not None:  # the strokes are certain, also where the shrink and the way back blurred them
        mask = (mask | hints[0]) & ~hints[1]
    return largest_component(mask)


def check_box_fill(mask: np.ndarray, box: Sequence[float], scene_file: Path | str, field: str, fix: str) -> None:
    """An InputError when the segmentation (H,W) kept less than MIN_BOX_FILL of ``box``."""
    height, width = mask.shape
    area = (box[2] - box[0]) * (box[3] - box[1])
    kept = int(mask.sum())
    if kept < MIN_BOX_FILL * area:
        raise InputError(scene_file, field, f"segmentation kept {kept} pixels, {100 * kept / area:.2f} % of the box "
                         f"[{', '.join(f'{v:g}' for v in box)}] in the {width}x{height} photograph, so it has "
                         "lost the object", fix)


def check_box_leaves_background(box: Sequence[float], width: int, height: int, scene_file: Path | str,
                                field: str) -> None:
    """An InputError when a box gives GrabCut nothing to learn from: no pixel outside it, or under 2 px inside."""
    if box[0] < 1 and box[1] < 1 and box[2] > width - 1 and box[3] > height - 1:
        raise InputError(scene_file, field, f"box [{', '.join(f'{v:g}' for v in box)}] covers the whole {width}x{height} "
                         "photograph, so GrabCut has no background to learn from",
                         "draw the box around the object only, or give a mask file")
    if box[2] - box[0] < 2 or box[3] - box[1] < 2:
        raise InputError(scene_file, field, f"box [{', '.join(f'{v:g}' for v in box)}] is under 2 pixels wide or "
                         "high", "draw the box around the whole object, in this photograph's pixels")


def read_mask(path: Path, shape: tuple[int, int], field: str, size: Optional[tuple[int, int]] = None) -> np.ndarray:
    """Boolean mask from a mask image of ``shape`` (H,W): non-zero (any channel, or alpha) is the object;
    brought to ``size`` (w, h) when given (the bounded copy of the photograph)."""
    raw = read_image(path)
    if raw is None:
        raise InputError(path, field, "cannot read this file as an image", "give a PNG mask")
    if raw.shape[:2] != shape:
        raise InputError(path, field, f"mask is {raw.shape[1]}x{raw.shape[0]} but the photograph is "
                         f"{shape[1]}x{shape[0]}", "make the mask exactly the photograph's size")
    mask = (raw > 127) if raw.ndim == 2 else (raw > 127).any(axis=2)
    if size is not None and size != (shape[1], shape[0]):
        mask = cv2.resize(mask.astype(np.uint8), size, interpolation=cv2.INTER_AREA) > 0
    if not mask.any():
        raise InputError(path, field, "mask has no pixel above 127", "paint the object white on black")
    return mask


def segment_objects(photo: np.ndarray, alpha: Optional[np.ndarray], objects: Sequence[ObjectSpec],
                    scene_file: Path | str = "scene.yaml", sam: Optional["SamSegmenter"] = None,
                    mask_shape: Optional[tuple[int, int]] = None) -> np.ndarray:
    """Label image (H,W) u8: 0 background, k+1 object k.

    ``mask_shape`` (H,W): the size mask files must have, when ``photo`` is a smaller copy of the
    photograph (boxes then are in the copy's pixels); the masks are brought to the copy's size.

    Per object: its mask file; else its box, refined by SAM when ``sam`` is
    given and the object has no hints, by GrabCut otherwise (with the hints'
    strokes); else (one object only, no hints) the image alpha; else GrabCut
    from the whole image less a 5 % margin. Where masks overlap the earlier
    object keeps the pixel.
    """
    height, width = photo.shape[:2]
    labels = np.zeros((height, width), np.uint8)
    for k, spec in enumerate(objects):
        field = f"objects[{k}]"
        hints = None
        if spec.hints is not None:
            full_height, full_width = mask_shape or (height, width)
            hints = read_hints(spec.hints, (full_height, full_width))
            if hints is None:
                raise InputError(spec.hints, f"{field}.hints", "cannot read this file as a hint image of the "
                                 f"photograph's size ({full_width}x{full_height})",
                                 "give a PNG of that size, or remove the key")
            if (full_height, full_width) != (height, width):  # strokes onto the bounded copy
                hints = tuple(cv2.resize(h.astype(np.uint8), (width, height), interpolation=cv2.INTER_NEAREST) > 0
                              for h in hints)
        if spec.mask is not None:
            mask = read_mask(spec.mask, mask_shape or (height, width), f"{field}.mask", (width, height))
        elif spec.box is not None:
            check_box_leaves_background(spec.box, width, height, scene_file, f"{field}.box")
            mask = sam.segment(photo, spec.box) if sam is not None and hints is None else grabcut(photo, spec.box, hints)
            check_box_fill(mask, spec.box, scene_file, f"{field}.box", "draw the box around the whole object with a "
                           "few pixels to spare, in this photograph's pixels, or give a mask file")
        elif alpha is not None and len(objects) == 1 and hints is None:
            mask = alpha > 127
        elif len(objects) > 1:
            raise InputError(scene_file, field, "several objects but this one has neither mask nor box",
                             "give each object a mask file or a box [x0, y0, x1, y1]")
        else:
            mx, my = max(1.0, DEFAULT_BOX_MARGIN * width), max(1.0, DEFAULT_BOX_MARGIN * height)
            box = (mx, my, width - mx, height - my)
            mask = grabcut(photo, box, hints)
            check_box_fill(mask, box, scene_file, field, "give a box around the object, or a mask file")
        free = mask & (labels == 0)
        if not free.any():
            raise InputError(scene_file, field, "segmentation found no pixel of this object (or only pixels "
                             "of earlier objects)", "give a mask file, or a tighter box around the object")
        if free.sum() < mask.sum():
            log.warning("object %d overlaps an earlier object; %d pixels stay with the earlier one",
                        k, int(mask.sum() - free.sum()))
        labels[free] = k + 1
    return labels


class SamSegmenter:
    """Segment Anything through transformers (SamModel), loaded from a local folder only.

    The folder is what ``SamModel.save_pretrained`` + ``SamProcessor.save_pretrained``
    write (e.g. a download of facebook/sam-vit-base): config.json, the weights and
    the processor's config. Nothing is fetched from the network.
    """

    def __init__(self, model_dir: Path | str, device: str = "cpu"):
        import torch
        from transformers import SamModel, SamProcessor

        self.torch, self.device = torch, device
        self.processor, self.model = load_local_model(SamProcessor, SamModel, Path(model_dir), device,
                                                      "SAM", "facebook/sam-vit-base", "segment with a mask or a box")

    def segment(self, photo: np.ndarray, box: Sequence[float]) -> np.ndarray:
        """Boolean mask (H,W) of the object in ``box`` [x0,y0,x1,y1]: SAM's highest-scoring mask."""
        inputs = self.processor(images=photo, input_boxes=[[list(map(float, box))]], return_tensors="pt")
        with self.torch.no_grad():
            out = self.model(pixel_values=inputs["pixel_values"].to(self.device),
                             input_boxes=inputs["input_boxes"].to(self.device), multimask_output=True)
        masks = self.processor.post_process_masks(out.pred_masks.cpu(), inputs["original_sizes"],
                                                  inputs["reshaped_input_sizes"])[0][0]  # (3,H,W)
        best = int(out.iou_scores[0, 0].argmax())
        return largest_component(masks[best].numpy().astype(bool))
