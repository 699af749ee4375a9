"""The simulate tests run on every Warp device present: the CPU always, CUDA where a GPU is."""
from __future__ import annotations

import pytest
import warp as wp

wp.config.quiet = True
DEVICES = ["cpu"] + (["cuda:0"] if wp.get_cuda_device_count() > 0 else [])


@pytest.fixture(params=DEVICES)
def device(request) -> str:
    return request.param
