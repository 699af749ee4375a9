"""scene.yaml: the user-facing description of one scene.

Units: metres, seconds, kilograms, pascals, degrees. Condition vectors and
regions are read in the gravity-aligned frame (x the picture's right made
horizontal, y down along gravity, z horizontal away from the camera) unless a
condition says `frame: camera`. Regions live in an object's own normalised
box, [0,1]^3 over its bounding box at rest in that frame. Every path is
relative to the scene folder.
"""
from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path
from typing import Annotated, Any, List, Literal, Optional, Tuple, Union, get_args

import yaml
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, ValidationError, field_validator, model_validator, PrivateAttr

from .diffusion import DiffusionSettings
from .materials import PRESETS, Jelly, Material
from .program import InputError

Vec3 = Tuple[float, float, float]


class _Strict(BaseModel):
    # allow_inf_nan: every float must be finite, refused under its own key (a NaN fails every bound check,
    # so pydantic would otherwise report the first bound, "should be <= 240").
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class CameraConfig(_Strict):
    fov_deg: float = Field(40.0, gt=1, lt=179, description="vertical field of view in degrees")
    pitch_deg: float = Field(0.0, ge=-89, le=89,
                             description="camera tilt down from horizontal in degrees; turns the default gravity")


class ObjectConfig(_Strict):
    mask: Optional[Path] = Field(None, description="mask image (non-zero = object); else box; neither: image alpha, else GrabCut")
    box: Optional[Tuple[float, float, float, float]] = Field(None, description="[x0, y0, x1, y1] in pixels, refined by GrabCut")
    hints: Optional[Path] = Field(None, description="hint image for GrabCut, the photograph's size: opaque white "
                                  "strokes are object, opaque black strokes background, transparent no hint "
                                  "(pm-setup paints it)")
    size_m: float = Field(0.25, ge=0.01, le=1000, description="largest extent of the object in metres (1 cm to "
                          "1 km: a smaller object would stand nearer than splat's near plane, 1 cm from the camera)")
    thickness_m: Optional[float] = Field(None, ge=0.001, le=1000, description="thickness of a flat object (a printed "
                                         "logo, a coin, a slab) across the view, metres: its body is cut to a slab "
                                         "that thick about its middle; none: the silhouette alone shapes it, which "
                                         "makes a disc a ball")
    material: Material = Field(default_factory=Jelly, description="material preset and its keys")

    @model_validator(mode="after")
    def _one_segmentation(self) -> "ObjectConfig":
        if self.mask is not None and self.box is not None:
            raise ValueError("give either mask or box, not both")
        if self.mask is not None and self.hints is not None:
            raise ValueError("hints correct a box's GrabCut; a mask file needs none: give mask or hints, not both")
        if self.box is not None and not (self.box[0] < self.box[2] and self.box[1] < self.box[3]):
            raise ValueError("box must be [x0, y0, x1, y1] with x0 < x1 and y0 < y1")
        return self


class ExtraView(_Strict):
    image: Path = Field(description="another view of the object (e.g. from a multi-view diffusion model)")
    azimuth_deg: float = Field(description="azimuth of that view about the object's vertical axis, degrees")


class ReconstructConfig(_Strict):
    resolution: int = Field(256, ge=32, le=2048, description="longest image side used by the optimisation, pixels")
    iterations: int = Field(600, ge=0, description="optimisation iterations (paper: 3000)")
    prior: Literal["symmetric", "lgm"] = Field(
        "symmetric", description="the shape of the unseen half: symmetric continues the photographed front without "
        "weights; lgm runs multi-view diffusion (ImageDream) and LGM from local weights (pm-reconstruct "
        "--lgm-model/--multiview-model, else env PHYSMOTION_LGM_MODEL/PHYSMOTION_MULTIVIEW_MODEL, else the Hugging "
        "Face cache)")
    init_ply: Optional[Path] = Field(None, description="3DGS PLY from another tool as the initial Gaussians")
    extra_views: List[ExtraView] = Field(default_factory=list, description="extra views for the hard-depth loss (Eq. 9)")
    sam_model: Optional[Path] = Field(None, description="folder of a transformers SAM model: boxes are refined by SAM "
                                      "instead of GrabCut (else env PHYSMOTION_SAM_MODEL)")
    depth_model: Optional[Path] = Field(None, description="folder of a transformers DPT/MiDaS model for the depth prior "
                                        "instead of silhouette inflation (else env PHYSMOTION_DEPTH_MODEL)")


class GroundConfig(_Strict):
    enabled: bool = True
    type: Literal["sticky", "slip", "friction"] = Field("friction", description="boundary condition on the ground")
    friction: float = Field(0.3, ge=0, description="Coulomb friction coefficient (type: friction)")


class BoxRegion(_Strict):
    box: Tuple[float, float, float, float, float, float] = Field(description="[x0, y0, z0, x1, y1, z1] in [0,1]^3")

    @field_validator("box")
    @classmethod
    def _ordered(cls, b):
        if not all(b[i] < b[i + 3] for i in range(3)):
            raise ValueError("box must be [x0, y0, z0, x1, y1, z1] with each min below its max")
        return b


class SphereRegion(_Strict):
    sphere: Tuple[float, float, float, float] = Field(description="[cx, cy, cz, radius] in the normalised box")

    @field_validator("sphere")
    @classmethod
    def _positive_radius(cls, s):
        if s[3] <= 0:
            raise ValueError("sphere radius must be positive")
        return s


REGION_FORMS = "'all', {box: [x0, y0, z0, x1, y1, z1]} or {sphere: [cx, cy, cz, radius]} in the object's [0,1]^3 box"


def _parse_region(value: Any) -> Union[str, BoxRegion, SphereRegion]:
    """One clear message for every malformed region, instead of one per union member."""
    if value == "all" or isinstance(value, (BoxRegion, SphereRegion)):
        return value
    kinds = {"box": BoxRegion, "sphere": SphereRegion}
    if isinstance(value, dict) and len(value) == 1 and next(iter(value)) in kinds:
        try:
            return kinds[next(iter(value))].model_validate(value)
        except ValidationError as err:
            raise ValueError(f"region must be {REGION_FORMS}; this {next(iter(value))} is not "
                             f"({err.errors()[0]['msg'].lower()})") from None
    raise ValueError(f"region must be {REGION_FORMS}, got {value!r}")


Region = Annotated[Union[Literal["all"], BoxRegion, SphereRegion], BeforeValidator(_parse_region)]


class _Condition(_Strict):
    object: int = Field(0, ge=0, description="index into objects")
    region: Region = Field("all", description=REGION_FORMS)
    frame: Literal["gravity", "camera"] = Field(
        "gravity", description="frame of the vector and the region box. gravity: x the picture's right made "
        "horizontal, y down along gravity, z horizontal away from the camera (the camera frame when the camera "
        "is level); camera: x right, y down, z along the camera's view")


class _Windowed(_Condition):
    start_s: float = Field(0.0, ge=0, description="start of the window in seconds")
    end_s: Optional[float] = Field(None, description="end of the window in seconds; null: until the end")

    @model_validator(mode="after")
    def _ordered(self):
        if self.end_s is not None and self.end_s <= self.start_s:
            raise ValueError("end_s must be after start_s")
        return self


class Impulse(_Condition):
    type: Literal["impulse"]
    velocity: Vec3 = Field(description="velocity change in m/s, added once at start_s")
    start_s: float = Field(0.0, ge=0, description="time of the impulse in seconds")


class Velocity(_Windowed):
    """Moves the region at a prescribed velocity during the window. On a rigid body the whole body follows it
    (the rigid motion that best gives the region that velocity), turning freely about the region where it is
    one point or one line of particles, as `fixed` does."""

    type: Literal["velocity"]
    velocity: Vec3 = Field(description="prescribed velocity of the region in m/s during the window")


class Force(_Windowed):
    type: Literal["force"]
    force: Vec3 = Field(description="total force in newtons, shared by mass over the region")


class Torque(_Windowed):
    type: Literal["torque"]
    torque: Vec3 = Field(description="torque in N m about the region's centre of mass")


class Fixed(_Windowed):
    """Holds the region still during the window. On a rigid body the region holds the whole body: held over an
    area or a volume it cannot move; held at one point (a region with one particle) it swings about that point
    as on a pin, and held along one line of particles it turns about that line as on a hinge."""

    type: Literal["fixed"]


Condition = Annotated[Union[Impulse, Velocity, Force, Torque, Fixed], Field(discriminator="type")]


class PhysicsConfig(_Strict):
    duration_s: float = Field(1.0, gt=0, le=600, description="length of the video in seconds (at most 10 minutes)")
    fps: float = Field(24.0, ge=1, le=240, description="frames per second")
    gravity: Optional[Vec3] = Field(None, description="m/s^2; null: 9.81 down in the picture, turned by camera.pitch_deg")
    grid: int = Field(64, ge=8, le=512, description="grid cells along the longest side of the domain")
    particles_per_cell: int = Field(8, ge=1, le=64, description="interior fill density")
    ground: GroundConfig = GroundConfig()
    walls: bool = Field(False, description="close the domain with slip walls a quarter of the objects' size "
                        "around them; without walls only the ground stops anything, and what leaves the "
                        "simulation grid flies on freely")
    dt: Optional[float] = Field(None, gt=0, description="substep in seconds; null: from the CFL bound")
    max_substeps_per_frame: int = Field(20000, ge=1, description="refuse a run whose CFL bound (stiffness, speed, "
                                        "physics.dt) asks for more substeps per frame than this, before it starts")
    conditions: List[Condition] = Field(default_factory=list, description="impulses, forces, torques, fixed regions")


class RenderConfig(_Strict):
    width: int = Field(512, ge=16, le=4096, description="video width in pixels (capped at the photo's, rounded even)")


class EnhanceConfig(_Strict):
    backend: Literal["flow", "diffusion"] = Field("flow", description="flow: photo pixels moved by the simulation")
    confidence_threshold: float = Field(0.5, ge=0, le=1,
                                        description="flow: trust the photograph where source_confidence is above this")
    hidden_surfaces: Literal["photo", "render"] = Field(
        "photo", description="flow: what surfaces the photograph never saw (the back, an opened interior) show. "
        "photo: the photograph read through the object at source_uv, the texture the reconstruction gave them, "
        "wherever it maps smoothly (source_coherence); render: the coarse render (the default under reconstruct.prior "
        "lgm, whose unseen surfaces have colours of their own)")
    relight: bool = Field(True, description="flow: re-shade the object for where its surface faces in each frame, "
                          "under one light fitted to the photograph; skipped when that light explains less than half "
                          "of the photograph's brightness")
    diffusion: DiffusionSettings = DiffusionSettings()


class Scene(_Strict):
    image: Path = Field(description="the photograph, relative to the scene folder")
    prompt: str = Field("", description="text prompt for the diffusion backend")
    camera: CameraConfig = CameraConfig()
    objects: List[ObjectConfig] = Field(default_factory=lambda: [ObjectConfig()], min_length=1)
    reconstruct: ReconstructConfig = ReconstructConfig()
    physics: PhysicsConfig = PhysicsConfig()
    render: RenderConfig = RenderConfig()
    enhance: EnhanceConfig = EnhanceConfig()

    @model_validator(mode="after")
    def _conditions_name_objects(self) -> "Scene":
        for i, c in enumerate(self.physics.conditions):
            if c.object >= len(self.objects):
                raise ValueError(f"physics.conditions[{i}].object is {c.object} but the scene has "
                                 f"{len(self.objects)} object(s), numbered from 0")
        return self

    # Filled in by load_scene; not part of the YAML.
    _file: Path = PrivateAttr(default=Path("scene.yaml"))

    @property
    def file(self) -> Path:
        """The scene.yaml this scene was loaded from."""
        return self._file

    @property
    def folder(self) -> Path:
        return self._file.parent


# ---------------------------------------------------------------------------
# Loading

class DuplicateKeyError(yaml.YAMLError):
    """A mapping gives the same key twice (YAML forbids it; PyYAML would keep the last silently)."""

    def __init__(self, key: Any, first_line: int, second_line: int):
        self.key, self.first_line, self.second_line = key, first_line, second_line
        super().__init__(f"key {key!r} on lines {first_line} and {second_line}")


class _Yaml12Loader(yaml.SafeLoader):
    """PyYAML speaks YAML 1.1, where `2e5` is a string; YAML 1.2 makes it a float.
    Duplicate keys are refused, as YAML 1.2 says, rather than the last one winning."""

    def construct_mapping(self, node, deep=False):
        if isinstance(node, yaml.MappingNode):
            first_line = {}
            for key_node, _ in node.value:
                if not isinstance(key_node, yaml.ScalarNode) or key_node.tag == "tag:yaml.org,2002:merge":
                    continue  # unhashable keys are PyYAML's own error; merged keys may be overridden
                key = self.construct_object(key_node)
                line = key_node.start_mark.line + 1
                if key in first_line:
                    raise DuplicateKeyError(key, first_line[key], line)
                first_line[key] = line
        return super().construct_mapping(node, deep)


_Yaml12Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?$|^[-+]?\.(?:inf|Inf|INF)$|^\.(?:nan|NaN|NAN)$"),
    list("-+0123456789."),
)  # appended after PyYAML's own int and float resolvers, so `2` stays an int


CONDITION_TYPES = tuple(get_args(c.model_fields["type"].annotation)[0] for c in (Impulse, Velocity, Force, Torque, Fixed))


def _loc_to_field(loc: Tuple[Any, ...]) -> str:
    """('objects', 0, 'material', 'jelly', 'density') -> 'objects[0].material.density'.

    pydantic puts the tag of a discriminated union into the path right after the field that
    holds it (a material, or an item of conditions); only there is it dropped, since a tag may
    also name a field (an impulse has a 'velocity')."""
    out, tags, previous = "", (), None
    for part in loc:
        if part in tags:
            tags = ()
            continue
        out += f"[{part}]" if isinstance(part, int) else ("." if out else "") + str(part)
        tags = PRESETS if part == "material" else CONDITION_TYPES if previous == "conditions" else ()
        previous = part
    return out


def _explain(err: dict) -> Tuple[str, str]:
    """A problem sentence and a fix sentence for one pydantic error."""
    kind, msg = err["type"], err["msg"]
    if kind == "extra_forbidden":
        return "unknown key", "remove it or check its spelling against docs/scene.schema.json"
    if kind == "missing":
        return "required key is missing", "add it (see docs/scene.schema.json)"
    if kind == "union_tag_invalid":
        return msg, "use one of the listed values"
    if kind == "finite_number":
        return "the value is infinite or not a number (.inf, .nan)", "give a finite number (see docs/scene.schema.json)"
    return msg.removeprefix("Value error, "), "see docs/scene.schema.json for the allowed values and units"


def _resolve_paths(scene: Scene, folder: Path) -> None:
    """Make every path absolute (relative to the scene folder) and check that it exists."""
    def check(path: Path, field: str) -> Path:
        full = path if path.is_absolute() else (folder / path)
        if full.is_dir():
            raise InputError(folder / "scene.yaml", field, f"'{path}' is a folder, not a file",
                             "give the path of the file inside it")
        if not full.is_file():
            raise InputError(folder / "scene.yaml", field, f"file '{path}' does not exist",
                             f"put the file in {folder} or correct the path")
        return full.resolve()

    scene.image = check(scene.image, "image")
    for k, obj in enumerate(scene.objects):
        if obj.mask is not None:
            obj.mask = check(obj.mask, f"objects[{k}].mask")
        if obj.hints is not None:
            obj.hints = check(obj.hints, f"objects[{k}].hints")
    for key in ("sam_model", "depth_model"):
        folder_path = getattr(scene.reconstruct, key)
        if folder_path is not None:
            full = folder_path if folder_path.is_absolute() else folder / folder_path
            if not full.is_dir():
                raise InputError(folder / "scene.yaml", f"reconstruct.{key}", f"model folder '{folder_path}' does "
                                 "not exist", "give the folder a transformers model was saved to (save_pretrained), "
                                 "or remove the key to use the built-in method")
            setattr(scene.reconstruct, key, full.resolve())
    if scene.reconstruct.init_ply is not None:
        scene.reconstruct.init_ply = check(scene.reconstruct.init_ply, "reconstruct.init_ply")
    for i, view in enumerate(scene.reconstruct.extra_views):
        view.image = check(view.image, f"reconstruct.extra_views[{i}].image")


MIN_PHOTO_PX = 16
"""Shorter side of the smallest photograph accepted: GrabCut needs background pixels around the object
(a 1x1 photograph failed inside OpenCV), and splat's tiles are 16 px."""


def _check_images(scene: Scene) -> None:
    """The photograph and masks must be readable, masks the photo's size and not empty, boxes inside."""
    import numpy as np

    from .images import read_image

    yaml_file = scene.file
    photo = read_image(scene.image)
    if photo is None:
        raise InputError(scene.image, None, "cannot read this file as an image",
                         "give a PNG or JPEG photograph in 'image' of " + str(yaml_file))
    h, w = photo.shape[:2]
    if min(h, w) < MIN_PHOTO_PX:
        raise InputError(scene.image, "image", f"the photograph is {w}x{h} pixels, below the {MIN_PHOTO_PX} px "
                         "that segmentation and reconstruction need on its shorter side",
                         f"give a photograph at least {MIN_PHOTO_PX}x{MIN_PHOTO_PX} pixels in 'image' of {yaml_file}")
    for k, obj in enumerate(scene.objects):
        if obj.box is not None:
            x0, y0, x1, y1 = obj.box
            if x0 < 0 or y0 < 0 or x1 > w or y1 > h:
                raise InputError(yaml_file, f"objects[{k}].box", f"box {list(obj.box)} reaches outside the "
                                 f"{w}x{h} image", f"keep 0 <= x <= {w} and 0 <= y <= {h}")
        if obj.mask is not None:
            mask = read_image(obj.mask)
            if mask is None:
                raise InputError(obj.mask, None, "cannot read this file as an image",
                                 f"give a PNG mask in objects[{k}].mask of {yaml_file}")
            if mask.shape[:2] != (h, w):
                raise InputError(obj.mask, f"objects[{k}].mask", f"mask is {mask.shape[1]}x{mask.shape[0]} but the "
                                 f"photograph is {w}x{h}", "make the mask exactly the photograph's size")
            if not np.any(mask):
                raise InputError(obj.mask, f"objects[{k}].mask", "mask is empty (all zero)",
                                 "paint the object non-zero in the mask, or use a box instead")
        if obj.hints is not None:
            hints = read_image(obj.hints)
            if hints is None or hints.shape[:2] != (h, w):
                found = "cannot be read as an image" if hints is None else f"is {hints.shape[1]}x{hints.shape[0]}"
                raise InputError(obj.hints, f"objects[{k}].hints", f"hint image {found}, the photograph is {w}x{h}",
                                 "give a PNG of the photograph's size (pm-setup writes one), or remove the key")


def load_scene(path: Path | str, check_files: bool = True) -> Scene:
    """Read and validate a scene.yaml.

    Args:
        path: the scene.yaml, or its folder.
        check_files: also check that every referenced file exists and the images are consistent.

    Raises:
        InputError: naming the file, the field and the fix.
    """
    path = Path(path)
    if path.is_dir():
        path = path / "scene.yaml"
    if not path.is_file():
        raise InputError(path, None, "scene file does not exist", "give the path of a scene.yaml (or its folder)")
    try:
        raw = yaml.load(path.read_text(encoding="utf-8"), Loader=_Yaml12Loader)
    except UnicodeDecodeError as err:
        raise InputError(path, None, f"not UTF-8 text (byte {err.start} cannot be decoded)",
                         "save scene.yaml as UTF-8 text") from None
    except OSError as err:
        raise InputError(path, None, f"cannot be read ({err.strerror})", "check the file's permissions") from None
    except RecursionError:
        raise InputError(path, None, "the YAML is nested too deeply to read", "write the scene as in "
                         "scenes/*/scene.yaml: a few levels of mappings and lists") from None
    except DuplicateKeyError as err:
        raise InputError(path, str(err.key), f"key {str(err.key)!r} is given twice in one mapping, on line "
                         f"{err.first_line} and line {err.second_line}", "keep one of them") from None
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        raise InputError(path, None, f"YAML syntax error{where}: {getattr(err, 'problem', err)}",
                         "fix the YAML there (indentation, a missing colon or an unclosed bracket)") from None
    if not isinstance(raw, dict):
        raise InputError(path, None, "the file is not a YAML mapping", "start from scenes/*/scene.yaml")
    try:
        scene = Scene.model_validate(raw)
    except ValidationError as err:
        first = err.errors()[0]
        problem, fix = _explain(first)
        more = f" ({err.error_count() - 1} more problem(s) after this one)" if err.error_count() > 1 else ""
        raise InputError(path, _loc_to_field(first["loc"]), problem + more, fix) from None
    scene._file = path.resolve()
    if check_files:
        _resolve_paths(scene, scene.folder)
        _check_images(scene)
    return scene


# ---------------------------------------------------------------------------
# What each stage reads, and its hash

def stage_keys(scene: Scene, stage: str) -> dict:
    """The scene keys a stage reads (DESIGN.md); a rule reruns when, and only when, these change.

    simulate also reads camera.pitch_deg (it turns the default gravity); a change there
    reruns reconstruct anyway.
    """
    data = _relative_paths(scene.model_dump(mode="json"), str(scene.folder))
    if stage == "reconstruct":
        # hints only where given: a scene without hints hashes as if the key did not exist, so its results stay current
        # thickness only where given, likewise
        objs = [{k: o[k] for k in ("mask", "box", "size_m")} | ({"hints": o["hints"]} if o["hints"] else {})
                | ({"thickness_m": o["thickness_m"]} if o["thickness_m"] is not None else {})
                for o in data["objects"]]
        # prior only where not the default, likewise: results made before the key existed stay current
        reconstruct = {k: v for k, v in data["reconstruct"].items() if k != "prior" or v != "symmetric"}
        return {"image": data["image"], "camera": data["camera"], "objects": objs, "reconstruct": reconstruct}
    if stage == "simulate":
        return {"materials": [o["material"] for o in data["objects"]], "physics": data["physics"],
                "pitch_deg": data["camera"]["pitch_deg"]}
    if stage == "render":
        return {"render": data["render"]}
    if stage == "lora":  # trains on the object and the extra views
        return {"prompt": data["prompt"], "enhance": data["enhance"],
                "extra_views": data["reconstruct"]["extra_views"]}
    if stage in ("invert", "enhance"):
        return {"prompt": data["prompt"], "enhance": data["enhance"]}
    raise ValueError(f"unknown stage {stage!r}")


def _relative_paths(value: Any, folder: str) -> Any:
    """Paths inside the scene folder written relative to it, so hashes do not depend on the checkout's location."""
    if isinstance(value, dict):
        return {k: _relative_paths(v, folder) for k, v in value.items()}
    if isinstance(value, list):
        return [_relative_paths(v, folder) for v in value]
    if isinstance(value, str) and value.startswith(folder + "/"):
        return value[len(folder) + 1:]
    return value


def config_hash(keys: dict) -> str:
    """sha256 of the canonical JSON of ``keys`` (paths as given, sorted keys)."""
    return hashlib.sha256(json.dumps(keys, sort_keys=True, default=str).encode()).hexdigest()


def scene_json_schema() -> dict:
    """JSON Schema of scene.yaml, for editors and docs."""
    return Scene.model_json_schema()
