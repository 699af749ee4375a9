"""pm-setup's preview time per example scene: the quick coarse pass the page's Preview button runs.

Usage: python -m benchmarks.setup_preview [SCENE_DIR ...] [--no-figures]   (default: every scene under scenes/)
Prints one row per scene: frames, seconds per stage and in all (target: under 60 s on a 2-core CPU). The rows
go to benchmarks/results/setup.json, replacing those of the same scenes, and RESULTS.md is regenerated.
"""
import argparse
import re
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository, before benchmarks/splat.py

from benchmarks.figures import add_arguments, invocation, write_figures  # noqa: E402
from stages.setup.preview import Preview  # noqa: E402
from stages.setup.scene_file import read_raw  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
COLUMNS = ["scene", "frames", "reconstruct s", "simulate s", "render s", "total s"]


def run(folder: Path) -> dict:
    preview = Preview()
    raw, _ = read_raw(folder)
    stage_started, times, started = {}, {}, time.perf_counter()
    preview.start(raw, folder)
    while preview.state == "running":
        stage_started.setdefault(preview.stage, time.perf_counter())
        time.sleep(0.1)
    ends = sorted(stage_started.values())[1:] + [time.perf_counter()]
    for (name, t0), t1 in zip(sorted(stage_started.items(), key=lambda kv: kv[1]), ends):
        times[name] = t1 - t0
    result = {"state": preview.state, "frames": len(preview.frames), "total": time.perf_counter() - started, **times}
    if preview.state != "done":
        result["message"] = re.sub(r"\s+", " ", preview.message)[:200]
    preview.close()
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("folders", nargs="*", type=Path, help="scene folders (default: every scene under scenes/)")
    add_arguments(parser)
    args = parser.parse_args()
    folders = args.folders or sorted(p.parent for p in (REPO / "scenes").glob("*/scene.yaml"))
    print("| " + " | ".join(COLUMNS) + " |")
    print("|" + "---|" * len(COLUMNS))
    rows = []
    for folder in folders:
        r = run(folder.resolve())
        row = [folder.name, r["frames"], f"{r.get('reconstruct', 0):.1f}", f"{r.get('simulate', 0):.1f}",
               f"{r.get('render', 0):.1f}", f"{r['total']:.1f}"]
        print("| " + " | ".join(str(c) for c in row) + " |" + (f" {r['state']}: {r['message']}" if "message" in r else ""))
        if "message" not in r:
            rows.append(row)
    if rows and not args.no_figures:
        write_figures(
            "setup", "pm-setup's preview",
            """pm-setup's preview: the saved scene through pm-reconstruct, pm-simulate and pm-render with the
            preview's lowered keys (resolution 96, 40 iterations, grid 24, 2 particles per cell, 8 fps, width
            192), from the Preview click to the last frame. Target: under 60 s.""",
            invocation(__file__), COLUMNS, rows, merge_on=1)


if __name__ == "__main__":
    main()
