"""The HDF5 artifacts that cross stage boundaries, and the only code that touches h5py.

Each artifact is a pydantic model whose array fields carry an :class:`H5`
annotation: where the field lives in the file, its stored dtype and its shape in
named dimensions (``"T,P,3"``). One reader and one writer walk those
annotations, so the table in DESIGN.md and this module cannot drift apart.

Files are built in memory and written through :func:`schemas.files.write_file`
(a temporary name beside the target, renamed when complete), without timestamps,
so the same inputs give the same bytes. Float datasets hold finite numbers
(NaN only where a field's annotation says it marks "no value"); every artifact
records the sha256 of the artifacts it was made from (``inputs``), so that a
program can refuse a mix of files that do not belong together.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Annotated, Any, ClassVar, Dict, List, Optional, Type, TypeVar

import numpy as np
from pydantic import BaseModel, ConfigDict, model_validator

from .files import write_file
from .program import InputError
from .solid import solids_of


@dataclass(frozen=True)
class H5:
    """Where and how a field is stored.

    path: ``/group/dataset`` for a dataset, ``/group@name`` or ``@name`` for an attribute.
    dtype: numpy dtype of a dataset (attributes keep their Python type).
    shape: named dimensions, e.g. ``"T,h,w,3"``; a name must have one value across the artifact.
    frames: per-frame dataset, chunked one frame per chunk.
    gzip: compress (level 2) — frames only; particle arrays stay uncompressed.
    nan: NaN marks "no value" here (off the object, not evaluated); otherwise floats must be finite.
    """

    path: str
    dtype: Optional[str] = None
    shape: str = ""
    frames: bool = False
    gzip: bool = False
    nan: bool = False

    @property
    def is_attr(self) -> bool:
        return "@" in self.path


Array = np.ndarray
T = TypeVar("T", bound="Artifact")


class Artifact(BaseModel):
    """Base of every artifact: the fields with H5 annotations are the file's content."""

    model_config = ConfigDict(arbitrary_types_allowed=True, extra="forbid")
    SCHEMA: ClassVar[str]
    VERSION: ClassVar[int]
    NONEMPTY: ClassVar[tuple] = ()
    """Named dimensions that must not be 0 (an artifact of no Gaussians or no frames is no result)."""

    @classmethod
    def layout(cls) -> Dict[str, H5]:
        return {name: next(m for m in f.metadata if isinstance(m, H5))
                for name, f in cls.model_fields.items() if any(isinstance(m, H5) for m in f.metadata)}

    @model_validator(mode="after")
    def _cast_and_check_shapes(self):
        dims: Dict[str, int] = {}
        for name, spec in self.layout().items():
            value = getattr(self, name)
            if spec.dtype is None:
                continue
            arr = np.ascontiguousarray(value, dtype=spec.dtype)
            object.__setattr__(self, name, arr)
            names = spec.shape.split(",") if spec.shape else []
            if arr.ndim != len(names):
                raise ValueError(f"{type(self).__name__}.{name}: expected shape ({spec.shape}), got {arr.shape}")
            for dim, size in zip(names, arr.shape):
                if dim.isdigit():
                    if int(dim) != size:
                        raise ValueError(f"{type(self).__name__}.{name}: expected shape ({spec.shape}), got {arr.shape}")
                elif dims.setdefault(dim, size) != size:
                    raise ValueError(f"{type(self).__name__}.{name}: dimension {dim} is {size} here but "
                                     f"{dims[dim]} elsewhere in the artifact")
                if dim in self.NONEMPTY and size == 0:
                    raise ValueError(f"{spec.path} holds no {dim} (shape {spec.shape} = {arr.shape})")
        return self


def non_finite(value: Any, spec: H5) -> Optional[str]:
    """What is wrong with a float dataset or attribute that holds inf (or NaN where NaN is not allowed), or None."""
    arr = np.asarray(value)
    if arr.dtype.kind != "f":
        return None
    bad = np.isinf(arr) if spec.nan else ~np.isfinite(arr)
    if not bad.any():
        return None
    first = tuple(int(i) for i in np.argwhere(bad)[0]) if arr.ndim else ()
    return (f"{int(bad.sum())} of its {arr.size} values are {'infinite' if spec.nan else 'infinite or NaN'} "
            f"(the first {arr[first] if first else arr.item()} at index {list(first)})")


def _f(path: str, dtype: Optional[str] = None, shape: str = "", frames: bool = False, gzip: bool = False,
       nan: bool = False):
    return H5(path, dtype, shape, frames, gzip, nan)


class GaussiansArtifact(Artifact):
    """gaussians.h5, written by pm-reconstruct. G Gaussians; photo H x W."""

    SCHEMA: ClassVar[str] = "physmotion.gaussians"
    VERSION: ClassVar[int] = 3
    NONEMPTY: ClassVar[tuple] = ("G", "H", "W")

    K: Annotated[Array, _f("/camera/K", "f8", "3,3")]
    world_to_camera: Annotated[Array, _f("/camera/world_to_camera", "f8", "4,4")]
    width: Annotated[int, _f("/camera@width")]
    height: Annotated[int, _f("/camera@height")]
    means: Annotated[Array, _f("/gaussians/means", "f4", "G,3")]
    scales: Annotated[Array, _f("/gaussians/scales", "f4", "G,3")]
    rotations: Annotated[Array, _f("/gaussians/rotations", "f4", "G,4")]
    opacities: Annotated[Array, _f("/gaussians/opacities", "f4", "G")]
    colors: Annotated[Array, _f("/gaussians/colors", "f4", "G,3")]
    object_id: Annotated[Array, _f("/gaussians/object_id", "i4", "G")]
    photo: Annotated[Array, _f("/image/photo", "u1", "H,W,3", gzip=True)]
    mask: Annotated[Array, _f("/image/mask", "u1", "H,W", gzip=True)]
    background: Annotated[Array, _f("/image/background", "u1", "H,W,3", gzip=True)]
    depth_prior: Annotated[Array, _f("/image/depth_prior", "f4", "H,W", gzip=True, nan=True)]  # NaN off objects
    # Each object's solid (schemas/solid.py, SolidGrid), the body pm-simulate fills; NaN for an object without
    # one (init_ply, reconstruct.prior lgm), whose solid is its Gaussians'. distance: signed distance in m,
    # negative inside, at N^3 nodes; centre: the middle node, world frame, m; axes: rows the grid's directions
    # in the world frame (x horizontal, y against gravity, z = x cross y); spacing: m between nodes.
    solid_distance: Annotated[Array, _f("/objects/solid/distance", "f4", "O,N,N,N", gzip=True, nan=True)]
    solid_centre: Annotated[Array, _f("/objects/solid/centre", "f8", "O,3", nan=True)]
    solid_axes: Annotated[Array, _f("/objects/solid/axes", "f8", "O,3,3", nan=True)]
    solid_spacing: Annotated[Array, _f("/objects/solid/spacing", "f8", "O", nan=True)]
    loss: Annotated[Array, _f("/optimization/loss", "f4", "iterations,terms", nan=True)]  # NaN: not evaluated
    loss_terms: Annotated[List[str], _f("/optimization/loss@terms")]

    def solids(self) -> list:
        """Per object its solid (schemas.solid.SolidGrid), None where it has none."""
        return solids_of(self.solid_distance, self.solid_centre, self.solid_axes, self.solid_spacing)


class TrajectoriesArtifact(Artifact):
    """trajectories.h5, written by pm-simulate. P particles (the G Gaussians first), T frames."""

    SCHEMA: ClassVar[str] = "physmotion.trajectories"
    VERSION: ClassVar[int] = 3
    NONEMPTY: ClassVar[tuple] = ("P", "G", "T")

    rest_positions: Annotated[Array, _f("/particles/rest_positions", "f4", "P,3")]
    volumes: Annotated[Array, _f("/particles/volumes", "f4", "P")]
    masses: Annotated[Array, _f("/particles/masses", "f4", "P")]
    material_id: Annotated[Array, _f("/particles/material_id", "i4", "P")]
    object_id: Annotated[Array, _f("/particles/object_id", "i4", "P")]
    is_gaussian: Annotated[Array, _f("/particles/is_gaussian", "bool", "P")]
    # m, the spacing of the lattice every object's fill particles lie on at rest (one for all objects)
    lattice_spacing: Annotated[float, _f("/particles@lattice_spacing")]
    positions: Annotated[Array, _f("/frames/positions", "f4", "T,P,3", frames=True)]
    F: Annotated[Array, _f("/frames/F", "f4", "T,P,3,3", frames=True)]
    time_s: Annotated[Array, _f("/diagnostics/time_s", "f8", "T")]
    substeps: Annotated[Array, _f("/diagnostics/substeps", "f8", "T")]
    kinetic_energy: Annotated[Array, _f("/diagnostics/kinetic_energy", "f8", "T")]
    potential_energy: Annotated[Array, _f("/diagnostics/potential_energy", "f8", "T")]
    momentum: Annotated[Array, _f("/diagnostics/momentum", "f8", "T,3")]
    angular_momentum: Annotated[Array, _f("/diagnostics/angular_momentum", "f8", "T,3")]
    max_speed: Annotated[Array, _f("/diagnostics/max_speed", "f8", "T")]
    fps: Annotated[float, _f("@fps")]
    duration_s: Annotated[float, _f("@duration_s")]


class CoarseArtifact(Artifact):
    """coarse.h5, written by pm-render. T frames of h x w pixels."""

    SCHEMA: ClassVar[str] = "physmotion.coarse"
    VERSION: ClassVar[int] = 3
    NONEMPTY: ClassVar[tuple] = ("T", "h", "w")

    rgb: Annotated[Array, _f("/frames/rgb", "u1", "T,h,w,3", frames=True, gzip=True)]
    alpha: Annotated[Array, _f("/frames/alpha", "f4", "T,h,w", frames=True, gzip=True)]
    depth: Annotated[Array, _f("/frames/depth", "f4", "T,h,w", frames=True, gzip=True)]
    source_uv: Annotated[Array, _f("/frames/source_uv", "f4", "T,h,w,2", frames=True, gzip=True, nan=True)]
    source_coherence: Annotated[Array, _f("/frames/source_coherence", "f4", "T,h,w", frames=True, gzip=True)]
    source_confidence: Annotated[Array, _f("/frames/source_confidence", "f4", "T,h,w", frames=True, gzip=True)]
    normal: Annotated[Array, _f("/frames/normal", "f4", "T,h,w,3", frames=True, gzip=True, nan=True)]
    K: Annotated[Array, _f("/camera/K", "f8", "3,3")]
    width: Annotated[int, _f("/camera@width")]
    height: Annotated[int, _f("/camera@height")]
    fps: Annotated[float, _f("/camera@fps")]


class LatentsArtifact(Artifact):
    """latents.h5, written by pm-invert: the DDIM+ inverted latents of every frame at every timestep."""

    SCHEMA: ClassVar[str] = "physmotion.latents"
    VERSION: ClassVar[int] = 1
    NONEMPTY: ClassVar[tuple] = ("T",)

    latents: Annotated[Array, _f("/latents", "f2", "T,steps_plus_1,4,h8,w8", frames=True, gzip=True)]
    timesteps: Annotated[Array, _f("/timesteps", "i8", "steps_plus_1")]
    scheduler: Annotated[str, _f("/latents@scheduler")]  # JSON of the scheduler's config
    prompt: Annotated[str, _f("/latents@prompt")]


# ---------------------------------------------------------------------------

def _version() -> str:
    try:
        return metadata.version("physmotion")
    except metadata.PackageNotFoundError:
        return "0+unknown"


def _split(path: str):
    """'/camera@width' -> ('/camera', 'width'); '@fps' -> ('/', 'fps')."""
    obj, name = path.split("@")
    return (obj or "/"), name


def write_artifact(path: Path | str, artifact: Artifact, *, created_by: str, config_hash: str,
                   inputs: Optional[Dict[str, Any]] = None) -> Path:
    """Write ``artifact`` to ``path`` atomically (schemas.files.write_file).

    Args:
        created_by: the program, e.g. "pm-simulate"; the package version is appended.
        config_hash: hash of the scene keys the artifact was made from.
        inputs: what it was made from, {"files": role or scene key -> sha256 of the file,
            "stages": stage -> config_hash of the stages before it} (:func:`check_lineage` returns it);
            stored as JSON in the root attribute ``inputs``. Every program gives it; its presence marks
            an artifact whose lineage the next programs check.

    Raises:
        ValueError: a float field holds inf, or NaN where NaN means nothing (a bug of the writing program).
        InputError: the disk is full or the folder not writable (nothing is left behind).
    """
    import h5py

    for name, spec in artifact.layout().items():
        problem = non_finite(getattr(artifact, name), spec)
        if problem:
            raise ValueError(f"{created_by} made {spec.path} of {Path(path).name} with {problem}")
    # The file is built in memory (the core driver, never backed by disk) and written by write_file:
    # libhdf5 writing to a full disk itself crashed the process (exit 139), leaving its temporary file.
    with h5py.File(f"{Path(path).name}-in-memory", "w", driver="core", backing_store=False,
                   track_order=False) as f:
        f.attrs["schema"] = artifact.SCHEMA
        f.attrs["schema_version"] = artifact.VERSION
        f.attrs["created_by"] = f"{created_by} (physmotion {_version()})"
        f.attrs["config_hash"] = config_hash
        if inputs is not None:
            f.attrs["inputs"] = json.dumps(inputs, sort_keys=True)
        layout = artifact.layout()
        for name, spec in layout.items():  # datasets first, so attributes find their objects
            if spec.is_attr:
                continue
            data = getattr(artifact, name)
            chunks = (1,) + data.shape[1:] if spec.frames and data.size else None
            f.create_dataset(spec.path, data=data, chunks=chunks, track_times=False,
                             compression="gzip" if spec.gzip else None,
                             compression_opts=2 if spec.gzip else None)
        for name, spec in layout.items():
            if not spec.is_attr:
                continue
            obj, attr = _split(spec.path)
            target = f.require_group(obj) if obj not in f else f[obj]
            value = getattr(artifact, name)
            target.attrs[attr] = np.array(value, dtype=h5py.string_dtype()) if isinstance(value, list) else value
        f.flush()
        image = f.id.get_file_image()
    return write_file(path, image)


def read_header(path: Path | str) -> Dict[str, Any]:
    """The root attributes (schema, schema_version, created_by, config_hash) of an artifact."""
    import h5py

    if Path(path).is_dir():
        raise InputError(path, None, "this is a folder, not an HDF5 file", "give the path of the file")
    try:
        with h5py.File(path, "r") as f:
            return {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()}
    except FileNotFoundError:
        raise InputError(path, None, "file does not exist", "run the stage that writes it first") from None
    except OSError as err:
        raise InputError(path, None, f"not a readable HDF5 file ({err})",
                         "delete it and rerun the stage that writes it") from None


def read_artifact(path: Path | str, cls: Type[T]) -> T:
    """Read and validate an artifact of type ``cls``.

    Raises:
        InputError: the file is missing, not HDF5, of another schema or version, or incomplete;
            the message names the program that wrote it.
    """
    import h5py

    path = Path(path)
    header = read_header(path)
    writer = header.get("created_by", "an unknown program")
    schema, version = header.get("schema"), header.get("schema_version")
    if schema != cls.SCHEMA:
        raise InputError(path, "schema", f"this is a '{schema}' file written by {writer}, not '{cls.SCHEMA}'",
                         "pass the right file (check the argument order)")
    if version != cls.VERSION:
        raise InputError(path, "schema_version", f"schema version {version} (written by {writer}) but this program "
                         f"reads version {cls.VERSION}", "rerun the stage that writes it with this physmotion version")
    values: Dict[str, Any] = {}
    with h5py.File(path, "r") as f:
        for name, spec in cls.layout().items():
            try:
                if spec.is_attr:
                    obj, attr = _split(spec.path)
                    value = f[obj].attrs[attr]
                    if isinstance(value, np.ndarray):
                        value = [v.decode() if isinstance(v, bytes) else str(v) for v in value]
                    elif isinstance(value, bytes):
                        value = value.decode()
                    elif isinstance(value, np.generic):
                        value = value.item()
                    values[name] = value
                else:
                    values[name] = f[spec.path][()]
            except KeyError:
                raise InputError(path, spec.path, f"missing from this file written by {writer}",
                                 "delete it and rerun the stage that writes it") from None
            problem = non_finite(values[name], spec)
            if problem:
                raise InputError(path, spec.path, f"{problem}, in this file written by {writer}",
                                 "delete it and rerun the stage that writes it")
    try:
        return cls(**values)
    except ValueError as err:
        raise InputError(path, None, f"inconsistent content written by {writer}: {err}",
                         "delete it and rerun the stage that writes it") from None


def scheduler_json(config: Dict[str, Any]) -> str:
    """Canonical JSON for LatentsArtifact.scheduler."""
    return json.dumps(config, sort_keys=True, default=str)


# ---------------------------------------------------------------------------
# Lineage: which files an artifact was made from

ROLE_STAGE = {"gaussians": "reconstruct", "trajectories": "simulate", "coarse": "render", "latents": "invert"}
"""Each artifact's role and the stage whose scene keys it was made from (its config_hash)."""


def file_digest(path: Path | str) -> str:
    """sha256 (hex) of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def check_lineage(scene, **given: Optional[Path]) -> Dict[str, Any]:
    """Refuse artifacts that do not belong together or to ``scene``; return the record of what they are.

    Every artifact given (role=path: gaussians, trajectories, coarse, latents; None is skipped) that
    holds a lineage record (``inputs``, written by every program) must record the sha256 of each other
    given artifact it was made from, and its own config_hash and those of every stage before it must be
    those of ``scene``'s keys now. Artifacts without a record (made by other tools) are taken as they are.

    Returns:
        The record for an artifact made from the given ones (write_artifact's ``inputs``):
        {"files": role -> sha256, "stages": stage -> config_hash of every stage before it}.
    Raises:
        InputError: naming both files, or the artifact and scene.yaml, and what to rerun.
    """
    from .scene import config_hash, stage_keys

    paths = {role: Path(p) for role, p in given.items() if p is not None}
    headers = {role: read_header(p) for role, p in paths.items()}
    digests = {role: file_digest(p) for role, p in paths.items()}
    stages: Dict[str, str] = {}
    for role, header in headers.items():
        if "inputs" not in header or header.get("schema") != f"physmotion.{role}":
            continue  # no record; or a file of another kind, which read_artifact refuses as such
        record = json.loads(header["inputs"])
        for source, digest in record["files"].items():
            if source in digests and digests[source] != digest:
                raise InputError(paths[role], "inputs", f"this {role}.h5 was made from another {source}.h5 than "
                                 f"{paths[source]} (sha256 {digest[:12]}..., that file's {digests[source][:12]}...)",
                                 f"pass the {source}.h5 it was made from, or rerun the stages after "
                                 f"{ROLE_STAGE[source]} so that the files belong together")
        made_from = {**record["stages"], ROLE_STAGE[role]: header.get("config_hash")}
        for stage, recorded in made_from.items():
            if recorded != config_hash(stage_keys(scene, stage)):
                raise InputError(paths[role], "config_hash", f"this {role}.h5 was made from other {stage} keys "
                                 f"than {scene.file} holds now (another scene, or the scene edited since)",
                                 f"rerun pm-{stage} and the stages after it on this scene, or pass the scene it "
                                 "was made from")
        stages.update(made_from)
    return {"files": digests, "stages": stages}
