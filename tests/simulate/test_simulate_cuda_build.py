"""The simulate kernels also build for CUDA (sm_90), even on a machine without a GPU (Warp compiles with NVRTC).

Numerical checks on CUDA run in the other tests' ``device`` parameter where a GPU is visible.
"""
from stages.simulate import conditions, constitutive, crack_fields, mpm, quasi_static, rigid
from testing.cuda_build import compiled_cubins


def test_kernels_compile_for_cuda(tmp_path):
    per_field_count = [kernels[n].module for kernels in mpm.PER_FIELD_COUNT for n in (1, 2)]
    modules = [conditions, constitutive, crack_fields, mpm, quasi_static, rigid, *per_field_count]
    assert compiled_cubins(modules, tmp_path) == len(modules)
