"""End to end: the Snakemake workflow on a tiny scene, what reruns after an edit, and the programs' exits."""
import os
import re
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from schemas.artifacts import CoarseArtifact, GaussiansArtifact, TrajectoriesArtifact, read_artifact
from schemas.video import read_video
from testing.tiny_scene import tiny_scene_dict, write_scene
from testing.workflow import BIN, ENV, run_snakemake, snakemake_command

from .conftest import snakemake


def planned_jobs(workdir: Path) -> dict:
    """Rule -> job count of a dry run (empty when nothing is to be done)."""
    out = snakemake(workdir, "-n")
    if "Nothing to be done" in out:
        return {}
    table = out.split("Job stats:")[1].split("Reasons:")[0]
    return {rule: int(n) for rule, n in re.findall(r"^(\w+)\s+(\d+)\s*$", table, re.M) if rule not in ("total", "all")}


@pytest.fixture(scope="module")
def finished_run(tiny_run) -> Path:
    """The session's complete run of the tiny scene (conftest.tiny_run); module scope keeps this module's tests,
    which edit its scene in place, on one worker."""
    return tiny_run


@pytest.mark.slow
def test_workflow_makes_every_artifact_and_a_video(finished_run):
    out = finished_run / "results" / "tiny"
    for name in ("gaussians.h5", "trajectories.h5", "setup.png", "coarse.h5", "coarse.mp4", "video.mp4",
                 "contact_sheet.png", "logs/reconstruct.log", "benchmarks/simulate.tsv"):
        assert (out / name).exists(), name
    gaussians = read_artifact(out / "gaussians.h5", GaussiansArtifact)
    trajectories = read_artifact(out / "trajectories.h5", TrajectoriesArtifact)
    coarse = read_artifact(out / "coarse.h5", CoarseArtifact)
    T = round(0.25 * 8) + 1
    assert trajectories.positions.shape[0] == T and coarse.rgb.shape[0] == T
    assert np.array_equal(trajectories.rest_positions[: len(gaussians.means)], gaussians.means)
    frames, fps, codec = read_video(out / "video.mp4")
    assert codec == "h264" and fps == 8 and frames.shape[0] == T
    assert frames.shape[1] % 2 == 0 and frames.shape[2] % 2 == 0


@pytest.mark.slow
def test_second_run_does_nothing(finished_run):
    assert planned_jobs(finished_run) == {}


def jobs_after_edit(workdir: Path, edit) -> dict:
    """The dry-run plan after editing the scene in place; the file is restored afterwards.

    In place, because Snakemake keys the params it recorded by output path: a copied
    results folder would have none to compare with.
    """
    path = workdir / "scenes" / "tiny" / "scene.yaml"
    original = path.read_text()
    scene = yaml.safe_load(original)
    edit(scene)
    path.write_text(yaml.safe_dump(scene, sort_keys=False))
    try:
        return planned_jobs(workdir)
    finally:
        path.write_text(original)


@pytest.mark.slow
def test_editing_physics_reruns_all_but_reconstruct(finished_run):
    plan = jobs_after_edit(finished_run, lambda s: s["physics"].update(duration_s=0.125))
    assert plan == {"simulate": 1, "render": 1, "enhance": 1, "plots": 1}  # plots: the report's, after the video


@pytest.mark.slow
def test_editing_enhance_reruns_only_enhance(finished_run):
    assert jobs_after_edit(finished_run, lambda s: s["enhance"].update(confidence_threshold=0.7)) == {"enhance": 1,
                                                                                                      "plots": 1}


@pytest.mark.slow
@pytest.mark.parametrize("program", ["pm-reconstruct", "pm-simulate", "pm-render", "pm-enhance"])
def test_program_refuses_wrong_artifact_without_output(finished_run, tmp_path, program):
    """Each program given the wrong artifact exits 2 with one paragraph and writes nothing."""
    r, s = finished_run / "results" / "tiny", finished_run / "scenes" / "tiny" / "scene.yaml"
    wrong = str(r / "coarse.h5") if program != "pm-render" else str(r / "gaussians.h5")
    out = tmp_path / "out.h5"
    args = {"pm-reconstruct": ["--out", str(out)],
            "pm-simulate": ["--gaussians", wrong, "--out", str(out)],
            "pm-render": ["--gaussians", wrong, "--trajectories", wrong, "--out", str(out),
                          "--video", str(tmp_path / "o.mp4")],
            "pm-enhance": ["--coarse", wrong, "--gaussians", wrong, "--out", str(tmp_path / "o.mp4")]}[program]
    scene = ["--scene", str(s)] if program != "pm-reconstruct" else ["--scene", str(tmp_path / "missing.yaml")]
    proc = subprocess.run([str(BIN / program), *scene, *args, "--device", "cpu"], env=ENV, capture_output=True,
                          text=True)
    assert proc.returncode == 2, proc.stderr
    assert "Fix:" in proc.stderr and "Traceback" not in proc.stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("program", ["pm-reconstruct", "pm-simulate", "pm-render", "pm-enhance"])
def test_help_says_what_it_does(program):
    proc = subprocess.run([str(BIN / program), "--help"], env=ENV, capture_output=True, text=True)
    assert proc.returncode == 0 and "--device" in proc.stdout and len(proc.stdout) > 400


@pytest.mark.slow
def test_killed_stage_leaves_no_artifact(tmp_path):
    scene = write_scene(tmp_path / "s")
    raw = yaml.safe_load(scene.read_text())
    raw["reconstruct"]["iterations"] = 100000
    scene.write_text(yaml.safe_dump(raw))
    out = tmp_path / "r" / "gaussians.h5"
    proc = subprocess.Popen([str(BIN / "pm-reconstruct"), "--scene", str(scene), "--out", str(out), "--device", "cpu"],
                            env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    for line in proc.stderr:
        if "iteration" in line:  # optimising
            break
    assert proc.poll() is None, "the stage should still be optimising"
    os.kill(proc.pid, signal.SIGKILL)
    proc.communicate()
    assert not out.exists()


def test_diffusion_scene_plans_lora_and_invert(tmp_path):
    scene = write_scene(tmp_path / "scenes" / "tiny")
    raw = yaml.safe_load(scene.read_text())
    raw["enhance"] = {"backend": "diffusion", "diffusion": {"lora": {"enabled": True}}}
    scene.write_text(yaml.safe_dump(raw))
    assert planned_jobs(tmp_path) == {"reconstruct": 1, "simulate": 1, "render": 1, "lora": 1, "invert": 1,
                                      "enhance": 1, "plots": 1}
    raw["enhance"]["diffusion"]["lora"]["enabled"] = False
    scene.write_text(yaml.safe_dump(raw))
    assert "lora" not in planned_jobs(tmp_path)


@pytest.mark.slow
def test_report_shows_each_scenes_video_sheet_setup_plots_and_times(finished_run):
    """snakemake --report embeds each item's bytes (base64) in one HTML file: each must be there, and the
    plots must hold the artifacts' own numbers."""
    import base64

    snakemake(finished_run, "--report", str(finished_run / "report.html"))
    html = (finished_run / "report.html").read_text()
    out = finished_run / "results" / "tiny"
    for name in ("video.mp4", "contact_sheet.png", "setup.png", "report/energy.svg", "report/momentum.svg",
                 "report/loss.svg", "report/stage_times.svg"):
        data = (out / name).read_bytes()
        assert base64.b64encode(data).decode()[:2000] in html, f"{name} is not in report.html"
    times = (out / "report" / "stage_times.svg").read_text()
    assert all(f">{stage}<" in times for stage in ("reconstruct", "simulate", "render", "enhance"))
    trajectories = read_artifact(out / "trajectories.h5", TrajectoriesArtifact)
    energy = (out / "report" / "energy.svg").read_text()
    assert energy.count("<polyline") == 3 and energy.count(",") >= 3 * len(trajectories.time_s)
    gaussians = read_artifact(out / "gaussians.h5", GaussiansArtifact)
    used = [t for i, t in enumerate(gaussians.loss_terms) if np.isfinite(gaussians.loss[:, i]).any()]  # NaN: unused
    loss = (out / "report" / "loss.svg").read_text()
    assert "total" in used and all(f">{term}<" in loss for term in used)
    assert loss.count("<polyline") == len(used)


def test_the_workflow_has_no_lint_findings(tmp_path):
    write_scene(tmp_path / "scenes" / "tiny")
    proc = run_snakemake(tmp_path / "scenes", tmp_path / "results", "--lint")
    assert proc.returncode == 0 and "Congratulations" in proc.stdout + proc.stderr, proc.stdout + proc.stderr


def test_the_config_is_checked_by_its_schema(tmp_path):
    write_scene(tmp_path / "scenes" / "tiny")
    for wrong, named in (("gpu=-1", "gpu"), ("devices=cpu", "devices"), ("device=tpu", "tpu")):
        proc = run_snakemake(tmp_path / "scenes", tmp_path / "results", "-n", config=(wrong,))
        out = proc.stdout + proc.stderr
        assert proc.returncode != 0 and named in out and "config.schema.yaml" in out, out


@pytest.mark.slow
def test_a_bad_scene_fails_its_own_job_and_the_good_one_runs(tmp_path):
    """A folder of a good scene and one with friction .inf: the bad one is one failing job whose paragraph names
    its key, with no traceback; the good one's reconstruction runs (the default profile keeps going)."""
    write_scene(tmp_path / "scenes" / "good")
    bad = tiny_scene_dict()
    bad["physics"]["ground"] = {"friction": float("inf")}
    write_scene(tmp_path / "scenes" / "bad one", bad)
    proc = run_snakemake(tmp_path / "scenes", tmp_path / "results", "--until", "reconstruct", "refused")
    out = proc.stdout + proc.stderr
    assert proc.returncode != 0
    assert "field 'physics.ground.friction'" in out and "Fix:" in out
    assert "Traceback" not in out and "InputFunctionException" not in out, out
    assert (tmp_path / "results" / "good" / "gaussians.h5").exists()
    assert not (tmp_path / "results" / "bad one" / "refused").exists()


@pytest.mark.slow
def test_after_ctrl_c_the_same_command_reruns_and_completes(tmp_path):
    """Ctrl-C (SIGINT to the process group, as a terminal sends it) while pm-simulate runs, then the README's
    command again: it completes, with no IncompleteFilesException to answer with --rerun-incomplete."""
    scene = tiny_scene_dict()
    scene["physics"]["duration_s"] = 2.0
    write_scene(tmp_path / "scenes" / "tiny", scene)
    command = snakemake_command(tmp_path / "scenes", tmp_path / "results", "--until", "simulate")
    proc = subprocess.Popen(command, cwd=tmp_path, env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    setup = tmp_path / "results" / "tiny" / "setup.png"
    deadline = time.time() + 300
    while not setup.exists() and proc.poll() is None and time.time() < deadline:
        time.sleep(0.2)
    assert proc.poll() is None, "the workflow should still be simulating"
    os.killpg(proc.pid, signal.SIGINT)
    proc.wait(timeout=120)
    assert not (tmp_path / "results" / "tiny" / "trajectories.h5").exists()
    rerun = subprocess.run(command, cwd=tmp_path, env=ENV, capture_output=True, text=True)
    assert rerun.returncode == 0, rerun.stdout[-2000:] + rerun.stderr[-2000:]
    assert "Incomplete" not in rerun.stderr and setup.exists()
