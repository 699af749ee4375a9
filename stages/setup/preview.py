"""The preview: the saved scene through the same stage programs as the workflow, coarse and short.

pm-reconstruct, pm-simulate and pm-render run one after another on a copy of scene.yaml whose
resolution, iterations, grid, particle density, frame rate and video width are lowered to
PREVIEW_KEYS; every other key (materials, conditions, camera, duration) is the scene's own. The
frames come from coarse.h5, laid over the background pm-reconstruct filled in. A stage that refuses its input ends the preview with that stage's
own one-paragraph message.
"""
from __future__ import annotations

import copy
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import cv2
import yaml

import numpy as np

from schemas.artifacts import CoarseArtifact, GaussiansArtifact, read_artifact

PREVIEW_KEYS = {
    "reconstruct": {"resolution": 96, "iterations": 40},
    "physics": {"grid": 24, "particles_per_cell": 2, "fps": 8},
    "render": {"width": 192},
}
"""What the preview lowers. On this 2-core CPU the coffee example takes about 30 s (benchmarks/RESULTS.md)."""
PATH_KEYS = (("image",), ("objects", "*", "mask"), ("objects", "*", "hints"), ("reconstruct", "init_ply"),
             ("reconstruct", "extra_views", "*", "image"), ("reconstruct", "sam_model"), ("reconstruct", "depth_model"))


def preview_scene(raw: dict, folder: Path) -> dict:
    """The scene mapping the preview runs: PREVIEW_KEYS lowered (never raised), paths made absolute."""
    scene = copy.deepcopy(raw)
    for section, keys in PREVIEW_KEYS.items():
        target = scene.setdefault(section, {})
        for key, value in keys.items():
            given = target.get(key)
            target[key] = value if given is None else min(given, value)
    for path in PATH_KEYS:
        _absolute(scene, path, folder)
    return scene


def _absolute(node, path: tuple, folder: Path) -> None:
    """Turn the relative path at ``path`` (``*``: every item of a list) into one under ``folder``."""
    head, rest = path[0], path[1:]
    items = (enumerate(node) if isinstance(node, list) else ()) if head == "*" else \
        ([(head, node[head])] if isinstance(node, dict) and head in node else [])
    for key, value in items:
        if rest:
            _absolute(value, rest, folder)
        elif isinstance(value, str) and not Path(value).is_absolute():
            node[key] = str(folder / value)


@dataclass
class Preview:
    """One preview run; ``status()`` is what the page polls."""

    state: str = "idle"  # idle, running, done, failed, cancelled
    stage: str = ""
    done_stages: int = 0
    message: str = ""
    frames: list = field(default_factory=list)
    fps: float = 8.0
    seconds: float = 0.0
    workdir: Optional[Path] = None
    _process: Optional[subprocess.Popen] = None
    _cancelled: bool = False
    _lock: threading.Lock = field(default_factory=threading.Lock)

    STAGES = ("reconstruct", "simulate", "render")

    def status(self) -> dict:
        # the stages log 'iteration i/N' and 'frame i/N': the running stage's share of its bar
        step = re.search(r"(?:iteration|frame) (\d+)/(\d+)", self.message) if self.state == "running" else None
        return {"state": self.state, "stage": self.stage, "done_stages": self.done_stages,
                "stage_fraction": int(step.group(1)) / max(1, int(step.group(2))) if step else 0.0,
                "stages": list(self.STAGES), "message": self.message, "fps": self.fps,
                "frames": [f"/preview/{name}" for name in self.frames], "seconds": round(self.seconds, 1),
                "setup": "/preview/setup.png" if self.done_stages >= 2 else None}

    def start(self, raw: dict, folder: Path, device: str = "cpu") -> None:
        with self._lock:
            if self.state == "running":
                return
            if self.workdir is not None:
                shutil.rmtree(self.workdir, ignore_errors=True)
            self.workdir = Path(tempfile.mkdtemp(prefix="pm-setup-preview-"))
            (self.workdir / "scene.yaml").write_text(yaml.safe_dump(preview_scene(raw, folder), sort_keys=False))
            self.state, self.stage, self.done_stages, self.message, self.frames = "running", "", 0, "", []
            self._cancelled = False
        threading.Thread(target=self._run, args=(device,), daemon=True).start()

    def cancel(self) -> None:
        with self._lock:
            self._cancelled = True
            if self._process is not None and self._process.poll() is None:
                os.killpg(self._process.pid, signal.SIGTERM)  # the stage and any worker it started

    def close(self) -> None:
        self.cancel()
        if self.workdir is not None:
            shutil.rmtree(self.workdir, ignore_errors=True)

    def _commands(self, device: str) -> list[list[str]]:
        bin_dir, w = Path(sys.executable).parent, self.workdir
        scene = ["--scene", str(w / "scene.yaml"), "--device", device]
        return [[str(bin_dir / "pm-reconstruct"), *scene, "--out", str(w / "gaussians.h5")],
                [str(bin_dir / "pm-simulate"), *scene, "--gaussians", str(w / "gaussians.h5"),
                 "--out", str(w / "trajectories.h5")],
                [str(bin_dir / "pm-render"), *scene, "--gaussians", str(w / "gaussians.h5"),
                 "--trajectories", str(w / "trajectories.h5"), "--out", str(w / "coarse.h5"),
                 "--video", str(w / "coarse.mp4")]]

    def _run(self, device: str) -> None:
        started = time.perf_counter()
        try:
            for name, command in zip(self.STAGES, self._commands(device)):
                with self._lock:
                    if self._cancelled:
                        break
                    self.stage = name
                    log = open(self.workdir / f"{name}.log", "w+")
                    self._process = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT,
                                                     start_new_session=True, text=True)
                while self._process.poll() is None:
                    time.sleep(0.2)
                    self.seconds = time.perf_counter() - started
                    self.message = _last_line(log)
                if self._process.returncode != 0:
                    if not self._cancelled:
                        self.state, self.message = "failed", _error_paragraph(log, name)
                    break
                self.done_stages += 1
            if self._cancelled:
                self.state, self.message = "cancelled", "preview cancelled"
            elif self.state == "running":
                self.frames = self._write_frames()
                self.state, self.message = "done", f"{len(self.frames)} frames in {time.perf_counter() - started:.0f} s"
        except Exception as err:  # a preview must tell the page, whatever went wrong
            self.state, self.message = "failed", f"preview failed: {err}"
        self.seconds = time.perf_counter() - started

    def _write_frames(self) -> list[str]:
        """PNG frames: the coarse render (colour composited on black, so premultiplied) over the background."""
        coarse = read_artifact(self.workdir / "coarse.h5", CoarseArtifact)
        background = read_artifact(self.workdir / "gaussians.h5", GaussiansArtifact).background
        height, width = coarse.rgb.shape[1:3]
        background = cv2.resize(background, (width, height), interpolation=cv2.INTER_AREA).astype(np.float32)
        self.fps = float(coarse.fps)
        names = []
        for t, (rgb, alpha) in enumerate(zip(coarse.rgb, coarse.alpha)):
            frame = rgb + (1 - np.clip(alpha, 0, 1))[..., None] * background
            names.append(f"frame_{t:03d}.png")
            cv2.imwrite(str(self.workdir / names[-1]), cv2.cvtColor(np.clip(frame + 0.5, 0, 255).astype(np.uint8),
                                                                     cv2.COLOR_RGB2BGR))
        return names


def _last_line(log) -> str:
    log.flush()
    log.seek(0)
    lines = [line.strip() for line in log.read().splitlines() if line.strip()]
    return lines[-1] if lines else ""


def _error_paragraph(log, stage: str) -> str:
    """The stage's InputError paragraph ('pm-x: error in ...'), else its last lines."""
    log.seek(0)
    lines = [line.rstrip() for line in log.read().splitlines() if line.strip()]
    for line in reversed(lines):
        if line.startswith(f"pm-{stage}: error in "):
            return line
    return f"pm-{stage} failed: " + " ".join(lines[-3:])
