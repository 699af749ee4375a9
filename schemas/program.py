"""Conventions every stage program shares: the user-facing error, exit codes,
the ``--device`` flag and logging.

A program's ``main`` builds its parser with :func:`stage_parser`, then hands its
body to :func:`run_main`, which turns an :class:`InputError` into one readable
paragraph on stderr and exit code 2, and a termination signal (SIGTERM, SIGHUP,
SIGINT: what Snakemake and a terminal send) into one paragraph and exit code
128 + signal, after the writes in progress have removed their temporary files.
"""
from __future__ import annotations

import argparse
import logging
import signal
import sys
from pathlib import Path
from typing import Callable, Optional, Sequence

EXIT_INPUT_ERROR = 2

log = logging.getLogger("physmotion")


class InputError(Exception):
    """Bad input from the user: names the file, the field and the fix.

    Args:
        file: the file at fault (scene.yaml, an image, an artifact).
        field: the key or dataset at fault, e.g. ``objects[0].material.poisson_ratio``;
            None when the file as a whole is at fault.
        problem: what is wrong, one sentence.
        fix: what the user should do, one sentence.
    """

    def __init__(self, file: Path | str, field: Optional[str], problem: str, fix: str):
        self.file, self.field, self.problem, self.fix = str(file), field, problem, fix
        super().__init__(self.paragraph())

    def paragraph(self) -> str:
        where = f"{self.file}" + (f", field '{self.field}'" if self.field else "")
        return f"error in {where}: {self.problem.rstrip('.')}. Fix: {self.fix.rstrip('.')}."


class Stopped(BaseException):
    """A termination signal arrived; a BaseException, so that no ``except Exception`` swallows it."""

    def __init__(self, signum: int):
        self.signum = signum
        super().__init__(signal.Signals(signum).name)


def _stop(signum, _frame):
    raise Stopped(signum)


def stage_parser(prog: str, description: str) -> argparse.ArgumentParser:
    """An argument parser with the flags every stage program takes."""
    parser = argparse.ArgumentParser(
        prog=prog, description=description, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--device", choices=("cpu", "cuda", "auto"), default="auto",
                        help="where kernels run; auto picks cuda when a GPU is visible (default: auto)")
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    return parser


def resolve_device(choice: str, runtime: str = "torch") -> str:
    """Map ``cpu|cuda|auto`` to a device name torch and Warp both accept ("cpu" or "cuda:0").

    `runtime` is the library the stage's work runs in, "torch" or "warp", and the one asked whether it
    sees a GPU: a CPU build of torch sees none where Warp does, and a Warp stage need not pay torch's
    import (seconds) for the question.
    """
    if choice == "cpu":
        return "cpu"
    if runtime == "warp":
        import warp as wp

        visible = wp.is_cuda_available()
    else:
        import torch

        visible = torch.cuda.is_available()
    if visible:
        return "cuda:0"
    if choice == "cuda":
        raise InputError("--device", None, "cuda was asked for but no CUDA GPU is visible",
                         "run with --device cpu or auto, or on a machine with an NVIDIA GPU")
    return "cpu"


def run_main(body: Callable[[argparse.Namespace], None], parser: argparse.ArgumentParser,
             argv: Optional[Sequence[str]] = None) -> None:
    """Parse arguments, set up logging, run ``body`` and exit with the right code."""
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO,
                        format=f"%(asctime)s {parser.prog} %(levelname)s %(message)s", datefmt="%H:%M:%S")
    previous = {signum: signal.signal(signum, _stop) for signum in (signal.SIGTERM, signal.SIGHUP, signal.SIGINT)}
    try:
        body(args)
    except InputError as err:
        print(f"{parser.prog}: {err.paragraph()}", file=sys.stderr)
        sys.exit(EXIT_INPUT_ERROR)
    except Stopped as stop:
        print(f"{parser.prog}: stopped by {stop} before it finished; outputs are written only when complete, so "
              "none of this run's is there. Fix: run it again (Snakemake reruns the job).", file=sys.stderr)
        sys.exit(128 + stop.signum)
    except MemoryError:
        print(f"{parser.prog}: ran out of memory. Fix: lower the scene's sizes (physics.grid, "
              "physics.particles_per_cell, physics.duration_s, render.width) or give the job more memory.",
              file=sys.stderr)
        sys.exit(EXIT_INPUT_ERROR)
    finally:  # a program called in-process (tests) gives the caller its own handlers back
        for signum, handler in previous.items():
            signal.signal(signum, handler)
