"""Launching Warp kernels from torch code: device, stream, and CPU threads."""
import contextlib
import threading

import torch
import warp as wp


def launch(kernel, dim, inputs: list, outputs: list, device: torch.device, **kwargs) -> None:
    """``wp.launch`` on the Warp device matching ``device``; on CUDA on torch's current stream,
    so that the kernel is ordered with the torch work that made its inputs and reads its outputs."""
    wp_device = wp.device_from_torch(device)
    stream = wp.stream_from_torch(device) if wp_device.is_cuda else None
    wp.launch(kernel, dim=dim, inputs=inputs, outputs=outputs, device=wp_device, stream=stream, **kwargs)


class _TorchThreads:
    """Counts who is inside ``single()``: the first to enter (of nested or concurrent
    callers) sets one thread, the last to leave restores the caller's setting."""

    def __init__(self):
        self.lock = threading.Lock()
        self.users = 0
        self.saved = 1

    @contextlib.contextmanager
    def single(self):
        with self.lock:
            if self.users == 0:
                self.saved = torch.get_num_threads()
                torch.set_num_threads(1)
            self.users += 1
        try:
            yield
        finally:
            with self.lock:
                self.users -= 1
                if self.users == 0:
                    torch.set_num_threads(self.saved)


torch_single_threaded = _TorchThreads().single
"""Run torch's own ops single-threaded while splat works (a context manager, or a decorator).

splat's torch ops are small gathers, sorts and sums; its CPU time goes to Warp
kernels launched from several Python threads. Torch's OpenMP workers spin-wait
after each parallel op and take the cores from those threads: on 2 cores a
render plus backward takes 3-5x the CPU time with them.
"""
