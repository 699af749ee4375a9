# The workflow's helpers (no rules): its configuration, the scenes, and the input and params functions.
import os
import re
import shlex
import sys
from importlib.metadata import version
from pathlib import Path

from snakemake.exceptions import WorkflowError
from snakemake.utils import validate

from schemas import InputError, config_hash, load_scene, stage_keys

def config_paragraph(err):
    """One paragraph for a --config that its schema refuses (snakemake's WorkflowError around jsonschema's)."""
    cause = err.__context__  # jsonschema's ValidationError, raised while snakemake handled it
    if not hasattr(cause, "schema"):
        return str(err)
    if not cause.path:  # a key the schema does not know
        return (f"error in --config (workflow/config.schema.yaml): {cause.message}. "
                f"Fix: use only the keys {', '.join(cause.schema.get('properties', {}))}.")
    key = ".".join(map(str, cause.path))
    described = cause.schema.get("description", "").strip()
    return (f"error in --config (workflow/config.schema.yaml), key '{key}': {cause.message}. "
            f"Fix: give {key} a value the schema allows" + (f" ({described})" if described else "") + ".")


# The keys of --config, checked and given their defaults by the schema (workflow/config.schema.yaml).
try:
    validate(config, "../config.schema.yaml")
except WorkflowError as err:
    raise WorkflowError(config_paragraph(err)) from None

envvars:
    "PATH",


# The stage programs are installed beside snakemake (.venv/bin): rules find them there without the
# venv being activated. Inside a stage image they are on the image's own PATH.
STAGE_BIN = Path(sys.executable).parent
if (STAGE_BIN / "pm-reconstruct").exists():
    os.environ["PATH"] = f"{STAGE_BIN}{os.pathsep}{os.environ['PATH']}"

SCENES = Path(str(config["scenes_dir"]))
RESULTS = Path(str(config["results_dir"]))
DEVICE = config["device"]
GPU = config["gpu"]
IMAGES = config["images"]

SCENE_NAMES = sorted(p.parent.name for p in SCENES.glob("*/scene.yaml"))
if not SCENE_NAMES:
    raise WorkflowError(f"no scene folders with a scene.yaml under '{SCENES}'. "
                        "Fix: point --config scenes_dir=DIR at a folder of scenes (see scenes/ for examples).")


def load_scenes(names):
    """({name: Scene} of the scenes that load, {name: the loader's one-paragraph message} of those refused)."""
    loaded, refused = {}, {}
    for name in names:
        try:
            loaded[name] = load_scene(SCENES / name / "scene.yaml")
        except InputError as err:
            refused[name] = err.paragraph()
    return loaded, refused


# A bad scene becomes one failing job (the refused one) instead of stopping the whole DAG: the others run.
LOADED, REFUSED = load_scenes(SCENE_NAMES)


def one_of(names):
    """A wildcard constraint matching exactly these names (spaces, brackets, dots, unicode escaped)."""
    return "|".join(re.escape(name) for name in names) or "(?!)"


def scene(name):
    """The validated scene of a good scene folder."""
    return LOADED[name]


def scene_yaml(wildcards):
    return str(SCENES / wildcards.scene / "scene.yaml")


def keys_hash(stage):
    """A params function: the hash of the keys `stage` reads from this scene."""
    return lambda wildcards: config_hash(stage_keys(scene(wildcards.scene), stage))


def image(stage):
    """The container image of a stage folder; its tag is this package's version, as in the README's docker build."""
    return f"{IMAGES}/{stage}:{version('physmotion')}"


def uses_diffusion(name):
    return scene(name).enhance.backend == "diffusion"


def reconstruct_inputs(wildcards):
    """The files reconstruct reads besides scene.yaml: photograph, masks, hint images, initial PLY, extra views."""
    s = scene(wildcards.scene)
    files = [s.image] + [o.mask for o in s.objects if o.mask is not None] + [o.hints for o in s.objects if o.hints]
    files += [s.reconstruct.init_ply] if s.reconstruct.init_ply else []
    return [str(f) for f in files + [v.image for v in s.reconstruct.extra_views]]


def lora_dir(wildcards):
    """The LoRA folder when the scene asks for personalisation, else nothing."""
    s = scene(wildcards.scene)
    wanted = uses_diffusion(wildcards.scene) and s.enhance.diffusion.lora.enabled
    return [str(RESULTS / wildcards.scene / "lora")] if wanted else []


def artifacts_and_lora(*names, latents=False):
    """Input function: this scene's named artifacts (+ latents.h5 when diffusion), + the LoRA folder when enabled."""
    def inputs(wildcards):
        wanted = list(names) + (["latents"] if latents and uses_diffusion(wildcards.scene) else [])
        files = {name: str(RESULTS / wildcards.scene / f"{name}.h5") for name in wanted}
        files.update({"lora": folder for folder in lora_dir(wildcards)})
        return files
    return inputs


def optional_flag(flag, files):
    """' --flag path' for a present optional input, '' otherwise."""
    return lambda wildcards, input: f" {flag} {shlex.quote(input[files])}" if files in input.keys() else ""


def refuse(paragraph, log):
    """The refused job: the scene's one paragraph in its log and in the job's error, then the job fails."""
    Path(log).parent.mkdir(parents=True, exist_ok=True)
    Path(log).write_text(paragraph + "\n")
    raise WorkflowError(paragraph)
