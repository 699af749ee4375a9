"""Every kernel stays in bounds: the renders of the hardest test scenes, forward and backward,
in Warp's debug mode (array bounds asserted; a CPU kernel otherwise corrupts memory silently).

Runs in a subprocess because the mode is process-wide, with one compositing thread:
Warp's debug CPU kernels are not safe to launch from several Python threads at once.
"""
import subprocess
import sys
from pathlib import Path

SCRIPT = """
import sys
import warp as wp
wp.config.mode = "debug"
sys.path.insert(0, {here!r})
import torch
from splat import composite
from splat_scenes import random_scene, render_warp
composite.CPU_THREADS = 1
scenes = [random_scene(0, 400, 37, 29, spread=1.5, background=True),
          random_scene(1, 100, 40, 30, depth=(-1.0, 0.6), scale=(0.01, 0.5)),
          random_scene(2, 30, 37, 29, spread=3.0, depth=(0.5, 2.0), scale=(0.5, 2.0)),
          random_scene(3, 0, 20, 10)]
for scene in scenes:
    for name in ("means", "scales", "rotations", "opacities", "features"):
        getattr(scene, name).requires_grad_()
    out = render_warp(scene)
    (out.features.sum() + out.alpha.sum() + out.depth.sum()).backward()
print("in bounds")
"""


def test_kernels_stay_in_bounds_in_debug_mode():
    here = str(Path(__file__).parent)
    result = subprocess.run([sys.executable, "-c", SCRIPT.format(here=here)], capture_output=True, text=True,
                            timeout=600, check=False)
    assert result.returncode == 0 and "in bounds" in result.stdout, result.stderr[-3000:]
    assert "Assertion failed" not in result.stderr, result.stderr[-3000:]
