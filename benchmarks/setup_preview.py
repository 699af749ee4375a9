"""pm-setup's preview time per example scene: the quick coarse pass the page's Preview button runs.

Usage: python benchmarks/setup_preview.py [SCENE_DIR ...]   (default: every scene under scenes/)
Prints one row per scene: frames, seconds per stage and in all (target: under 60 s on a 2-core CPU).
"""
import re
import sys
import time
from pathlib import Path

from stages.setup.preview import Preview
from stages.setup.scene_file import read_raw

REPO = Path(__file__).resolve().parents[1]


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


if __name__ == "__main__":
    folders = [Path(a) for a in sys.argv[1:]] or sorted(p.parent for p in (REPO / "scenes").glob("*/scene.yaml"))
    print("| scene | frames | reconstruct s | simulate s | render s | total s |")
    print("|---|---|---|---|---|---|")
    for folder in folders:
        r = run(folder.resolve())
        print(f"| {folder.name} | {r['frames']} | {r.get('reconstruct', 0):.1f} | {r.get('simulate', 0):.1f} | "
              f"{r.get('render', 0):.1f} | {r['total']:.1f} |" + (f" {r['state']}: {r['message']}" if "message" in r else ""))
