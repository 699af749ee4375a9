"""The video convention (DESIGN.md): H.264 through PyAV, yuv420p, even width and height.

OpenCV's wheels cannot write H.264, so every program writes video here.
"""
from __future__ import annotations

import contextlib
import ctypes
import io
from fractions import Fraction
from pathlib import Path

import numpy as np

from .files import write_file


X264_THREADS = 4
"""Encoder threads, fixed (see write_video); x264 runs them on however many cores there are."""
M_PERTURB, PERTURB_BYTE = -6, 0x5A
"""glibc's mallopt parameter that fills every block malloc hands out with one byte, and that byte."""


@contextlib.contextmanager
def filled_allocations():
    """While in the block, every block malloc returns is filled with PERTURB_BYTE (glibc's M_PERTURB).

    The encoding path (libx264 through libavcodec) reads memory it never wrote, so unfilled, the bytes
    of a video follow what the process freed earlier (the same frames encoded after a render, or after
    other allocations, come out different: pm-render's coarse.mp4 differs between two runs of the same
    inputs in one of three). Filled, they are the same whatever ran first. Without glibc's mallopt
    nothing changes."""
    mallopt = getattr(ctypes.CDLL(None), "mallopt", None)
    if mallopt is None:
        yield
        return
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt(M_PERTURB, PERTURB_BYTE)
    try:
        yield
    finally:
        mallopt(M_PERTURB, 0)


def even_size(width: int, height: int) -> tuple[int, int]:
    """Round a frame size down to even numbers (yuv420p needs them), at least 2x2."""
    return max(2, width - width % 2), max(2, height - height % 2)


def write_video(path: Path | str, frames: np.ndarray, fps: float, crf: int = 14) -> Path:
    """Write RGB frames to an H.264 MP4, encoded in memory and written atomically (schemas.files.write_file).

    Args:
        frames: (T, h, w, 3) uint8 RGB; odd sizes are cropped by one pixel to even.
        fps: frames per second.
        crf: x264 constant rate factor (lower is better); 14 keeps photographic texture (yuv420p
            chroma subsampling, not the rate, is then what limits fidelity).
    """
    import av

    path = Path(path)
    frames = np.asarray(frames)
    if frames.ndim != 4 or frames.shape[-1] != 3 or frames.dtype != np.uint8:
        raise ValueError(f"frames must be (T, h, w, 3) uint8, got {frames.shape} {frames.dtype}")
    width, height = even_size(frames.shape[2], frames.shape[1])
    encoded = io.BytesIO()
    with filled_allocations(), av.open(encoded, mode="w", format="mp4") as container:
        stream = container.add_stream("libx264", rate=Fraction(fps).limit_denominator(1001))
        stream.width, stream.height, stream.pix_fmt = width, height, "yuv420p"
        # x264 splits the work by its thread count, and its output depends on that count: left to x264
        # ("auto", from the CPUs this process may use) two runs on the same frames differ by up to 38/255
        # when one is pinned to one core. A fixed count gives the same bytes wherever it runs.
        stream.options = {"crf": str(crf), "threads": str(X264_THREADS)}
        for rgb in frames[:, :height, :width]:
            container.mux(stream.encode(av.VideoFrame.from_ndarray(np.ascontiguousarray(rgb), format="rgb24")))
        container.mux(stream.encode())
    return write_file(path, encoded.getvalue())


def read_video(path: Path | str) -> tuple[np.ndarray, float, str]:
    """Decode a video: (T, h, w, 3) uint8 RGB frames, fps and the codec name."""
    import av

    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        frames = [f.to_ndarray(format="rgb24") for f in container.decode(stream)]
        return np.stack(frames), float(stream.average_rate), stream.codec_context.name
