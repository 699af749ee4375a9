"""Launching Warp kernels on torch's device and stream."""
import torch
import warp as wp


def launch(kernel, dim, inputs: list, outputs: list, device: torch.device, **kwargs) -> None:
    """``wp.launch`` on the Warp device matching ``device``; on CUDA on torch's current stream,
    so that the kernel is ordered with the torch work that made its inputs and reads its outputs."""
    wp_device = wp.device_from_torch(device)
    stream = wp.stream_from_torch(device) if wp_device.is_cuda else None
    wp.launch(kernel, dim=dim, inputs=inputs, outputs=outputs, device=wp_device, stream=stream, **kwargs)
