"""The kernels also build for CUDA (sm_90), even on a machine without a GPU (Warp compiles with NVRTC).

Numerical checks on CUDA run in the other tests' ``device`` parameter where a GPU is visible.
"""
import pytest
import warp as wp

from splat import binning, composite, project


def test_kernels_compile_for_cuda(tmp_path):
    if 90 not in wp.get_cuda_supported_archs():
        pytest.skip("this Warp build cannot compile CUDA code for sm_90 here")
    _, forward, backward = composite.composite_kernels(3)
    for module in (project, binning, forward.module, backward.module):
        wp.compile_aot_module(module, arch=90, module_dir=str(tmp_path))
    assert len(list(tmp_path.glob("*.sm90.cubin"))) == 4
