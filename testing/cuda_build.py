"""Build Warp modules for a CUDA architecture on any machine: Warp compiles with NVRTC, no GPU needed."""
from __future__ import annotations

from pathlib import Path

import pytest
import warp as wp


def compiled_cubins(modules: list, directory: Path, arch: int = 90) -> int:
    """Compile each Warp module (a Python module of kernels or a wp.Module) ahead of time for sm_`arch` into
    `directory`; returns how many cubins it holds. Skips the calling test where this Warp build cannot
    compile for that architecture."""
    if arch not in wp.get_cuda_supported_archs():
        pytest.skip(f"this Warp build cannot compile CUDA code for sm_{arch} here")
    for module in modules:
        wp.compile_aot_module(module, arch=arch, module_dir=str(directory))
    return len(list(Path(directory).glob(f"*.sm{arch}.cubin")))
