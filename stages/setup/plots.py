"""pm-plots: the Snakemake report's plots of one scene, as SVG files drawn without a plotting library.

energy.svg      kinetic, potential and their sum against time (trajectories.h5 /diagnostics)
momentum.svg    the linear momentum's three components and its magnitude against time
loss.svg        the reconstruction's loss terms against the iteration (gaussians.h5 /optimization/loss)
stage_times.svg the wall time of each stage, from Snakemake's benchmark files
"""
from __future__ import annotations

import argparse
import csv
from html import escape
from pathlib import Path
from typing import Sequence

import numpy as np

from schemas import run_main, stage_parser
from schemas.artifacts import GaussiansArtifact, TrajectoriesArtifact, read_artifact

COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b")
WIDTH, HEIGHT, MARGIN = 640, 300, (60, 24, 10, 36)  # margins: left, top, right, bottom (px)
STAGE_ORDER = ("reconstruct", "simulate", "render", "lora", "invert", "enhance")


def _ticks(lo: float, hi: float, count: int = 5) -> np.ndarray:
    """Round tick values covering [lo, hi]."""
    if hi <= lo:
        hi = lo + 1.0
    step = 10 ** np.floor(np.log10((hi - lo) / count))
    step *= min((m for m in (1, 2, 5, 10) if (hi - lo) / (m * step) <= count), default=10)
    return np.arange(np.ceil(lo / step) * step, hi + 0.5 * step, step)


def line_chart(title: str, x: np.ndarray, series: dict[str, np.ndarray], x_label: str, y_label: str,
               log_y: bool = False) -> str:
    """An SVG line chart of ``series`` (name -> values (N,)) against ``x`` (N,); NaN points (a loss term
    the scene does not use) are left out, and a series with none left is not drawn."""
    series = {name: np.asarray(v, float) for name, v in series.items() if np.isfinite(np.asarray(v, float)).any()}
    if not series or len(x) == 0:  # e.g. reconstruct.iterations: 0
        x, series = np.zeros(1), {"(no data)": np.zeros(1)}
    left, top, right, bottom = MARGIN
    plot_w, plot_h = WIDTH - left - right - 110, HEIGHT - top - bottom
    values = np.concatenate(list(series.values()))
    values = values[np.isfinite(values)]
    if log_y:
        values = np.log10(np.maximum(values, 1e-12))
    lo, hi = float(values.min()), float(values.max())
    pad = 0.05 * (hi - lo or 1.0)
    lo, hi = lo - pad, hi + pad
    x = np.asarray(x, float)
    x0, x1 = float(x.min()), float(x.max()) if x.max() > x.min() else float(x.min()) + 1
    px = lambda v: left + (v - x0) / (x1 - x0) * plot_w
    py = lambda v: top + (hi - v) / (hi - lo) * plot_h
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH}" height="{HEIGHT}" font-family="sans-serif" '
           f'font-size="11"><rect width="100%" height="100%" fill="white"/>',
           f'<text x="{left}" y="{top - 6}" font-size="13" font-weight="bold">{escape(title)}</text>']
    for t in _ticks(lo, hi):
        shown = f"{10 ** t:.3g}" if log_y else f"{t + 0.0:g}"  # + 0.0: no '-0'
        out.append(f'<line x1="{left}" x2="{left + plot_w}" y1="{py(t):.1f}" y2="{py(t):.1f}" stroke="#ddd"/>'
                   f'<text x="{left - 4}" y="{py(t) + 4:.1f}" text-anchor="end">{shown}</text>')
    for t in _ticks(x0, x1):
        out.append(f'<line x1="{px(t):.1f}" x2="{px(t):.1f}" y1="{top}" y2="{top + plot_h}" stroke="#eee"/>'
                   f'<text x="{px(t):.1f}" y="{top + plot_h + 14}" text-anchor="middle">{t:g}</text>')
    out.append(f'<rect x="{left}" y="{top}" width="{plot_w}" height="{plot_h}" fill="none" stroke="#888"/>')
    out.append(f'<text x="{left + plot_w / 2}" y="{HEIGHT - 10}" text-anchor="middle">{escape(x_label)}</text>')
    out.append(f'<text transform="translate(14 {top + plot_h / 2}) rotate(-90)" text-anchor="middle">'
               f'{escape(y_label)}</text>')
    for i, (name, v) in enumerate(series.items()):
        v = np.log10(np.maximum(v, 1e-12)) if log_y else v
        points = " ".join(f"{px(a):.1f},{py(b):.1f}" for a, b in zip(x, v) if np.isfinite(b))
        colour = COLOURS[i % len(COLOURS)]
        out.append(f'<polyline points="{points}" fill="none" stroke="{colour}" stroke-width="1.8"/>')
        out.append(f'<rect x="{left + plot_w + 12}" y="{top + 16 * i}" width="10" height="10" fill="{colour}"/>'
                   f'<text x="{left + plot_w + 26}" y="{top + 16 * i + 9}">{escape(name)}</text>')
    out.append("</svg>")
    return "\n".join(out) + "\n"


def bar_chart(title: str, bars: dict[str, float], unit: str) -> str:
    """An SVG horizontal bar chart of ``bars`` (label -> value)."""
    left, row = 100, 26
    height = 40 + row * len(bars)
    longest = max(bars.values(), default=1.0) or 1.0
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH}" height="{height}" font-family="sans-serif" '
           f'font-size="11"><rect width="100%" height="100%" fill="white"/>',
           f'<text x="10" y="18" font-size="13" font-weight="bold">{escape(title)}</text>']
    for i, (name, value) in enumerate(bars.items()):
        y, w = 30 + row * i, (WIDTH - left - 90) * value / longest
        out.append(f'<text x="{left - 6}" y="{y + 14}" text-anchor="end">{escape(name)}</text>'
                   f'<rect x="{left}" y="{y}" width="{w:.1f}" height="{row - 8}" fill="{COLOURS[i % len(COLOURS)]}"/>'
                   f'<text x="{left + w + 6:.1f}" y="{y + 14}">{value:.1f} {unit}</text>')
    out.append("</svg>")
    return "\n".join(out) + "\n"


def stage_seconds(benchmarks: Path) -> dict[str, float]:
    """Stage -> wall seconds from Snakemake's benchmark files (<stage>.tsv, column 's'), in pipeline order."""
    times = {}
    for path in sorted(benchmarks.glob("*.tsv"), key=lambda p: (STAGE_ORDER + (p.stem,)).index(p.stem)):
        with path.open() as f:
            rows = list(csv.DictReader(f, delimiter="\t"))
        if rows:
            times[path.stem] = float(rows[-1]["s"])
    return times


def write_plots(gaussians: Path, trajectories: Path, benchmarks: Path, out: Path) -> list[Path]:
    traj = read_artifact(trajectories, TrajectoriesArtifact)
    recon = read_artifact(gaussians, GaussiansArtifact)
    out.mkdir(parents=True, exist_ok=True)
    kinetic, potential = traj.kinetic_energy, traj.potential_energy
    p = traj.momentum
    loss = recon.loss
    charts = {
        "energy.svg": line_chart("Energy", traj.time_s, {"kinetic": kinetic, "potential": potential,
                                                         "total": kinetic + potential}, "time (s)", "energy (J)"),
        "momentum.svg": line_chart("Linear momentum", traj.time_s, {"x": p[:, 0], "y": p[:, 1], "z": p[:, 2],
                                                                    "|p|": np.linalg.norm(p, axis=1)},
                                   "time (s)", "momentum (kg m/s)"),
        "loss.svg": line_chart("Reconstruction loss", np.arange(1, len(loss) + 1),
                               {name: loss[:, i] for i, name in enumerate(recon.loss_terms)},
                               "iteration", "loss (log scale)", log_y=True),
        "stage_times.svg": bar_chart("Stage times", stage_seconds(benchmarks), "s"),
    }
    written = []
    for name, svg in charts.items():
        written.append(out / name)
        tmp = written[-1].with_name(f".{name}.partial")
        tmp.write_text(svg)
        tmp.replace(written[-1])
    return written


def build_parser() -> argparse.ArgumentParser:
    parser = stage_parser("pm-plots", __doc__)
    parser.add_argument("--gaussians", required=True, type=Path, help="gaussians.h5 from pm-reconstruct")
    parser.add_argument("--trajectories", required=True, type=Path, help="trajectories.h5 from pm-simulate")
    parser.add_argument("--benchmarks", required=True, type=Path, help="folder of Snakemake's <stage>.tsv files")
    parser.add_argument("--out", required=True, type=Path, help="folder to write the SVG files to")
    return parser


def main(argv: Sequence[str] | None = None) -> None:
    run_main(lambda args: write_plots(args.gaussians, args.trajectories, args.benchmarks, args.out), build_parser(), argv)
