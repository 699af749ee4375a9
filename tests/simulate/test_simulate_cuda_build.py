"""The simulate kernels also build for CUDA (sm_90), even on a machine without a GPU (Warp compiles with NVRTC).

Numerical checks on CUDA run in the other tests' ``device`` parameter where a GPU is visible.
"""
import pytest
import warp as wp

from stages.simulate import conditions, constitutive, crack_fields, mpm, quasi_static, rigid


def test_kernels_compile_for_cuda(tmp_path):
    if 90 not in wp.get_cuda_supported_archs():
        pytest.skip("this Warp build cannot compile CUDA code for sm_90 here")
    per_field_count = [kernels[n].module for kernels in (mpm.PARTICLE_TO_GRID, mpm.GRID_UPDATE,
                                                          mpm.GRID_TO_PARTICLE) for n in (1, 2)]
    modules = [conditions, constitutive, crack_fields, mpm, quasi_static, rigid, *per_field_count]
    for module in modules:
        wp.compile_aot_module(module, arch=90, module_dir=str(tmp_path))
    assert len(list(tmp_path.glob("*.sm90.cubin"))) == len(modules)
