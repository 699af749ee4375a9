"""scene.yaml and its hint images as pm-setup reads and writes them.

Writes are atomic (a temporary file beside the target, renamed when complete) and checked by
schemas.load_scene before the rename, so a scene folder never holds a scene the pipeline refuses.
The page edits a plain mapping: every key the file holds is kept, also those the page has no
control for; the comment lines at the top of the file are kept too.
"""
from __future__ import annotations

import base64
import os
from pathlib import Path
from typing import Optional

import cv2
import numpy as np
import yaml

from schemas import InputError, load_scene
from schemas.images import HINT_BACKGROUND, HINT_OBJECT
from schemas.scene import _Yaml12Loader

SCENE_FILE = "scene.yaml"
MAX_IMAGE_BYTES = 40 * 2**20
"""Largest upload (photograph or hint image) the server takes; a 50 MP JPEG is about 20 MB."""
MAX_IMAGE_PIXELS = 80_000_000
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")


def read_raw(folder: Path) -> tuple[dict, str]:
    """The scene.yaml of ``folder`` as a plain mapping and its leading comment lines ({} and '' when absent)."""
    path = folder / SCENE_FILE
    if not path.is_file():
        return {}, ""
    text = path.read_text()
    try:
        raw = yaml.load(text, Loader=_Yaml12Loader)
    except yaml.YAMLError:
        raw = None  # load_scene names the line; the page shows its message
    return (raw if isinstance(raw, dict) else {}), leading_comments(text)


def leading_comments(text: str) -> str:
    """The comment lines a scene.yaml starts with (the examples say there what the scene is)."""
    lines = []
    for line in text.splitlines(keepends=True):
        if not line.startswith("#"):
            break
        lines.append(line)
    return "".join(lines)


class _Dumper(yaml.SafeDumper):
    """Block style for mappings, flow style for short lists of numbers (boxes, vectors), as the examples are written."""


def _represent_list(dumper: yaml.SafeDumper, data: list):
    flow = all(isinstance(v, (int, float, str)) for v in data) and len(data) <= 8
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=flow)


def _represent_dict(dumper: yaml.SafeDumper, data: dict):
    # a condition or a material on one line: {type: impulse, velocity: [...]} reads like the examples
    flow = all(not isinstance(v, dict) or len(v) == 1 for v in data.values()) and ("type" in data or "preset" in data)
    return dumper.represent_mapping("tag:yaml.org,2002:map", data.items(), flow_style=flow or None)


_Dumper.add_representer(list, _represent_list)
_Dumper.add_representer(dict, _represent_dict)


def dump_scene(raw: dict, header: str = "") -> str:
    """YAML text of a scene mapping, keys in the order given."""
    return header + yaml.dump(raw, Dumper=_Dumper, sort_keys=False, allow_unicode=True, width=110)


def atomic_write(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.partial-{os.getpid()}")
    try:
        tmp.write_bytes(data)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def check_scene(folder: Path, raw: dict, check_files: bool = True) -> Optional[InputError]:
    """The loader's error for this mapping as the folder's scene.yaml, None when it accepts it."""
    tmp = folder / f".{SCENE_FILE}.check-{os.getpid()}"
    try:
        tmp.write_text(dump_scene(raw))
        load_scene(tmp, check_files=check_files)
    except InputError as err:
        err.file = str(folder / SCENE_FILE) if Path(err.file) == tmp else err.file
        return err
    finally:
        tmp.unlink(missing_ok=True)
    return None


def without_empty_sections(value):
    """``value`` less the empty mappings inside mappings (a section the page opened but left at its defaults);
    list items stay, since `objects: [{}]` is one object with every default."""
    if isinstance(value, dict):
        pruned = {k: without_empty_sections(v) for k, v in value.items()}
        return {k: v for k, v in pruned.items() if not (isinstance(v, dict) and not v)}
    if isinstance(value, list):
        return [without_empty_sections(v) for v in value]
    return value


def save_scene(folder: Path, raw: dict, header: str = "") -> dict:
    """Write ``raw`` (less its empty sections) as the folder's scene.yaml, atomically, after load_scene accepted it.

    Returns:
        the mapping written.
    Raises:
        InputError: the loader's, and scene.yaml is left as it was.
    """
    raw = without_empty_sections(raw)
    error = check_scene(folder, raw)
    if error is not None:
        raise error
    atomic_write(folder / SCENE_FILE, dump_scene(raw, header).encode())
    return raw


def decode_image(data: bytes, what: str) -> np.ndarray:
    """An uploaded image (PNG or JPEG bytes) decoded with its alpha, after the size checks.

    Raises:
        InputError: too large, or not an image.
    """
    if len(data) > MAX_IMAGE_BYTES:
        raise InputError(what, None, f"upload of {len(data) / 2**20:.1f} MB is over the {MAX_IMAGE_BYTES // 2**20} MB "
                         "limit", "send a smaller image")
    header = data[:8]
    if not (header.startswith(b"\x89PNG\r\n\x1a\n") or header.startswith(b"\xff\xd8\xff")):
        raise InputError(what, None, "this is not a PNG or JPEG file", "send a PNG or JPEG image")
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if image is None or image.size == 0:
        raise InputError(what, None, "the file cannot be decoded as an image", "send a complete PNG or JPEG image")
    if image.shape[0] * image.shape[1] > MAX_IMAGE_PIXELS:
        raise InputError(what, None, f"{image.shape[1]}x{image.shape[0]} pixels is over the limit of "
                         f"{MAX_IMAGE_PIXELS // 10**6} MP", "send a smaller image")
    return image


def data_url_bytes(url: str, what: str) -> bytes:
    """The bytes of a ``data:image/png;base64,...`` URL as the page's canvas writes it."""
    prefix, _, payload = url.partition(",")
    if not prefix.startswith("data:image/") or not prefix.endswith(";base64"):
        raise InputError(what, None, "expected a base64 data URL of an image", "send canvas.toDataURL('image/png')")
    if len(payload) > MAX_IMAGE_BYTES * 4 // 3 + 4:
        raise InputError(what, None, "upload is over the size limit", "send a smaller image")
    return base64.b64decode(payload, validate=True)


def hint_image(strokes: np.ndarray) -> np.ndarray:
    """The hints file (H,W,4) BGRA of the page's stroke image (H,W,4): object strokes white, background black.

    The page paints object strokes green and background strokes red (alpha above 127 marks a stroke)."""
    out = np.zeros(strokes.shape[:2] + (4,), np.uint8)
    painted = strokes[..., 3] > 127 if strokes.shape[2] == 4 else np.zeros(strokes.shape[:2], bool)
    green_over_red = strokes[..., 1].astype(int) >= strokes[..., 2].astype(int)  # BGR: 1 green, 2 red
    out[painted & green_over_red] = HINT_OBJECT
    out[painted & ~green_over_red] = HINT_BACKGROUND
    return out


def hints_name(k: int) -> str:
    return f"hints_{k}.png"


def encode_png(image: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", image)
    assert ok
    return buf.tobytes()


def set_hints(folder: Path, raw: dict, k: int, strokes: Optional[np.ndarray], photo_shape: tuple[int, int]) -> None:
    """Write object k's hint image (or drop the key when there are no strokes) and point objects[k].hints at it."""
    obj = raw["objects"][k]
    if strokes is None or not (strokes.shape[2] == 4 and (strokes[..., 3] > 127).any()):
        obj.pop("hints", None)
        return
    if strokes.shape[:2] != photo_shape:
        raise InputError(hints_name(k), f"objects[{k}].hints", f"hint image is {strokes.shape[1]}x{strokes.shape[0]}"
                         f", the photograph {photo_shape[1]}x{photo_shape[0]}", "reload the page")
    atomic_write(folder / hints_name(k), encode_png(hint_image(strokes)))
    obj["hints"] = hints_name(k)

