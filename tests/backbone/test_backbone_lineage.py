"""Lineage: every program refuses artifacts that do not belong together or to the scene, naming the files,
and refuses an output path that names one of its inputs."""
from pathlib import Path

import pytest
import yaml

from schemas.artifacts import read_header
from stages.enhance.cli import main as enhance
from stages.reconstruct.cli import main as reconstruct
from stages.simulate.cli import main as simulate
from stages.render.cli import main as render
from testing.tiny_scene import write_scene


def refusal(capsys, program, *args) -> str:
    """The one paragraph a program prints when it exits 2."""
    with pytest.raises(SystemExit) as exit_:
        program([*map(str, args), "--device", "cpu"])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and "Traceback" not in err, err
    return err


def run_all(scene: Path, out: Path, gaussians: Path | None = None) -> Path:
    """The four programs on ``scene`` into ``out`` (from ``gaussians`` when given)."""
    if gaussians is None:
        gaussians = out / "gaussians.h5"
        reconstruct(["--scene", str(scene), "--out", str(gaussians), "--device", "cpu"])
    simulate(["--scene", str(scene), "--gaussians", str(gaussians), "--out", str(out / "trajectories.h5"),
              "--device", "cpu"])
    render(["--scene", str(scene), "--gaussians", str(gaussians), "--trajectories", str(out / "trajectories.h5"),
            "--out", str(out / "coarse.h5"), "--video", str(out / "coarse.mp4"), "--device", "cpu"])
    return out


@pytest.fixture(scope="module")
def two_runs(tmp_path_factory):
    """Scene a; scene b, the same but pushed the other way, simulated from a's Gaussians; scene c, the same
    but reconstructed with more iterations."""
    top = tmp_path_factory.mktemp("lineage")
    scenes = {name: write_scene(top / name) for name in "abc"}
    for name, edit in (("b", lambda s: s["physics"]["conditions"][0].update(velocity=[-0.5, -0.5, 0.0])),
                       ("c", lambda s: s["reconstruct"].update(iterations=12))):
        raw = yaml.safe_load(scenes[name].read_text())
        edit(raw)
        scenes[name].write_text(yaml.safe_dump(raw))
    a = run_all(scenes["a"], top / "ra")
    b = run_all(scenes["b"], top / "rb", gaussians=a / "gaussians.h5")
    c = top / "rc"
    reconstruct(["--scene", str(scenes["c"]), "--out", str(c / "gaussians.h5"), "--device", "cpu"])
    return scenes, a, b, c


@pytest.mark.slow
def test_artifacts_record_what_they_were_made_from(two_runs):
    import json

    _, a, _, _ = two_runs
    coarse = json.loads(read_header(a / "coarse.h5")["inputs"])
    assert set(coarse["files"]) == {"gaussians", "trajectories"} and set(coarse["stages"]) == {"reconstruct",
                                                                                              "simulate"}
    assert set(json.loads(read_header(a / "gaussians.h5")["inputs"])["files"]) == {"image", "objects[0].mask"}


@pytest.mark.slow
def test_trajectories_of_other_gaussians_are_refused(two_runs, capsys, tmp_path):
    scenes, a, _, c = two_runs
    err = refusal(capsys, render, "--scene", scenes["c"], "--gaussians", c / "gaussians.h5", "--trajectories",
                  a / "trajectories.h5", "--out", tmp_path / "c.h5", "--video", tmp_path / "c.mp4")
    assert f"this trajectories.h5 was made from another gaussians.h5 than {c / 'gaussians.h5'}" in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_trajectories_of_another_scene_are_refused(two_runs, capsys, tmp_path):
    scenes, a, b, _ = two_runs
    err = refusal(capsys, render, "--scene", scenes["a"], "--gaussians", a / "gaussians.h5", "--trajectories",
                  b / "trajectories.h5", "--out", tmp_path / "c.h5", "--video", tmp_path / "c.mp4")
    assert f"{b / 'trajectories.h5'}, field 'config_hash'" in err and "other simulate keys" in err


@pytest.mark.slow
def test_enhance_refuses_a_coarse_of_another_scene(two_runs, capsys, tmp_path):
    """b's coarse.h5 has a's Gaussians and a's render keys: only its simulate keys tell it apart."""
    scenes, a, b, _ = two_runs
    err = refusal(capsys, enhance, "--scene", scenes["a"], "--gaussians", a / "gaussians.h5", "--coarse",
                  b / "coarse.h5", "--out", tmp_path / "v.mp4")
    assert f"{b / 'coarse.h5'}, field 'config_hash'" in err and "other simulate keys" in err


@pytest.mark.slow
def test_simulate_refuses_gaussians_of_another_scene(two_runs, capsys, tmp_path):
    scenes, _, _, c = two_runs
    err = refusal(capsys, simulate, "--scene", scenes["a"], "--gaussians", c / "gaussians.h5", "--out",
                  tmp_path / "t.h5")
    assert "other reconstruct keys" in err and list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_an_output_that_names_an_input_is_refused(two_runs, capsys):
    scenes, a, _, _ = two_runs
    before = (a / "gaussians.h5").read_bytes()
    err = refusal(capsys, simulate, "--scene", scenes["a"], "--gaussians", a / "gaussians.h5", "--out",
                  a / "gaussians.h5")
    assert "--out names the same file as --gaussians" in err
    err = refusal(capsys, render, "--scene", scenes["a"], "--gaussians", a / "gaussians.h5", "--trajectories",
                  a / "trajectories.h5", "--out", a / "coarse.h5", "--video", a / "coarse.h5")
    assert "--video names the same file as --out" in err
    assert (a / "gaussians.h5").read_bytes() == before


@pytest.mark.slow
def test_a_file_of_another_kind_is_named_as_such_not_as_another_lineage(two_runs, capsys, tmp_path):
    scenes, a, _, _ = two_runs
    err = refusal(capsys, simulate, "--scene", scenes["a"], "--gaussians", a / "coarse.h5", "--out", tmp_path / "t.h5")
    assert "not 'physmotion.gaussians'" in err and "made from another" not in err
