"""Per-pixel front-to-back alpha compositing of tile-binned Gaussians (Warp), and its backward pass.

One kernel thread per pixel of a tile. Each tile reads its Gaussians from
contiguous buffers already sorted by depth (gathered once per render): on the
CPU that runs about twice as fast as gathering by Gaussian index per pixel.

The backward pass walks each pixel's list back to front, rebuilding the
transmittance by division, and writes gradients per intersection. An
intersection belongs to one tile, so the threads of different tiles never
write the same entry; the per-Gaussian sums are one ``index_add_`` afterwards.
On the CPU that lets several Python threads composite disjoint tile sets at
once (Warp runs one CPU launch on one thread).
"""

import functools
import os
from concurrent.futures import ThreadPoolExecutor

import torch
import warp as wp

from .binning import ALPHA_MIN, POWER_MARGIN, TILE_SIZE, TileBins
from .launch import launch, torch_single_threaded

ALPHA_MAX = wp.constant(0.99)
"""Alpha is clamped to this so that one Gaussian never hides everything behind it."""
TRANSMITTANCE_MIN = wp.constant(1e-4)
"""Compositing stops before the transmittance would fall below this."""


def _thread_budget() -> int:
    """OMP_NUM_THREADS where the caller sets it (snakemake sets it to each job's threads, so two one-thread
    jobs on two cores do not take each other's core), else the CPUs; at most 16."""
    given = os.environ.get("OMP_NUM_THREADS", "").strip()
    threads = int(given) if given.isdigit() and int(given) > 0 else os.cpu_count() or 1
    return min(threads, 16)


CPU_THREADS = _thread_budget()
"""Python threads that launch CPU kernels concurrently, each on its own set of tiles."""


@wp.func
def splat_power(mean2d: wp.vec2, conic: wp.vec3, px: float, py: float) -> float:
    """The Gaussian's exponent -1/2 d^T Sigma^-1 d at pixel centre (px, py)."""
    dx = mean2d[0] - px
    dy = mean2d[1] - py
    return -0.5 * (conic[0] * dx * dx + conic[2] * dy * dy) - conic[1] * dx * dy


@wp.func
def tile_pixel(tile_ids: wp.array(dtype=wp.int32), t: int, k: int, tiles_x: int) -> wp.vec2i:
    """(row, col) of pixel k of the t-th listed tile."""
    tile = tile_ids[t]
    ty = tile // tiles_x
    return wp.vec2i(ty * TILE_SIZE + k // TILE_SIZE, (tile - ty * tiles_x) * TILE_SIZE + k % TILE_SIZE)


@functools.cache
def composite_kernels(channels: int):
    """Forward and backward kernels for ``channels`` feature channels (one compiled pair per count)."""
    vec_c = wp.types.vector(length=channels, dtype=float)

    @wp.kernel(module="unique")
    def composite_forward(
        tile_ids: wp.array(dtype=wp.int32), tile_offsets: wp.array(dtype=wp.int32), tiles_x: int,
        means2d: wp.array(dtype=wp.vec2), conics: wp.array(dtype=wp.vec3), opacities: wp.array(dtype=float),
        power_floors: wp.array(dtype=float), distances: wp.array(dtype=float), features: wp.array(dtype=vec_c),
        background: vec_c, out_features: wp.array2d(dtype=vec_c), out_alpha: wp.array2d(dtype=float),
        out_depth: wp.array2d(dtype=float), out_transmittance: wp.array2d(dtype=float),
        out_end: wp.array2d(dtype=wp.int32),
    ):
        t, k = wp.tid()
        pixel = tile_pixel(tile_ids, t, k, tiles_x)
        row, col = pixel[0], pixel[1]
        if row >= out_alpha.shape[0] or col >= out_alpha.shape[1]:
            return
        px = float(col) + 0.5
        py = float(row) + 0.5
        tile = tile_ids[t]
        end = tile_offsets[tile]
        # Typed constructors: Warp only lets variables declared this way change inside a loop.
        transmittance = float(1.0)  # noqa: UP018
        color = vec_c()
        depth = float(0.0)  # noqa: UP018
        for n in range(tile_offsets[tile], tile_offsets[tile + 1]):
            power = splat_power(means2d[n], conics[n], px, py)
            if power < power_floors[n]:  # surely below 1/255: skip the exp
                continue
            alpha = wp.min(ALPHA_MAX, opacities[n] * wp.exp(power))
            if alpha < ALPHA_MIN:
                continue
            next_transmittance = transmittance * (1.0 - alpha)
            if next_transmittance < TRANSMITTANCE_MIN:
                break
            weight = alpha * transmittance
            color += weight * features[n]
            depth += weight * distances[n]
            transmittance = next_transmittance
            end = n + 1
        out_features[row, col] = color + transmittance * background
        out_alpha[row, col] = 1.0 - transmittance
        out_depth[row, col] = depth
        out_transmittance[row, col] = transmittance
        out_end[row, col] = end

    @wp.kernel(module="unique")
    def composite_backward(
        tile_ids: wp.array(dtype=wp.int32), tile_offsets: wp.array(dtype=wp.int32), tiles_x: int,
        means2d: wp.array(dtype=wp.vec2), conics: wp.array(dtype=wp.vec3), opacities: wp.array(dtype=float),
        power_floors: wp.array(dtype=float), distances: wp.array(dtype=float), features: wp.array(dtype=vec_c),
        background: vec_c, transmittances: wp.array2d(dtype=float), ends: wp.array2d(dtype=wp.int32),
        grad_out_features: wp.array2d(dtype=vec_c), grad_out_alpha: wp.array2d(dtype=float),
        grad_out_depth: wp.array2d(dtype=float),
        grad_means2d: wp.array(dtype=wp.vec2), grad_conics: wp.array(dtype=wp.vec3),
        grad_opacities: wp.array(dtype=float), grad_distances: wp.array(dtype=float),
        grad_features: wp.array(dtype=vec_c),
    ):
        t, k = wp.tid()
        pixel = tile_pixel(tile_ids, t, k, tiles_x)
        row, col = pixel[0], pixel[1]
        if row >= transmittances.shape[0] or col >= transmittances.shape[1]:
            return
        px = float(col) + 0.5
        py = float(row) + 0.5
        g_features = grad_out_features[row, col]
        g_alpha = grad_out_alpha[row, col]
        g_depth = grad_out_depth[row, col]
        transmittance = transmittances[row, col]
        # Loss carried by everything behind the current Gaussian (background included):
        # each of those terms holds a factor (1 - alpha) of the current one.
        behind = transmittance * wp.dot(g_features, background)
        n = ends[row, col]
        start = tile_offsets[tile_ids[t]]
        while n > start:
            n -= 1
            power = splat_power(means2d[n], conics[n], px, py)
            if power < power_floors[n]:
                continue
            weight_2d = wp.exp(power)
            raw_alpha = opacities[n] * weight_2d
            alpha = wp.min(ALPHA_MAX, raw_alpha)
            if alpha < ALPHA_MIN:
                continue
            transmittance = transmittance / (1.0 - alpha)
            weight = alpha * transmittance
            own = wp.dot(g_features, features[n]) + g_depth * distances[n] + g_alpha
            wp.atomic_add(grad_features, n, weight * g_features)
            wp.atomic_add(grad_distances, n, weight * g_depth)
            g_raw_alpha = own * transmittance - behind / (1.0 - alpha)
            behind += own * weight
            if raw_alpha > ALPHA_MAX:
                continue
            wp.atomic_add(grad_opacities, n, g_raw_alpha * weight_2d)
            # alpha = opacity exp(power); d alpha / d power = alpha.
            g_power = g_raw_alpha * alpha
            conic = conics[n]
            dx = means2d[n][0] - px
            dy = means2d[n][1] - py
            wp.atomic_add(grad_conics, n, g_power * wp.vec3(-0.5 * dx * dx, -dx * dy, -0.5 * dy * dy))
            wp.atomic_add(grad_means2d, n, -g_power * wp.vec2(conic[0] * dx + conic[1] * dy,
                                                               conic[1] * dx + conic[2] * dy))

    return vec_c, composite_forward, composite_backward


@functools.cache
def _cpu_pool() -> ThreadPoolExecutor:
    return ThreadPoolExecutor(CPU_THREADS, thread_name_prefix="splat")


def launch_over_tiles(kernel, bins: TileBins, inputs: list, outputs: list, device: torch.device) -> None:
    """Launch a per-pixel kernel on every tile.

    On CUDA: one launch. On the CPU: the tiles are dealt, heaviest first, to
    CPU_THREADS Python threads that launch concurrently, so each thread gets a
    similar share of intersections.
    """
    pixels_per_tile = TILE_SIZE * TILE_SIZE
    if device.type != "cpu" or CPU_THREADS == 1:
        tile_ids = torch.arange(bins.num_tiles, dtype=torch.int32, device=device)
        shares = [tile_ids]
    else:
        by_load = torch.argsort(bins.tile_loads(), descending=True, stable=True).to(torch.int32)
        shares = [by_load[i::CPU_THREADS] for i in range(min(CPU_THREADS, bins.num_tiles))]

    def launch_share(tile_ids: torch.Tensor) -> None:
        launch(kernel, (tile_ids.shape[0], pixels_per_tile), inputs=[wp.from_torch(tile_ids.contiguous()), *inputs],
               outputs=outputs, device=device)

    if len(shares) == 1:
        launch_share(shares[0])
    else:
        wp.load_module(kernel.module, device="cpu")  # compile once, not once per thread
        for future in [_cpu_pool().submit(launch_share, share) for share in shares]:
            future.result()


class _CompositeGaussians(torch.autograd.Function):
    @staticmethod
    def forward(ctx, means2d, conics, opacities, distances, features, background, bins: TileBins,
                width: int, height: int):
        device, channels = means2d.device, features.shape[1]
        vec_c, forward_kernel, _ = composite_kernels(channels)
        ids = bins.gaussian_ids
        # Per-intersection copies in composite order: each tile reads one contiguous run.
        sorted_inputs = [wp.from_torch(means2d[ids].contiguous(), dtype=wp.vec2),
                         wp.from_torch(conics[ids].contiguous(), dtype=wp.vec3),
                         wp.from_torch(opacities[ids].contiguous()),
                         # alpha >= 1/255 needs power >= -ln(255 opacity); binned Gaussians have opacity >= 1/255.
                         wp.from_torch((-torch.log(255.0 * opacities[ids]) - POWER_MARGIN).contiguous()),
                         wp.from_torch(distances[ids].contiguous()),
                         wp.from_torch(features[ids].contiguous(), dtype=vec_c),
                         vec_c(*background.tolist())]
        out_features = torch.zeros(height, width, channels, device=device)
        out_alpha = torch.zeros(height, width, device=device)
        out_depth = torch.zeros(height, width, device=device)
        transmittances = torch.ones(height, width, device=device)
        ends = torch.zeros(height, width, dtype=torch.int32, device=device)
        launch_over_tiles(
            forward_kernel, bins,
            inputs=[wp.from_torch(bins.tile_offsets), bins.tiles_x, *sorted_inputs],
            outputs=[wp.from_torch(out_features, dtype=vec_c), wp.from_torch(out_alpha), wp.from_torch(out_depth),
                     wp.from_torch(transmittances), wp.from_torch(ends)],
            device=device)
        ctx.bins, ctx.sorted_inputs, ctx.num_gaussians = bins, sorted_inputs, means2d.shape[0]
        ctx.save_for_backward(transmittances, ends, background)
        return out_features, out_alpha, out_depth

    @staticmethod
    @torch_single_threaded()
    def backward(ctx, grad_features_out, grad_alpha_out, grad_depth_out):
        transmittances, ends, background = ctx.saved_tensors
        bins, G = ctx.bins, ctx.num_gaussians
        device, channels = transmittances.device, background.shape[0]
        vec_c, _, backward_kernel = composite_kernels(channels)
        N = bins.gaussian_ids.shape[0]
        grads = [torch.zeros(N, 2, device=device), torch.zeros(N, 3, device=device), torch.zeros(N, device=device),
                 torch.zeros(N, device=device), torch.zeros(N, channels, device=device)]
        launch_over_tiles(
            backward_kernel, bins,
            inputs=[wp.from_torch(bins.tile_offsets), bins.tiles_x, *ctx.sorted_inputs,
                    wp.from_torch(transmittances), wp.from_torch(ends),
                    wp.from_torch(grad_features_out.contiguous(), dtype=vec_c),
                    wp.from_torch(grad_alpha_out.contiguous()), wp.from_torch(grad_depth_out.contiguous())],
            outputs=[wp.from_torch(grads[0], dtype=wp.vec2), wp.from_torch(grads[1], dtype=wp.vec3),
                     wp.from_torch(grads[2]), wp.from_torch(grads[3]), wp.from_torch(grads[4], dtype=vec_c)],
            device=device)
        per_gaussian = [torch.zeros(G, *g.shape[1:], device=device).index_add_(0, bins.gaussian_ids, g)
                        for g in grads]
        grad_background = (transmittances[..., None] * grad_features_out).sum((0, 1))
        return (*per_gaussian, grad_background, None, None, None)


def composite(means2d: torch.Tensor, conics: torch.Tensor, opacities: torch.Tensor, distances: torch.Tensor,
              features: torch.Tensor, background: torch.Tensor, bins: TileBins, width: int, height: int):
    """Alpha-composite binned Gaussians front to back (differentiable in every tensor argument).

    Args:
        means2d (G, 2) px, conics (G, 3) 1/px^2, opacities (G,), distances (G,) metres,
        features (G, C), background (C,): float32 on one device; bins: from ``bin_gaussians``.
    Returns:
        features (H, W, C) composited over the background, alpha (H, W) = 1 - final
        transmittance, depth (H, W) = sum of weight * distance (not divided by alpha).
    """
    return _CompositeGaussians.apply(means2d, conics, opacities, distances, features, background, bins,
                                     width, height)
