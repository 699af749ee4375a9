"""The pm-setup server: one page, the scene folder's files, and a small JSON API.

It serves the page's own assets (static/) and files inside the scene folder, nothing else:
a path with '..', an absolute path or one that resolves (through a link) outside the folder is
refused. Uploads are limited to scene_file.MAX_IMAGE_BYTES and must decode as PNG or JPEG.
"""
from __future__ import annotations

import base64
import contextlib
import json
import os
import re
import tempfile
from pathlib import Path
from typing import Optional

import numpy as np
from starlette.applications import Starlette
from starlette.concurrency import run_in_threadpool
from starlette.requests import Request
from starlette.responses import FileResponse, JSONResponse, Response
from starlette.routing import Route

from schemas import InputError, Scene
from stages.reconstruct.segment import ObjectSpec, SamSegmenter, read_photo, segment_objects

from . import scene_file as sf
from .preview import Preview

STATIC = Path(__file__).resolve().parent / "static"
ASSETS = ("index.html", "app.js", "forms.js", "draw.js", "style.css")


def safe_file(root: Path, relative: str) -> Optional[Path]:
    """``relative`` as a file inside ``root``, or None: no '..', no absolute path, no way out through a link."""
    if not relative or "\\" in relative or "\0" in relative or relative.startswith("/"):
        return None
    parts = Path(relative).parts
    if any(part in ("..", "") for part in parts) or Path(relative).is_absolute():
        return None
    root = root.resolve()
    full = (root / relative).resolve()
    return full if full.is_relative_to(root) and full.is_file() else None


def error_json(err: InputError, status: int = 422) -> JSONResponse:
    return JSONResponse({"error": {"field": err.field, "message": err.paragraph()}}, status_code=status)


class SetupApp:
    """The state behind the page: the scene folder, its photograph and the preview."""

    def __init__(self, folder: Path, device: str = "cpu"):
        self.folder, self.device = folder.resolve(), device
        self.raw, self.header = sf.read_raw(self.folder)
        self.preview = Preview()
        self._photo_cache: tuple[Optional[Path], Optional[tuple]] = (None, None)
        self._sam: tuple[Optional[Path], Optional[SamSegmenter]] = (None, None)

    # -- helpers -----------------------------------------------------------------------------------------------

    def photo(self) -> Optional[tuple[np.ndarray, Optional[np.ndarray]]]:
        """(RGB, alpha) of the scene's photograph, read once per file."""
        name = self.raw.get("image")
        path = safe_file(self.folder, name) if isinstance(name, str) else None
        if path is None:
            return None
        if self._photo_cache[0] != path:
            self._photo_cache = (path, read_photo(path))
        return self._photo_cache[1]

    def sam(self) -> Optional[SamSegmenter]:
        """pm-reconstruct's SAM where reconstruct.sam_model or $PHYSMOTION_SAM_MODEL names a local model, else None.

        Raises:
            InputError: the folder holds no model, or transformers is not installed.
        """
        named = (self.raw.get("reconstruct") or {}).get("sam_model") or os.environ.get("PHYSMOTION_SAM_MODEL")
        if not named:
            return None
        folder = Path(named) if Path(named).is_absolute() else (self.folder / named).resolve()
        if self._sam[0] != folder:
            try:
                self._sam = (folder, SamSegmenter(folder))
            except ImportError:
                raise InputError(folder, "reconstruct.sam_model", "SAM needs transformers, which is not installed",
                                 "pip install 'physmotion[reconstruct]', or remove the key to use GrabCut") from None
        return self._sam[1]

    def use_photo(self, name: str) -> None:
        """Make the file ``name`` of the folder the scene's photograph (a new scene: one object, all defaults)."""
        if self.raw.get("image") == name:
            return
        self.raw = {**self.raw, "image": name} if self.raw else {"image": name, "objects": [{}]}
        # boxes, masks and hints belong to the old photograph
        self.raw["objects"] = [{k: v for k, v in o.items() if k not in ("box", "mask", "hints")}
                               for o in self.raw.get("objects") or [{}]]

    def scene_state(self) -> dict:
        photo = self.photo()
        error = sf.check_scene(self.folder, self.raw) if self.raw else None
        hints = {k: f"/files/{o['hints']}" for k, o in enumerate(self.raw.get("objects") or [])
                 if isinstance(o, dict) and isinstance(o.get("hints"), str) and safe_file(self.folder, o["hints"])}
        return {"scene": self.raw, "schema": Scene.model_json_schema(), "folder": str(self.folder),
                "photo": None if photo is None else {"url": f"/files/{self.raw['image']}",
                                                     "width": photo[0].shape[1], "height": photo[0].shape[0]},
                "hints": hints, "saved": (self.folder / sf.SCENE_FILE).is_file(),
                "error": None if error is None else {"field": error.field, "message": error.paragraph()}}

    # -- routes ------------------------------------------------------------------------------------------------

    async def index(self, request: Request) -> Response:
        return FileResponse(STATIC / "index.html")

    async def asset(self, request: Request) -> Response:
        name = request.path_params["name"]
        return FileResponse(STATIC / name) if name in ASSETS else Response("not found", 404)

    async def files(self, request: Request) -> Response:
        path = safe_file(self.folder, request.path_params["path"])
        if path is None:
            return Response("not found", 404)
        return FileResponse(path, headers={"Cache-Control": "no-store"})

    async def preview_file(self, request: Request) -> Response:
        name = request.path_params["name"]
        if self.preview.workdir is None or not re.fullmatch(r"(frame_\d{3}|setup)\.png", name):
            return Response("not found", 404)
        path = safe_file(self.preview.workdir, name)
        return FileResponse(path, headers={"Cache-Control": "no-store"}) if path else Response("not found", 404)

    async def get_scene(self, request: Request) -> Response:
        return JSONResponse(self.scene_state())

    async def upload_photo(self, request: Request) -> Response:
        """The body is the image file; ?name= its file name (a plain name, kept in the scene folder)."""
        name = Path(request.query_params.get("name", "photo.png")).name
        if Path(name).suffix.lower() not in sf.IMAGE_SUFFIXES or name.startswith("."):
            return error_json(InputError(name, None, "not a .png, .jpg or .jpeg file name", "upload a PNG or JPEG"), 400)
        data = await _body(request)
        try:
            sf.decode_image(data, name)
        except InputError as err:
            return error_json(err, 413 if len(data) > sf.MAX_IMAGE_BYTES else 400)
        sf.atomic_write(self.folder / name, data)
        self.use_photo(name)
        return JSONResponse(self.scene_state())

    async def mask(self, request: Request) -> Response:
        """Body {object: k, box: [x0,y0,x1,y1] | null, mask: name | null, hints: dataURL | null}: the mask pm-reconstruct
        would make for this object alone, as a PNG data URL, its pixel count and bounding box."""
        body = await _json(request)
        if isinstance(body, Response):
            return body
        photo = self.photo()
        if photo is None:
            return error_json(InputError("scene.yaml", "image", "the scene has no photograph", "open one first"))
        k = int(body.get("object", 0))
        try:
            with tempfile.TemporaryDirectory() as tmp:
                hints = None
                if body.get("hints"):
                    strokes = sf.decode_image(sf.data_url_bytes(body["hints"], "hints"), "hints")
                    if strokes.ndim == 3 and strokes.shape[2] == 4 and (strokes[..., 3] > 127).any():
                        hints = Path(tmp) / "hints.png"
                        hints.write_bytes(sf.encode_png(sf.hint_image(strokes)))
                mask = self.folder / body["mask"] if body.get("mask") and safe_file(self.folder, body["mask"]) else None
                box = tuple(float(v) for v in body["box"]) if body.get("box") else None
                spec = ObjectSpec(mask=mask, box=box, hints=hints)
                sam = self.sam() if box is not None and hints is None else None
                labels = await run_in_threadpool(segment_objects, photo[0], photo[1], [spec], "scene.yaml", sam)
        except InputError as err:
            if err.field and err.field.startswith("objects[0]"):  # the one object segmented here is object k
                err.field = f"objects[{k}]" + err.field[len("objects[0]"):]
            return error_json(err)
        inside = labels > 0
        ys, xs = np.nonzero(inside)
        method = ("the mask file" if mask else "SAM in the box" if sam else "GrabCut in the box" if box else
                  "the photograph's alpha" if photo[1] is not None and hints is None else "GrabCut on the whole photograph")
        png = sf.encode_png(inside.astype(np.uint8) * 255)
        return JSONResponse({"mask": "data:image/png;base64," + base64.b64encode(png).decode(),
                             "pixels": int(inside.sum()), "method": method,
                             "bbox": [int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1]})

    async def check(self, request: Request) -> Response:
        """The loader's first complaint about the page's scene, without saving (files not checked)."""
        body = await _json(request)
        if isinstance(body, Response):
            return body
        error = sf.check_scene(self.folder, body.get("scene") or {}, check_files=False)
        return JSONResponse({"error": None if error is None else {"field": error.field, "message": error.paragraph()}})

    async def save(self, request: Request) -> Response:
        """Body {scene: mapping, hints: {k: dataURL | null}}: hint images written, then scene.yaml, atomically."""
        body = await _json(request)
        if isinstance(body, Response):
            return body
        raw = body.get("scene")
        photo = self.photo()
        if not isinstance(raw, dict) or photo is None:
            return error_json(InputError("scene.yaml", None, "no scene or no photograph to save", "open a photograph"))
        try:
            for key, url in (body.get("hints") or {}).items():
                k = int(key)
                strokes = sf.decode_image(sf.data_url_bytes(url, "hints"), sf.hints_name(k)) if url else None
                if 0 <= k < len(raw.get("objects") or []):
                    sf.set_hints(self.folder, raw, k, strokes, photo[0].shape[:2])
            self.raw = await run_in_threadpool(sf.save_scene, self.folder, raw, self.header)
        except InputError as err:
            return error_json(err)
        return JSONResponse(self.scene_state())

    async def start_preview(self, request: Request) -> Response:
        if not (self.folder / sf.SCENE_FILE).is_file():
            return error_json(InputError("scene.yaml", None, "the scene is not saved yet", "save it first"))
        self.preview.start(sf.read_raw(self.folder)[0], self.folder, self.device)
        return JSONResponse(self.preview.status())

    async def preview_status(self, request: Request) -> Response:
        return JSONResponse(self.preview.status())

    async def cancel_preview(self, request: Request) -> Response:
        self.preview.cancel()
        return JSONResponse(self.preview.status())

    def routes(self) -> list[Route]:
        return [Route("/", self.index), Route("/static/{name}", self.asset),
                Route("/files/{path:path}", self.files), Route("/preview/{name}", self.preview_file),
                Route("/api/scene", self.get_scene), Route("/api/scene", self.save, methods=["PUT"]),
                Route("/api/photo", self.upload_photo, methods=["POST"]), Route("/api/mask", self.mask, methods=["POST"]),
                Route("/api/check", self.check, methods=["POST"]),
                Route("/api/preview", self.preview_status), Route("/api/preview", self.start_preview, methods=["POST"]),
                Route("/api/preview", self.cancel_preview, methods=["DELETE"])]


async def _body(request: Request) -> bytes:
    """The request body, read no further than the upload limit (one byte past it says 'too large')."""
    data = bytearray()
    async for chunk in request.stream():
        data += chunk
        if len(data) > sf.MAX_IMAGE_BYTES:
            break
    return bytes(data)


async def _json(request: Request):
    data = await _body(request)
    if len(data) > sf.MAX_IMAGE_BYTES:
        return error_json(InputError("request", None, "request is over the size limit", "send less"), 413)
    try:
        body = json.loads(data)
    except ValueError:
        return error_json(InputError("request", None, "the request is not JSON", "send JSON"), 400)
    return body if isinstance(body, dict) else error_json(InputError("request", None, "expected an object", "send one"), 400)


def make_app(folder: Path, device: str = "cpu") -> Starlette:
    state = SetupApp(folder, device)

    @contextlib.asynccontextmanager
    async def lifespan(app):
        yield
        state.preview.close()  # a running stage is stopped and the preview's files removed

    app = Starlette(routes=state.routes(), lifespan=lifespan)
    app.state.setup = state
    return app
