"""Speed and memory of splat.rasterize: forward and forward+backward.

    python -m benchmarks.splat [--device cpu|cuda] [--repeats 5] [--no-figures]

The scene is an object-like blob (the reconstruction's use): G Gaussians in a
ball of radius 0.5 m, 2.5 m in front of a 40-degree camera, scales
log-uniform in [5 mm, 3 cm], opacities uniform in [0.2, 1], RGB features.
Times are medians over the repeats after one warm-up (which also compiles):
wall seconds, and in brackets the process's CPU seconds over all threads.
Peak memory: the process's peak resident set growth on the CPU (each case runs
in its own subprocess), torch's peak allocation on CUDA. The table goes to
benchmarks/results/splat.json (splat_cuda.json on a GPU), and RESULTS.md is regenerated.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

# This script shares its name with the package it measures: keep its own folder off the import path.
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]

CASES = [(20_000, 256), (20_000, 512), (100_000, 256), (100_000, 512)]


def make_scene(num_gaussians: int, width: int, device: str, seed: int = 0):
    import torch

    import splat

    g = torch.Generator().manual_seed(seed)
    direction = torch.nn.functional.normalize(torch.randn(num_gaussians, 3, generator=g), dim=-1)
    radius = 0.5 * torch.rand(num_gaussians, 1, generator=g) ** (1 / 3)
    means = direction * radius + torch.tensor([0.0, 0.0, 2.5])
    scales = torch.exp(torch.empty(num_gaussians, 3).uniform_(math.log(0.005), math.log(0.03), generator=g))
    rotations = torch.randn(num_gaussians, 4, generator=g)
    opacities = torch.empty(num_gaussians).uniform_(0.2, 1.0, generator=g)
    colors = torch.rand(num_gaussians, 3, generator=g)
    focal = 0.5 * width / math.tan(math.radians(20.0))
    K = [[focal, 0.0, width / 2], [0.0, focal, width / 2], [0.0, 0.0, 1.0]]
    camera = splat.Camera(K, torch.eye(4), width, width)
    tensors = [t.to(device) for t in (means, opacities, colors, scales, rotations)]
    return tensors, camera


def run_case(num_gaussians: int, width: int, device: str, repeats: int) -> dict:
    import torch

    import splat
    from splat.binning import bin_gaussians
    from splat.project import project_gaussians

    (means, opacities, colors, scales, rotations), camera = make_scene(num_gaussians, width, device)
    leaves = [t.requires_grad_() for t in (means, opacities, colors, scales, rotations)]

    def sync():
        if device.startswith("cuda"):
            torch.cuda.synchronize()

    def forward():
        return splat.rasterize(means, opacities, colors, camera, scales=scales, rotations=rotations)

    def forward_backward():
        out = forward()
        (out.features.sum() + out.depth.sum()).backward()
        for leaf in leaves:
            leaf.grad = None

    def median_time(fn) -> tuple[float, float]:
        """Median wall and process CPU seconds (CPU time is what other loads on the machine cannot inflate)."""
        fn()  # warm-up, compiles kernels
        wall, cpu = [], []
        for _ in range(repeats):
            sync()
            start, start_cpu = time.perf_counter(), time.process_time()
            fn()
            sync()
            wall.append(time.perf_counter() - start)
            cpu.append(time.process_time() - start_cpu)
        return statistics.median(wall), statistics.median(cpu)

    rss_before_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    if device.startswith("cuda"):
        torch.cuda.reset_peak_memory_stats()
    with torch.no_grad():
        t_forward, cpu_forward = median_time(forward)
    t_both, cpu_both = median_time(forward_backward)
    if device.startswith("cuda"):
        peak_mib = torch.cuda.max_memory_allocated() / 2**20
    else:
        peak_mib = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss_before_kib) / 1024
    with torch.no_grad():
        projection = project_gaussians(means, camera, scales=scales, rotations=rotations)
        bins = bin_gaussians(projection.means2d, projection.conics, opacities, projection.depths,
                             camera.width, camera.height)
    return {"gaussians": num_gaussians, "size": width, "forward_s": t_forward, "forward_backward_s": t_both,
            "forward_cpu_s": cpu_forward, "forward_backward_cpu_s": cpu_both, "peak_mib": peak_mib,
            "intersections": int(bins.gaussian_ids.shape[0])}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--device", default="cpu", help="cpu or cuda (default: cpu)")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--case", nargs=2, type=int, metavar=("GAUSSIANS", "SIZE"), help=argparse.SUPPRESS)
    parser.add_argument("--no-figures", action="store_true",
                        help="print the table only; do not write benchmarks/results/*.json and RESULTS.md")
    args = parser.parse_args()
    if args.case:
        print(json.dumps(run_case(*args.case, args.device, args.repeats)))
        return

    cuda = args.device.startswith("cuda")
    print(f"splat.rasterize on {args.device}, median of {args.repeats}; {os.cpu_count()} CPUs, "
          f"load average at start {os.getloadavg()[0]:.1f}")
    columns = (["Gaussians", "image", "intersections", "forward s", "forward+backward s", "peak GPU memory MiB"]
               if cuda else ["Gaussians", "image", "intersections", "forward s (CPU s)", "forward+backward s (CPU s)",
                             "peak memory MiB"])
    print("| " + " | ".join(columns) + " |")
    print("| " + " | ".join("---:" for _ in columns) + " |")
    rows = []
    for num_gaussians, width in CASES:
        result = subprocess.run(
            [sys.executable, __file__, "--device", args.device, "--repeats", str(args.repeats),
             "--case", str(num_gaussians), str(width)], capture_output=True, text=True, check=True)
        r = json.loads(result.stdout.strip().splitlines()[-1])
        cpu_forward, cpu_both = ("", "") if cuda else (f" ({r['forward_cpu_s']:.3f})", f" ({r['forward_backward_cpu_s']:.3f})")
        rows.append([f"{r['gaussians']:,}", f"{r['size']}x{r['size']}", f"{r['intersections']:,}",
                     f"{r['forward_s']:.3f}{cpu_forward}", f"{r['forward_backward_s']:.3f}{cpu_both}",
                     f"{r['peak_mib']:.0f}"])
        print("| " + " | ".join(rows[-1]) + " |", flush=True)
    if not args.no_figures:
        sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
        from benchmarks.figures import invocation, write_figures

        if cuda:
            import torch  # noqa: F401 (figures names the GPU through torch)
        write_figures(
            "splat_cuda" if cuda else "splat", f"splat on {'CUDA' if cuda else 'the CPU'}",
            f"""`splat.rasterize` forward, and forward + backward of `features.sum() + depth.sum()`, on an
            object-like blob (G Gaussians in a 0.5 m ball 2.5 m from a 40-degree camera, scales log-uniform in
            5 mm to 3 cm, opacities 0.2 to 1, RGB features), median of {args.repeats} after a warm-up: wall
            seconds{'' if cuda else ' and, in brackets, the process CPU seconds over all threads'}; peak memory
            is {"torch's peak allocation" if cuda else "the growth of the process's peak resident set during the case"}
            (each case runs in its own process).""",
            invocation(__file__), columns, rows, device=args.device,
            notes=[] if cuda else ["Targets for 20k Gaussians at 256x256 on the 2-core CPU: forward under 0.15 s, "
                                   "forward + backward under 0.5 s."])


if __name__ == "__main__":
    main()
