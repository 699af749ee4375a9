"""pm-setup DIR [--image PHOTO]: set a scene up in the browser."""
from __future__ import annotations

import argparse
import shutil
from pathlib import Path

from schemas import InputError, run_main, stage_parser

from . import scene_file as sf

DESCRIPTION = """\
Set a scene up in the browser: draw a box around each object and see its mask
at once (GrabCut, as pm-reconstruct does it), correct it with object and
background strokes, pick the material, draw forces, impulses, torques and fixed
regions on the photograph, set the camera, save scene.yaml and run a quick
preview through the stage programs.

Serves one page on http://HOST:PORT/ (127.0.0.1 unless --host says otherwise)
and prints its address. DIR is created when missing; --image copies a
photograph into it. The page reads only DIR and its own files.
"""


def build_parser() -> argparse.ArgumentParser:
    parser = stage_parser("pm-setup", DESCRIPTION)
    parser.set_defaults(device="cpu")
    parser.add_argument("folder", type=Path, metavar="DIR", help="the scene folder (created when missing)")
    parser.add_argument("--image", type=Path, help="photograph to copy into DIR and use as the scene's image")
    parser.add_argument("--host", default="127.0.0.1",
                        help="address to listen on (default 127.0.0.1: this machine only)")
    parser.add_argument("--port", type=int, default=8765, help="port to listen on (default 8765; 0: any free one)")
    return parser


def check_image(image: Path | None) -> None:
    """Refuse a --image that is missing, not a PNG or JPEG, or does not decode; before anything is made."""
    if image is None:
        return
    if not image.is_file():
        raise InputError(image, None, "photograph does not exist", "give the path of a PNG or JPEG file")
    if image.suffix.lower() not in sf.IMAGE_SUFFIXES:
        raise InputError(image, None, "not a .png, .jpg or .jpeg file", "give a PNG or JPEG photograph")
    sf.decode_image(image.read_bytes(), str(image))


def open_folder(folder: Path, image: Path | None) -> None:
    """Create the folder and put the (checked) photograph in it; a new scene's scene.yaml is written on the
    first save."""
    folder.mkdir(parents=True, exist_ok=True)
    if image is None:
        return
    target = folder / image.name
    if not target.exists() or not target.samefile(image):
        shutil.copyfile(image, target)


def listen(host: str, port: int):
    """A socket listening on host:port, or an InputError naming --port when it cannot."""
    import socket

    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
        sock.listen(128)  # from now on a browser's connection waits for the server instead of being refused
    except OSError as err:
        sock.close()
        raise InputError("--port", None, f"cannot listen on {host}:{port} ({err.strerror})",
                         "give another --port, or 0 for any free one") from None
    return sock


def serve(args: argparse.Namespace) -> None:
    import socket

    import uvicorn

    from .server import make_app

    # the photograph and the port first: a refused start leaves no folder and no copied photograph behind
    check_image(args.image)
    sock = listen(args.host, args.port)
    open_folder(args.folder, args.image)
    app = make_app(args.folder, args.device)
    setup = app.state.setup
    if args.image is not None:
        setup.use_photo(args.image.name)
    host, port = sock.getsockname()[:2]
    shown = f"[{host}]" if sock.family == socket.AF_INET6 else host
    print(f"pm-setup: scene folder {setup.folder}\npm-setup: open http://{shown}:{port}/", flush=True)
    uvicorn.Server(uvicorn.Config(app, log_level="warning", access_log=False)).run(sockets=[sock])


def main(argv=None) -> None:
    run_main(serve, build_parser(), argv)
