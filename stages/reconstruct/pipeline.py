"""The reconstruction of one scene, step by step, without file output (cli.py writes it)."""
from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Optional

import cv2
import numpy as np

from schemas import InputError, Scene
from schemas.camera import pixel_rays
from schemas.solid import SolidGrid

from splat.project import NEAR_PLANE

from .background import inpaint_background
from .body import sample
from .closure import object_depths
from .depth import DptDepth, ObjectDepth, depth_prior_image
from .geometry import intrinsics_from_fov, working_size
from .lift import Gaussians, lift_object
from .optimize import Settings, optimize
from .ply import place_ply
from .segment import ObjectSpec, SamSegmenter, read_photo, segment_objects
from .views import extra_view, input_view

if TYPE_CHECKING:  # the learned prior's modules import diffusers, which only prior lgm needs
    from .lgm.prior import LearnedPrior

log = logging.getLogger("physmotion.reconstruct")

MAX_PHOTO_PX = 4096
"""pm-reconstruct works on a copy of the photograph at most this long (the artifact holds the copy): a
20000 x 20000 photograph took minutes and 4.7 GB at full size with no word in the log, while the
optimisation works at reconstruct.resolution (at most 2048) and the video at render.width (at most 4096)."""
NEAR_PLANE_M = float(NEAR_PLANE)
WIDE_SPAN_DEG = 90.0
"""An object spanning this much of the view (degrees) and still reaching the near plane is a field of view
wider than the photograph's, not a wrong size."""
MAX_GAUSSIANS = 30000
"""Initial Gaussians of all objects at most: keeps 600 iterations at 256 px within about 3 minutes
on 2 CPU cores (benchmarks/RESULTS.md); larger objects are sampled every 2nd, 3rd... pixel."""


@dataclass
class Prepared:
    """Everything before the optimisation, at full photo resolution unless named otherwise."""

    photo: np.ndarray          # RGB u8 (H,W,3)
    labels: np.ndarray         # u8 (H,W): 0 background, k+1 object k
    background: np.ndarray     # RGB u8 (H,W,3)
    K: np.ndarray              # (3,3) at full resolution
    depths: list[ObjectDepth]  # per object, camera-space z (H,W)
    depth_prior: np.ndarray    # f32 (H,W) metres along the ray, NaN off objects
    initial: Gaussians
    seen: np.ndarray           # (G,) bool: the initial Gaussians on surfaces the photograph sees
    solids: list[Optional[SolidGrid]]  # per object the body the closure took; None for an init_ply's or prior lgm's


def downsample(image: np.ndarray, size: tuple[int, int], labels: bool = False) -> np.ndarray:
    """``image`` at ``size`` (w, h): area averaging for colour, nearest for labels and NaN-masked depth."""
    if image.shape[1::-1] == size:
        return image
    return cv2.resize(image, size, interpolation=cv2.INTER_NEAREST if labels else cv2.INTER_AREA)


def prepare(scene: Scene, device: str = "cpu", sam_model: Optional[Path] = None,
            depth_model: Optional[Path] = None, learned: Optional["LearnedPrior"] = None) -> Prepared:
    """Segment, inpaint, estimate depth and lift the initial Gaussians of ``scene``; with reconstruct.prior lgm
    the initial Gaussians are ``learned``'s (lgm/prior.py), and their body is theirs (no solid)."""
    photo, alpha = read_photo(scene.image)
    full_height, full_width = photo.shape[:2]
    size = working_size(full_width, full_height, MAX_PHOTO_PX)
    scale = size[0] / full_width
    if scale < 1:
        photo = downsample(photo, size)
        alpha = downsample(alpha, size) if alpha is not None else None
        log.info("photograph %dx%d px: working on a copy of %dx%d px (at most %d px long)", full_width,
                 full_height, *size, MAX_PHOTO_PX)
    else:
        log.info("photograph %dx%d px", full_width, full_height)
    height, width = photo.shape[:2]
    K = intrinsics_from_fov(scene.camera.fov_deg, width, height)
    sam = SamSegmenter(sam_model, device) if sam_model is not None else None
    specs = [ObjectSpec(mask=o.mask, box=tuple(v * scale for v in o.box) if o.box else None, hints=o.hints)
             for o in scene.objects]
    labels = segment_objects(photo, alpha, specs, scene.file, sam, mask_shape=(full_height, full_width))
    log.info("segmented %d object(s): %s pixels", len(specs),
             ", ".join(str(int((labels == k + 1).sum())) for k in range(len(specs))))
    background = inpaint_background(photo, labels)
    inverse_depth = DptDepth(depth_model, device).inverse_depth(photo) if depth_model is not None else None
    depths = object_depths(labels, K, [o.size_m for o in scene.objects], scene.camera.pitch_deg, inverse_depth,
                           [o.thickness_m for o in scene.objects])
    for k, d in enumerate(depths):
        log.info("object %d: front depth %.3f-%.3f m, back up to %.3f m", k, np.nanmin(d.front),
                 np.nanmax(d.front), np.nanmax(d.back))
        if not np.nanmin(d.front) > NEAR_PLANE_M:  # written so that NaN fails too
            span = view_span_deg(labels == k + 1, K)
            if span >= WIDE_SPAN_DEG:  # the angle, not the size: a body of any size would stand at the camera
                raise InputError(scene.file, "camera.fov_deg", f"at fov_deg {scene.camera.fov_deg:g} object {k} "
                                 f"spans {span:.0f} degrees of the view, too wide for a body to stand in front of "
                                 "the camera", "give camera.fov_deg the photograph's own vertical field of view "
                                 "(a phone's main camera about 40-70 degrees)")
            raise InputError(scene.file, f"objects[{k}].size_m", f"an object of {scene.objects[k].size_m:g} m "
                             f"covering its pixels stands {np.nanmin(d.front):.3g} m from the camera, nearer than the "
                             f"renderer sees ({NEAR_PLANE_M:g} m)", "give the object's real size in metres")
    if scene.reconstruct.prior == "lgm":
        from .lgm.prior import learned_objects

        initial, seen = learned_objects(learned, scene.file, photo, labels, [d.front for d in depths], K,
                                                 [o.size_m for o in scene.objects], MAX_GAUSSIANS)
    else:
        initial, seen = initial_gaussians(scene, photo, labels, depths, K)
    solids = [None if scene.reconstruct.prior == "lgm" or scene.reconstruct.init_ply is not None else
              object_solid(d, K, k) for k, d in enumerate(depths)]
    return Prepared(photo, labels, background, K, depths, depth_prior_image(depths, K), initial, seen,
                    solids)


def object_solid(depth: ObjectDepth, K: np.ndarray, k: int) -> Optional[SolidGrid]:
    """The body the closure took for object k (depth.body), on its grid (body.sample), its front and back
    (H,W) spanning it; None without one."""
    if depth.body is None:
        return None
    pixels = depth.pixels
    rays = pixel_rays(K, *pixels.shape)[pixels]
    rays = rays / rays[:, 2:3]
    points = np.concatenate([rays * depth.front[pixels][:, None], rays * depth.back[pixels][:, None]])
    solid = sample(depth.body, points)
    if solid is not None:
        log.info("object %d: its solid holds %.4g m^3 (%d^3 nodes of %.2f mm; its depths enclose %.4g m^3)", k,
                 solid.volume(), solid.distance.shape[0], 1e3 * solid.spacing, depth.volume(K))
    return solid


def view_span_deg(mask: np.ndarray, K: np.ndarray) -> float:
    """The larger of the horizontal and vertical angles in degrees between the rays through the outer edges
    of a mask's (H,W) pixels, camera intrinsics K (3,3)."""
    rows, cols = np.nonzero(mask)
    spans = [np.degrees(np.arctan((hi + 1 - K[a, 2]) / K[a, a]) - np.arctan((lo - K[a, 2]) / K[a, a]))
             for a, lo, hi in ((0, cols.min(), cols.max()), (1, rows.min(), rows.max()))]
    return float(max(spans))


def initial_gaussians(scene: Scene, photo: np.ndarray, labels: np.ndarray, depths: list[ObjectDepth],
                      K: np.ndarray) -> tuple[Gaussians, np.ndarray]:
    """Lift every object at the working resolution (reconstruct.resolution), or place reconstruct.init_ply.

    Returns the Gaussians and which of them lie on surfaces the photograph sees, (G,) bool (all of a PLY's:
    its shape is the user's, and the optimisation may move any of it)."""
    height, width = labels.shape
    size = working_size(width, height, scene.reconstruct.resolution)
    K_work = K.copy()
    K_work[:2] *= size[0] / width
    photo_work = downsample(photo, size)
    if scene.reconstruct.init_ply is not None:
        if len(scene.objects) != 1:
            raise InputError(scene.file, "reconstruct.init_ply", "an initial PLY describes one object but the "
                             f"scene has {len(scene.objects)}", "use init_ply with a single object, or remove it")
        placed = place_ply(scene.reconstruct.init_ply, labels == 1, K, scene.objects[0].size_m)
        return placed, np.ones(len(placed), bool)
    small = [ObjectDepth(downsample(d.front, size, labels=True), downsample(d.back, size, labels=True),
                         None if d.base is None else downsample(d.base.astype(np.uint8), size, labels=True) > 0,
                         d.body)
             for d in depths]
    for stride in range(1, 9):  # the finest sampling within the budget
        lifted = [lift_object(d, K_work, photo_work, k, front_stride=stride, back_stride=2 * stride)
                  for k, d in enumerate(small)]
        if sum(len(part) for part, _ in lifted) <= MAX_GAUSSIANS:
            break
    for k, (part, _) in enumerate(lifted):
        log.info("object %d: %d initial Gaussians (front sampled every %d pixel(s))", k, len(part), stride)
    return Gaussians.concatenate([part for part, _ in lifted]), np.concatenate([seen for _, seen in lifted])


def optimize_scene(scene: Scene, prepared: Prepared, device: str = "cpu",
                   settings: Optional[Settings] = None) -> tuple[Gaussians, np.ndarray]:
    """Optimise the initial Gaussians on the input view (colour, hard depth) and the extra views (hard depth)."""
    settings = settings or Settings(iterations=scene.reconstruct.iterations)
    resolution = scene.reconstruct.resolution
    views = [input_view(prepared.photo, prepared.labels, prepared.depth_prior, prepared.K, resolution, device)]
    views += [extra_view(v.image, v.azimuth_deg, f"reconstruct.extra_views[{i}]", prepared.initial,
                         scene.camera.fov_deg, resolution, device)
              for i, v in enumerate(scene.reconstruct.extra_views)]
    log.info("optimising %d Gaussians for %d iterations at %dx%d on %d view(s)", len(prepared.initial),
             settings.iterations, views[0].camera.width, views[0].camera.height, len(views))
    # Only the input view supervises the prior's unseen back, rim wall and cut base; where no extra view sees
    # them, they stay where the prior put them, and unless the input view shows them, in the colour of the
    # seen pixel whose ray they lie on (the optimisation would drift both by its learning rate a step: the
    # colours to rainbow speckles on a cut base).
    held = None if views[1:] else ~prepared.seen
    return optimize(prepared.initial, views, settings, device, held=held)
