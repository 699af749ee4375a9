"""pm-simulate as a program and its building blocks: fill, gravity/frame, regions, errors, the artifact."""
from __future__ import annotations

import contextlib
import io
import logging
import math
import re
import signal
import time

import cv2
import numpy as np
import pytest
import warp as wp

from schemas import InputError
from schemas import materials as M
from schemas.artifacts import GaussiansArtifact, TrajectoriesArtifact, read_artifact, write_artifact
from schemas.scene import PhysicsConfig, SphereRegion
from schemas.solid import solid_fields
from stages.simulate import cli, domain
from stages.simulate.conditions import region_members
from stages.simulate.fill import fill_object, fill_solid
from scipy.spatial import cKDTree

from stages.simulate.simulation import Simulation
from testing.particles import box_surface, boxes, fibonacci_sphere, sphere_solid

wp.config.quiet = True


def test_fill_of_a_sphere_shell_has_the_sphere_volume():
    """Ray-parity fill of Gaussians on a sphere's surface: volume within 4 % of 4/3 pi r^3, the requested
    density (8 per interior cell), and every fill particle within half a lattice cell's diagonal of the
    surface: the occupancy is resolved at the lattice spacing dx / 2, whose cells hold a Gaussian or lie
    inside (on whole simulation cells the staircase reached 1.15 dx out and the volume was 6 % over)."""
    rng = np.random.default_rng(0)
    d = rng.standard_normal((20000, 3))
    r, dx = 0.1, 0.01
    means = r * d / np.linalg.norm(d, axis=1, keepdims=True)
    fill, volume = fill_object(means, dx, 8)
    assert volume.sum() == pytest.approx(4 / 3 * math.pi * r ** 3, rel=0.04)
    assert np.linalg.norm(fill, axis=1).max() < r + math.sqrt(3) / 2 * (dx / 2)
    assert len(fill) == pytest.approx(8 * 4 / 3 * math.pi * (r / dx) ** 3, rel=0.12)


@pytest.mark.parametrize("spacing", [0.004, 0.0065, 0.01])
def test_a_solid_is_filled_with_its_volume_whatever_the_lattice(spacing):
    """fill.fill_solid: a 5 cm ball's signed distance holds 4/3 pi r^3 within 1.5 % at three lattice spacings
    (each particle its cell's share inside; 1.3 % over at a fifth of the radius, where a cell's share
    counts the curved surface as flat), and its particles' centre of volume lies on the solid's centre
    within a nanometre (the lattice is laid from it, mirror-symmetric)."""
    centre, r = np.array([0.01, -0.02, 0.5]), 0.05
    Q = domain.simulation_rotation(np.array([0.0, 1.0, 0.0]))
    fill, volumes = fill_solid(sphere_solid(centre, r), Q, spacing)
    assert volumes.sum() == pytest.approx(4 / 3 * math.pi * r ** 3, rel=0.015)
    np.testing.assert_allclose(volumes @ fill / volumes.sum(), Q @ centre, atol=1e-9)


@pytest.mark.parametrize("dx", [0.013, 0.0175, 0.025])
def test_fill_volume_does_not_depend_on_the_lattice(dx):
    """The surface cuts the outer cells where the means lie, not at a cell's middle: a 10 cm box of surface
    points 1 cm apart, straight and turned, and a ball of 5 cm radius keep their analytic volume within 5 %
    at three cell sizes (counting outer cells half gave 0.78 to 1.10 of the box); the same box moved by a
    fraction of a cell gets the same solid to 0.5 % (the lattice is laid from the body's centre; laid from its
    corner, two such boxes differed by 7.5 %)."""
    box = box_surface(np.zeros(3), np.full(3, 0.1), 0.01)
    turned = box @ np.array(cv2.Rodrigues(np.array([0.35, 0.52, 0.17]))[0]).T
    ball = fibonacci_sphere(4000, 0.05)

    def volume(means):
        return fill_object(means, dx, 8).volume.sum()

    assert volume(box) == pytest.approx(1e-3, rel=0.05)
    assert volume(turned) == pytest.approx(1e-3, rel=0.05)
    assert volume(ball) == pytest.approx(4 / 3 * math.pi * 0.05 ** 3, rel=0.05)
    assert volume(box + 0.37 * dx) == pytest.approx(volume(box), rel=5e-3)


def test_fill_ignores_huge_covariances_and_is_bounded_by_the_grid():
    """Only the means matter: the occupancy grid is at most (extent / dx + 3)^3 cells whatever else."""
    means = box_surface((0, 0, 0), (0.1, 0.05, 0.02), 0.005)
    fill = fill_object(means, 0.01, 1).fill
    assert len(fill) <= (10 + 3) * (5 + 3) * (2 + 3)
    assert np.all((fill > -0.011) & (fill < 0.111))


def test_default_gravity_turns_with_camera_pitch_and_frame_is_a_rotation():
    g = domain.world_gravity(None, 30.0)
    np.testing.assert_allclose(g, 9.81 * np.array([0, math.cos(math.radians(30)), math.sin(math.radians(30))]))
    Q = domain.simulation_rotation(g / np.linalg.norm(g))
    np.testing.assert_allclose(Q @ Q.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(Q) == pytest.approx(1.0)
    np.testing.assert_allclose(Q @ g, [0, -9.81, 0], atol=1e-12)  # gravity is -y in the simulation frame
    np.testing.assert_allclose(domain.world_gravity([1.0, 2.0, 3.0], 30.0), [1, 2, 3])


def test_regions_are_in_the_objects_normalised_box():
    x = np.array([[0.0, 0, 0], [1.0, 2, 4], [0.5, 1, 2], [0.9, 0.1, 0.1]])
    assert region_members("all", x).all()
    np.testing.assert_array_equal(region_members(SphereRegion(sphere=[0.5, 0.5, 0.5, 0.1]), x),
                                  [False, False, True, False])


def test_empty_region_is_an_input_error():
    means, oid = boxes(((0, 0, 0), (0.1, 0.1, 0.1)), spacing=0.01)
    with pytest.raises(InputError, match=r"conditions\[0\]\.region"):
        Simulation(PhysicsConfig(conditions=[{"type": "fixed", "region": {"sphere": [2, 2, 2, 0.1]}}]),
                   [M.Jelly()], means, oid)


def test_cfl_substep_shrinks_with_stiffness_and_speed():
    soft, stiff = M.Jelly(youngs_modulus=1e4), M.Jelly(youngs_modulus=1e6)
    assert domain.cfl_substep(0.01, [stiff], 0.0) == pytest.approx(domain.cfl_substep(0.01, [soft], 0.0) / 10)
    assert domain.cfl_substep(0.01, [soft], 10.0) < domain.cfl_substep(0.01, [soft], 0.0)


def test_a_condition_bounds_the_substep_only_in_the_frames_it_acts():
    """A 3 N push from 0.1 to 0.2 s on a 10 cm jelly box shortens the CFL substep of the frames it touches
    (a frame of its acceleration, F / M, added to the speeds); before and after them the substep is that of
    the same box with no push."""
    means, oid = boxes(((0, 0, 0.5), (0.1, 0.1, 0.6)), spacing=0.01)
    push = {"type": "force", "region": {"box": [0, 0, 0, 1, 1, 1]}, "force": [3.0, 0, 0], "start_s": 0.1, "end_s": 0.2}
    pushed, still = (Simulation(PhysicsConfig(grid=16, fps=20, duration_s=0.4, conditions=c), [M.Jelly()], means, oid)
                     for c in ([push], []))
    alone = still._cfl_substep(0.0)
    assert pushed._cfl_substep(0.0, 0.0, 0.05) == pytest.approx(alone)
    assert pushed._cfl_substep(0.0, 0.25, 0.3) == pytest.approx(alone)
    expected = domain.cfl_substep(pushed.grid.dx, [M.Jelly()], (9.81 + 3.0 / pushed.masses.sum()) / 20, 0.05)
    assert pushed._cfl_substep(0.0, 0.1, 0.15) == pytest.approx(expected) and expected < alone


@pytest.mark.parametrize("plastic_volume, hardening", [(1.0, 1.25), (0.95, 1.25 * math.exp(0.5)), (0.8, 5.0)])
def test_snow_steps_at_the_wave_speed_of_the_hardening_it_has(plastic_volume, hardening):
    """The CFL substep of a 10 cm snow box whose particles have compacted to J_p is CFL dx over its P-wave
    speed sqrt(k (lambda + 2 mu) / rho) plus a frame of free fall, k = 1.25 exp(xi (1 - J_p)) (xi = 10)
    the factor its hardening may reach in the next substep, at most the clamp's 5; with physics.dt set,
    the check of that dt takes the clamp's 5 whatever J_p is. E = 1.4e5 Pa, nu = 0.2, rho = 400 kg/m^3."""
    means, oid = boxes(((0, 0, 0.5), (0.1, 0.1, 0.6)), spacing=0.01)
    sim = Simulation(PhysicsConfig(grid=16, fps=20, duration_s=0.1), [M.Snow()], means, oid)
    sim.solver.history.fill_(plastic_volume)
    sim.solver.reset(sim.rest_sim, keep=np.ones(len(sim.masses), bool))
    mu, lam = 1.4e5 / (2 * 1.2), 1.4e5 * 0.2 / (1.2 * 0.6)
    speed = math.sqrt(hardening * (lam + 2 * mu) / 400.0)
    assert sim._cfl_substep(0.0) == pytest.approx(0.4 * sim.grid.dx / (speed + 9.81 / 20), rel=1e-6)
    fixed = Simulation(PhysicsConfig(grid=16, fps=20, duration_s=0.1, dt=1e-5), [M.Snow()], means, oid)
    clamp = math.sqrt(5.0 * (lam + 2 * mu) / 400.0)
    assert fixed._cfl_substep(0.0) == pytest.approx(0.4 * fixed.grid.dx / (clamp + 9.81 / 20), rel=1e-6)


def test_a_frame_re_split_past_max_substeps_per_frame_is_refused():
    """A snow frame re-splits its rest after every substep (its substep follows its hardening); where the
    re-split substep shrinks tenfold, the frame's count passes physics.max_substeps_per_frame, set at twice
    the first split's, and the run is refused naming that field (frame 1)."""
    means, oid = boxes(((0, 0, 0.5), (0.1, 0.1, 0.6)), spacing=0.01)
    sim = Simulation(PhysicsConfig(grid=16, fps=20, duration_s=0.1), [M.Snow()], means, oid)
    assert sim.solver.hardening_followed
    real, calls = sim.substep_size, []

    def shrinking(*args):
        calls.append(args)
        return real(*args) / (1 if len(calls) == 1 else 10)

    first = math.ceil(1 / 20 / real(0.0, 0.0, 1 / 20) - 1e-9)
    sim.physics.max_substeps_per_frame = 2 * first
    sim.substep_size = shrinking
    with pytest.raises(InputError, match="max_substeps_per_frame") as refusal:
        sim.run()
    assert "frame 1 " in str(refusal.value) and len(calls) >= 2


def test_snow_thrown_down_compacts_as_at_the_clamp_s_substep():
    """A 10 cm snow box thrown down at 2 m/s onto friction ground compacts (J_p falls) and stops; stepped at
    the hardening it has, it ends as it does at the substep of the clamp's fivefold stiffness (a physics.dt
    0.9 of that bound): its mean J_p within 0.005, every particle within a tenth of a cell. Its hardening
    reaches near the clamp in the impact, so it saves few substeps here (1809 against 2072)."""
    means, oid = boxes(((0, 0, 0.5), (0.1, 0.1, 0.6)), spacing=0.01)
    physics = dict(grid=16, fps=20, duration_s=0.2, ground={"type": "friction", "friction": 0.5},
                   conditions=[{"type": "impulse", "velocity": [0.0, 2.0, 0.0]}])  # world y is down
    followed = Simulation(PhysicsConfig(**physics), [M.Snow()], means, oid)
    bound = domain.cfl_substep(followed.grid.dx, [M.Snow()], 2.0 + 9.81 / 20, 1 / 20)
    clamped = Simulation(PhysicsConfig(**physics, dt=0.9 * bound), [M.Snow()], means, oid)
    runs = [(sim, sim.run()) for sim in (followed, clamped)]
    (_, a), (_, b) = runs
    compaction = [float(np.mean(sim.solver.history.numpy())) for sim, _ in runs]
    assert compaction[0] < 0.99 and abs(compaction[0] - compaction[1]) < 0.005
    assert np.max(np.linalg.norm(a.positions[-1] - b.positions[-1], axis=1)) < 0.1 * followed.grid.dx
    assert a.substeps.sum() < b.substeps.sum()


def make_gaussians(path, means, object_id):
    H, W = 120, 160
    f = H / 2 / math.tan(math.radians(20))
    G = len(means)
    photo = np.full((H, W, 3), 128, np.uint8)
    write_artifact(path, GaussiansArtifact(
        K=np.array([[f, 0, W / 2], [0, f, H / 2], [0, 0, 1]]), world_to_camera=np.eye(4), width=W, height=H,
        means=means, scales=np.full((G, 3), 0.004), rotations=np.tile([1.0, 0, 0, 0], (G, 1)),
        opacities=np.ones(G), colors=np.full((G, 3), 0.5), object_id=object_id, photo=photo,
        mask=np.zeros((H, W)), background=photo, depth_prior=np.zeros((H, W)),
        **solid_fields([None] * (int(np.max(object_id)) + 1)), loss=np.zeros((0, 1)),
        loss_terms=["l1"]), created_by="test", config_hash="0")


def test_program_writes_trajectories_and_setup_png(tmp_path):
    """pm-simulate end to end on two small objects: the artifact has DESIGN.md's layout (Gaussians first,
    frame 0 at rest with F = I), and setup.png is the photograph's size."""
    cv2.imwrite(str(tmp_path / "photo.png"), np.full((120, 160, 3), 128, np.uint8))
    (tmp_path / "scene.yaml").write_text(
        "image: photo.png\n"
        "objects:\n  - {size_m: 0.08, material: {preset: jelly}}\n  - {size_m: 0.08, material: {preset: metal}}\n"
        "physics:\n  duration_s: 0.1\n  fps: 20\n  grid: 16\n  ground: {type: slip}\n"
        "  conditions:\n    - {type: force, object: 1, region: {box: [0, 0, 0, 1, 0.5, 1]}, force: [0, -1, 0],"
        " start_s: 0, end_s: 0.05}\n")
    means, oid = boxes(((-0.1, 0, 0.5), (-0.02, 0.08, 0.58)), ((0.02, 0, 0.5), (0.1, 0.08, 0.58)), spacing=0.01)
    make_gaussians(tmp_path / "gaussians.h5", means, oid)
    out = tmp_path / "run" / "trajectories.h5"
    cli.main(["--scene", str(tmp_path / "scene.yaml"), "--gaussians", str(tmp_path / "gaussians.h5"),
              "--out", str(out), "--device", "cpu"])
    tr = read_artifact(out, TrajectoriesArtifact)
    G = len(means)
    P = len(tr.masses)
    assert tr.positions.shape[0] == 3 and tr.F.shape == (3, P, 3, 3) and P > G
    np.testing.assert_allclose(tr.positions[0, :G], means, atol=1e-6)
    np.testing.assert_allclose(tr.rest_positions, tr.positions[0], atol=1e-6)
    np.testing.assert_allclose(tr.F[0], np.broadcast_to(np.eye(3), (P, 3, 3)), atol=1e-6)
    assert tr.is_gaussian[:G].all() and not tr.is_gaussian[G:].any()
    assert set(np.unique(tr.material_id)) == {M.PRESETS.index("jelly"), M.PRESETS.index("metal")}
    assert tr.masses[tr.object_id == 1].sum() == pytest.approx(3000 * 0.08 ** 3, rel=0.25)
    assert tr.substeps[1] >= 1 and np.all(np.isfinite(tr.kinetic_energy))
    for k in (0, 1):  # the written lattice spacing is each fill's nearest-neighbour distance
        fill = tr.rest_positions[(tr.object_id == k) & ~tr.is_gaussian].astype(np.float64)
        assert np.median(cKDTree(fill).query(fill, k=2)[0][:, 1]) == pytest.approx(tr.lattice_spacing, rel=1e-5)
    setup = cv2.imread(str(tmp_path / "run" / "setup.png"))
    assert setup.shape == (120, 160, 3)


def test_program_refuses_a_bad_scene_with_exit_code_2(tmp_path, capsys):
    (tmp_path / "scene.yaml").write_text("image: missing.png\n")
    with pytest.raises(SystemExit) as exit_info:
        cli.main(["--scene", str(tmp_path / "scene.yaml"), "--gaussians", str(tmp_path / "g.h5"),
                  "--out", str(tmp_path / "t.h5"), "--device", "cpu"])
    assert exit_info.value.code == 2
    assert "image" in capsys.readouterr().err


# --- bad scenes the schema accepts (issue 33): each ends in a run or one paragraph, leaving nothing behind ---

PHOTO = "image: photo.png\n"


def program(tmp_path, scene: str, means=None, object_id=None, out=None) -> tuple[int, str]:
    """pm-simulate on `scene` (scene.yaml's text after `image:`) and a 10 cm jelly-sized box of Gaussians 0.5 m
    in front of the camera (or `means`, `object_id`): (exit code, stderr). The run's folder is tmp_path/run."""
    cv2.imwrite(str(tmp_path / "photo.png"), np.full((120, 160, 3), 128, np.uint8))
    (tmp_path / "scene.yaml").write_text(PHOTO + scene)
    if means is None:
        means, object_id = boxes(((-0.05, 0, 0.5), (0.05, 0.1, 0.6)), spacing=0.01)
    make_gaussians(tmp_path / "gaussians.h5", means, object_id)
    out = out or tmp_path / "run" / "trajectories.h5"
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        try:
            cli.main(["--scene", str(tmp_path / "scene.yaml"), "--gaussians", str(tmp_path / "gaussians.h5"),
                      "--out", str(out), "--device", "cpu"])
            code = 0
        except SystemExit as exit_info:
            code = exit_info.code
    return code, err.getvalue()


def refused(code: int, err: str, field: str) -> str:
    """The paragraph of a refusal (exit 2) naming `field`, without a traceback."""
    assert code == 2, err
    assert f"field '{field}'" in err and "Fix:" in err and "Traceback" not in err, err
    return err


def left_in(tmp_path) -> list:
    run = tmp_path / "run"
    return sorted(p.name for p in run.iterdir()) if run.exists() else []


JELLY = "objects:\n  - {size_m: 0.1, material: {preset: jelly}}\n"


def test_a_dt_above_the_cfl_bound_is_refused_up_front_and_the_advice_runs(tmp_path):
    """physics.dt 1 s (and 0.04 s, which a halving advice would have offered) is refused before any work,
    naming physics.dt and a value; that value runs to the end with finite positions."""
    for dt in (1.0, 0.04):
        err = refused(*program(tmp_path, JELLY + f"physics: {{duration_s: 0.2, fps: 10, grid: 12, dt: {dt}}}\n"),
                      "physics.dt")
        assert left_in(tmp_path) == []
    advice = float(re.search(r"set physics.dt to ([0-9.e+-]+) s or less", err).group(1))
    code, err = program(tmp_path, JELLY + f"physics: {{duration_s: 0.2, fps: 10, grid: 12, dt: {advice}}}\n")
    assert code == 0, err
    tr = read_artifact(tmp_path / "run" / "trajectories.h5", TrajectoriesArtifact)
    assert np.isfinite(tr.positions).all() and np.ptp(tr.positions[-1], axis=0).max() > 0.05


def test_a_huge_gravity_is_blamed_on_physics_gravity(tmp_path):
    code, err = program(tmp_path, JELLY + "physics: {duration_s: 0.2, fps: 10, grid: 12, gravity: [0, 1.0e6, 0]}\n")
    assert "9.81" in refused(code, err, "physics.gravity")
    assert left_in(tmp_path) == []


def test_an_impact_that_collapses_a_body_is_refused_naming_its_velocity_and_the_advice_runs(tmp_path):
    """A soft jelly thrown at 37 m/s between walls piles into a corner (the solver clamps particles onto the
    walls): refused, naming the impulse's velocity, nothing written; at the speed the message advises it runs
    and keeps its size."""
    scene = JELLY + ("physics:\n  duration_s: 0.2\n  fps: 10\n  grid: 12\n  walls: true\n"
                     "  conditions: [{type: impulse, velocity: [30, -20, 10]}]\n")
    err = refused(*program(tmp_path, scene), "physics.conditions[0].velocity")
    assert "collapsed" in err and left_in(tmp_path) == []
    speed = float(re.search(r"a speed below ([0-9.e+-]+) m/s", err).group(1))
    direction = np.array([30, -20, 10]) / np.linalg.norm([30, -20, 10])
    code, err = program(tmp_path, scene.replace("[30, -20, 10]", str([float(v) for v in 0.9 * speed * direction])))
    assert code == 0, err
    tr = read_artifact(tmp_path / "run" / "trajectories.h5", TrajectoriesArtifact)
    assert np.ptp(tr.positions[-1], axis=0).max() > 0.5 * np.ptp(tr.positions[0], axis=0).max()


def test_a_failed_run_leaves_no_setup_png(tmp_path, monkeypatch):
    """setup.png belongs to the trajectories: a run stopped (SIGINT) or failed after drawing it removes it."""
    from schemas.program import Stopped

    scene = JELLY + "physics: {duration_s: 0.2, fps: 10, grid: 12}\n"
    for failure, expected in ((Stopped(signal.SIGINT), 128 + signal.SIGINT), (MemoryError(), 2)):
        def fail(self, failure=failure):
            assert (tmp_path / "run" / "setup.png").exists()  # drawn before the run, for a look at it
            raise failure
        monkeypatch.setattr(Simulation, "run", fail)
        code, err = program(tmp_path, scene)
        assert code == expected and "Traceback" not in err, err
        assert left_in(tmp_path) == []


def test_out_given_as_a_folder_is_refused_up_front(tmp_path):
    (tmp_path / "run" / "trajectories.h5").mkdir(parents=True)
    code, err = program(tmp_path, JELLY)
    assert code == 2 and "--out" in err and "folder" in err and "Traceback" not in err, err
    assert left_in(tmp_path) == ["trajectories.h5"]


def warnings_of(caplog) -> list:
    return [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING and r.name.startswith("physmotion")]


@pytest.mark.parametrize("scene, scale", [
    (JELLY.replace("preset: jelly", "preset: jelly, density: 1.0e8"), 1.0),  # SVD failed in the settle's warning
    (JELLY.replace("size_m: 0.1", "size_m: 1000"), 1e4),  # the schema's largest body
])
def test_extreme_bodies_run_or_are_refused_in_one_paragraph(tmp_path, scene, scale):
    means, object_id = boxes(((-0.05, 0, 0.5), (0.05, 0.1, 0.6)), spacing=0.01)
    code, err = program(tmp_path, scene + "physics: {duration_s: 0.2, fps: 10, grid: 12}\n", means * scale, object_id)
    assert "Traceback" not in err
    if code:
        refused(code, err, err.split("field '")[1].split("'")[0])
        assert left_in(tmp_path) == []
    else:
        tr = read_artifact(tmp_path / "run" / "trajectories.h5", TrajectoriesArtifact)
        assert np.isfinite(tr.positions).all()


def test_an_absurdly_soft_body_ends_within_the_time_its_log_states(tmp_path, caplog):
    """Jelly of E = 1e-3 Pa (it cannot carry its weight): the log states the run's substeps before any, and
    the program ends, in a run or a paragraph, within a minute (it printed nothing for 300 s)."""
    caplog.set_level(logging.INFO, logger="physmotion")
    started = time.perf_counter()
    code, err = program(tmp_path, JELLY.replace("preset: jelly", "preset: jelly, youngs_modulus: 1.0e-3")
                        + "physics: {duration_s: 0.2, fps: 10, grid: 12}\n")
    assert time.perf_counter() - started < 60
    assert "Traceback" not in err and code in (0, 2), err
    messages = [r.getMessage() for r in caplog.records]
    assert any("substeps per frame at rest" in m for m in messages[:12]), messages[:12]


def test_no_weight_diagnostics_where_there_is_no_weight_or_no_shape_to_hold(tmp_path, caplog):
    """A sand box at rest warns of no sag beyond its own height, and a jelly in zero gravity of nothing about
    its weight (it warned of 5818.5 mm of sag for a 189 mm body, and of not resting under its own weight)."""
    caplog.set_level(logging.INFO, logger="physmotion")
    physics = "physics: {duration_s: 0.2, fps: 10, grid: 12%s}\n"
    code, err = program(tmp_path, JELLY.replace("preset: jelly", "preset: sand") + physics % "")
    assert code == 0, err
    for message in [r.getMessage() for r in caplog.records]:
        for sag in re.findall(r"([0-9.]+) mm of sag|sag of up to ([0-9.]+) mm", message):
            assert max(float(v or 0) for v in sag) < 100, message
    caplog.clear()
    code, err = program(tmp_path, JELLY + physics % ", gravity: [0, 0, 0]")
    assert code == 0, err
    assert not [m for m in warnings_of(caplog) if "weight" in m or "sag" in m], warnings_of(caplog)


def test_the_turn_of_a_blown_up_settle_is_nan_not_an_svd_failure():
    from stages.simulate import rest_state

    x = np.random.default_rng(0).random((20, 3))
    assert math.isnan(rest_state.turn_deg(x, np.full_like(x, np.nan), np.ones(20)))
    assert rest_state.turn_deg(x, x, np.ones(20)) == pytest.approx(0.0, abs=1e-5)


def test_a_youngs_modulus_too_stiff_to_afford_is_refused_with_one_that_runs(tmp_path):
    """Metal of real steel's E = 2e11 Pa asks for more substeps per frame than the limit: refused up front,
    naming a youngs_modulus; a scene at that value passes the same budget and runs."""
    physics = "physics: {duration_s: 0.1, fps: 10, grid: 12, max_substeps_per_frame: 400}\n"
    steel = JELLY.replace("preset: jelly", "preset: metal, youngs_modulus: 2.0e11, density: 7800")
    err = refused(*program(tmp_path, steel + physics), "objects[0].material.youngs_modulus")
    offered = re.search(r"youngs_modulus to ([0-9.e+]+) Pa or less", err).group(1)
    assert float(offered) < 2.0e11
    code, err = program(tmp_path, steel.replace("2.0e11", offered) + physics)
    assert code == 0, err


@pytest.mark.parametrize("speed, dented", [(0.2, False), (2.0, True)])
def test_metal_tossed_faster_than_its_yield_allows_is_said_to_dent(tmp_path, caplog, speed, dented):
    """The metal preset (E = 1e6 Pa, 3000 kg/m^3, yield 1.5e4 Pa) meets the ground with an impact stress
    sqrt(E rho) v: 1.1e4 Pa at 0.2 m/s stays elastic, 1.1e5 Pa at 2 m/s yields, and the log says which."""
    caplog.set_level(logging.INFO, logger="physmotion")
    toss = f"  conditions: [{{type: impulse, velocity: [0, -{speed}, 0]}}]\n"
    code, err = program(tmp_path, JELLY.replace("preset: jelly", "preset: metal")
                        + "physics:\n  duration_s: 0.1\n  fps: 10\n  grid: 12\n" + toss)
    assert code == 0, err
    assert any("dents and flattens" in m for m in warnings_of(caplog)) == dented, warnings_of(caplog)
