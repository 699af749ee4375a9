"""Launching Warp kernels from torch code: device, stream, and CPU threads."""
import contextlib

import torch
import warp as wp


def launch(kernel, dim, inputs: list, outputs: list, device: torch.device, **kwargs) -> None:
    """``wp.launch`` on the Warp device matching ``device``; on CUDA on torch's current stream,
    so that the kernel is ordered with the torch work that made its inputs and reads its outputs."""
    wp_device = wp.device_from_torch(device)
    stream = wp.stream_from_torch(device) if wp_device.is_cuda else None
    wp.launch(kernel, dim=dim, inputs=inputs, outputs=outputs, device=wp_device, stream=stream, **kwargs)


@contextlib.contextmanager
def torch_single_threaded():
    """Run torch's own ops single-threaded while splat works.

    splat's torch ops are small gathers, sorts and sums; its CPU time goes to Warp
    kernels launched from several Python threads. Torch's OpenMP workers spin-wait
    after each parallel op and take the cores from those threads: on 2 cores a
    render plus backward took 3-5x longer with them. Usable as a decorator.
    """
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)
