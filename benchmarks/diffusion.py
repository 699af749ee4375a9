"""Speed of the diffusion backend: one UNet + 2 ControlNet call, inversion and sampling per frame.

    python -m benchmarks.diffusion            # the tiny test model on this machine's CPU
    python -m benchmarks.diffusion --full     # SD 2.1's full-size UNet and ControlNets, random weights, 768 px

Per frame, the pipeline makes `inversion steps` batch-1 calls (pm-invert) and
`steps * (1 + 1/window)` batch-3 calls (pm-enhance: every frame in the propagation
pass, the keyframes once more in the keyframe pass). --full on a CPU measures one call
and prints the estimate instead of running for hours (add --force to run anyway).

The run's row goes to benchmarks/results/diffusion.json (diffusion_cuda.json on a GPU), replacing the
row of the same model, image and threads, and RESULTS.md is regenerated.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.figures import add_arguments, invocation, write_figures  # noqa: E402
from schemas.diffusion import DiffusionSettings  # noqa: E402
from stages.enhance.diffusion.components import Components  # noqa: E402
from stages.enhance.diffusion.inversion import inverse_scheduler, invert_video, stored_timesteps  # noqa: E402
from stages.enhance.diffusion.sampling import sample  # noqa: E402
from testing.tiny_diffusion import full_size_components, tiny_components  # noqa: E402


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize()


def time_call(model: Components, batch: int, size: int, repeats: int) -> float:
    """Seconds per UNet + ControlNet call on ``batch`` latents of a ``size`` px image."""
    latents = torch.randn(batch, 4, size // 8, size // 8, device=model.device, dtype=model.dtype)
    text = model.encode_prompt("a red cup").expand(batch, -1, -1)
    controls = [torch.rand(batch, 3, size, size, device=model.device) for _ in range(2)]
    model.predict(latents, 500, text, controls, 1.0)  # warm-up
    _sync(model.device)
    start = time.perf_counter()
    for _ in range(repeats):
        model.predict(latents, 500, text, controls, 1.0)
    _sync(model.device)
    return (time.perf_counter() - start) / repeats


def time_video(model: Components, frames: int, size: int, settings: DiffusionSettings) -> tuple[float, float]:
    """Seconds per frame of inversion and of sampling + decoding, measured on a short video."""
    images = torch.rand(frames, 3, size, size, device=model.device)
    controls = [torch.rand(frames, 3, size, size, device=model.device, dtype=model.dtype) for _ in range(2)]
    text, negative = model.encode_prompt("a red cup"), model.encode_prompt("")
    scheduler = inverse_scheduler(model, settings.inversion_total_steps, settings.inversion_stride)
    _sync(model.device)
    start = time.perf_counter()
    inverted = invert_video(model, model.encode_images(images), text, controls, 1.0, scheduler, settings.frame_batch)
    _sync(model.device)
    middle = time.perf_counter()
    clean = sample(model, inverted, stored_timesteps(scheduler), controls, text, negative, settings)
    model.decode_latents(clean)
    _sync(model.device)
    return (middle - start) / frames, (time.perf_counter() - middle) / frames


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--full", action="store_true", help="full-size SD 2.1 shapes at 768 px")
    parser.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu", help="for --full")
    parser.add_argument("--frames", type=int, default=5)
    parser.add_argument("--steps", type=int, default=10, help="sampling = inversion steps of the video run")
    parser.add_argument("--force", action="store_true", help="run --full on a CPU anyway")
    parser.add_argument("--threads", type=int, default=torch.get_num_threads(), help="CPU threads")
    add_arguments(parser)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)

    size = 768 if args.full else 64
    if not args.full:
        args.device = "cpu"  # the tiny model is for CPU timings
    model = full_size_components(args.device) if args.full else tiny_components()
    paper = DiffusionSettings()
    calls_per_frame = paper.inversion_total_steps // paper.inversion_stride, paper.steps * (1 + 1 / paper.keyframe_window)
    rows = [("device", f"{args.device} ({torch.get_num_threads()} threads)" if args.device == "cpu" else args.device),
            ("model", f"SD 2.1 full-size UNet + 2 ControlNets, random, {model.dtype}" if args.full
             else "tiny SD-2.1-shaped"),
            ("image", f"{size} x {size} px")]
    if args.full and args.device == "cpu":
        print("measuring one full-size call on the CPU first (about a minute); the full run would take hours",
              file=sys.stderr)
    call1 = time_call(model, 1, size, repeats=1 if args.full and args.device == "cpu" else 5)
    rows.append(("UNet+ControlNets call, batch 1", f"{call1:.3f} s"))
    estimate = calls_per_frame[0] * call1 + calls_per_frame[1] * 3 * call1
    if args.full and args.device == "cpu" and not args.force:
        rows.append(("estimate per frame (paper settings)", f"{estimate / 60:.0f} min: a 48-frame video takes "
                                                            f"{48 * estimate / 3600:.0f} h; not run (--force)"))
    else:
        call3 = time_call(model, 3, size, repeats=3 if args.full else 5)
        settings = DiffusionSettings(steps=args.steps, inversion_stride=1000 // args.steps, frame_batch=4)
        invert_s, sample_s = time_video(model, args.frames, size, settings)
        scale = paper.steps / args.steps
        rows += [("UNet+ControlNets call, batch 3 (one frame, 3 branches)", f"{call3:.3f} s"),
                 (f"inversion per frame, {args.steps} steps", f"{invert_s:.3f} s"),
                 (f"sampling + decoding per frame, {args.steps} steps", f"{sample_s:.3f} s"),
                 ("per frame at paper settings (50 + 50 steps, scaled)", f"{(invert_s + sample_s) * scale:.2f} s")]
    width = max(len(k) for k, _ in rows)
    for key, value in rows:
        print(f"| {key:<{width}} | {value} |")
    if args.no_figures:
        return
    cpu = args.device == "cpu"
    values = dict(rows)
    estimated = "estimate per frame (paper settings)" in values
    model_name = (f"SD 2.1 full-size UNet + 2 ControlNets (random, {str(model.dtype).replace('torch.float', 'fp')})"
                  if args.full else "tiny SD-2.1-shaped (random)")
    write_figures(
        "diffusion" if cpu else "diffusion_cuda", f"Diffusion backend on {'the CPU' if cpu else 'CUDA'}",
        f"""Time of one UNet + two-ControlNet call (batch 1: inversion; batch 3: the coarse, enhanced and
        unconditional branches of one frame) and, per frame of a {args.frames}-frame video, of the diffusion
        backend's inversion and of its sampling and decoding with {args.steps} steps, scaled to the paper's
        50 + 50 steps. Per frame the pipeline makes 50 batch-1 calls (inversion, stride 20 over 1000
        timesteps) and 50 x (1 + 1/5) batch-3 calls (every frame in the propagation pass, the keyframes
        again in the keyframe pass).""",
        invocation(__file__),
        ["model", "image", "threads", "call, batch 1", "call, batch 3", f"inversion / frame ({args.steps} steps)",
         f"sampling + decode / frame ({args.steps} steps)", "per frame, paper settings (50 + 50 steps)"],
        [[model_name, f"{size} px", torch.get_num_threads() if cpu else "-", f"{call1:.3f} s",
          "not run" if estimated else f"{call3:.3f} s", "-" if estimated else f"{invert_s:.3f} s",
          "-" if estimated else f"{sample_s:.3f} s",
          values["estimate per frame (paper settings)"] if estimated else f"{(invert_s + sample_s) * scale:.2f} s"]],
        device=args.device, merge_on=3)


if __name__ == "__main__":
    main()
