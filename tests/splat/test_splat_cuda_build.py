"""The kernels also build for CUDA (sm_90), even on a machine without a GPU (Warp compiles with NVRTC).

Numerical checks on CUDA run in the other tests' ``device`` parameter where a GPU is visible.
"""
from splat import binning, composite, project
from testing.cuda_build import compiled_cubins


def test_kernels_compile_for_cuda(tmp_path):
    _, forward, backward = composite.composite_kernels(3)
    assert compiled_cubins([project, binning, forward.module, backward.module], tmp_path) == 4
