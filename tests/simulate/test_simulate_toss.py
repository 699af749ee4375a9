"""A body tossed straight up comes down where it went up: reconstructed synthetic balls, not hand-placed spheres.

A 12 cm ball is ray-cast (testing/photographs.py) under a level and a pitched camera, reconstructed
by pm-reconstruct from a 192 x 144 photograph, and tossed straight up (against gravity) at 1.2 m/s. Over 1 s
its centre of mass may drift along the ground by at most 2 % of its size and it may turn at most 3 degrees;
its total energy (trajectories' kinetic + potential diagnostics) never rises above its value just after the
toss by more than 2 % of the toss's kinetic energy. Every preset of the issue runs on friction and slip ground
under both cameras: rigid, metal, plasticine and jelly, 16 cases.

The grid has 16 cells along the domain, 8 across the ball (about 4200 particles): the claim is the body's,
not the resolution's, and it holds at every grid measured. Jelly on slip ground turns 0.37 and 0.69 degrees
(level, pitched) at 16 cells, 0.17 and 0.30 at 20, 0.32 and 0.71 at 24; every other case turns at most 0.16
degrees and drifts at most 0.1 % of its size. The 16 cases take 65 s of CPU at 16 cells, about 140 s at 24
(docs/decisions/0038-the-suite-s-time.md).

Jelly (E = 5e4 Pa) bounces four times in the second, and each landing turns it by the lever between its
contact and its centre of mass: a frictionless ground gives no other torque, and the solver adds no lever
of its own (tests/simulate/test_simulate_physics.py: mirror images spin mirrored, a mirror-symmetric ball
not at all). So the ball passes because its body is the closure's own solid (gaussians.h5's
/objects/solid), whose bottom lies under its centre of mass; a ball filled from its Gaussians' means has
its ground node layer's mass centroid 0.89 mm (level) and 0.57 mm (pitched) off its centre of mass and
turns 46 and 39 degrees on slip ground at 24 cells (docs/decisions/0029-toss-spin-is-the-body-s.md). At
most 3 degrees in four bounces asks for a lever of a few hundredths of a millimetre.
"""
from __future__ import annotations

import functools

import numpy as np
import pytest

from schemas import materials as M
from schemas.artifacts import GaussiansArtifact, read_artifact
from schemas.scene import PhysicsConfig
from stages.reconstruct.cli import main as reconstruct
from testing.photographs import Capsule, write_scene
from stages.simulate.rest_state import turn_deg
from stages.simulate.simulation import Simulation

SIZE = 0.12
SPEED = 1.2  # m/s straight up
GRID = 16  # cells along the domain: 8 across the ball, about 4200 particles


@pytest.fixture(scope="session")
def reconstructed_balls(tmp_path_factory):
    """pitch in degrees -> gaussians artifact of the 12 cm ball 0.6 m away on the optical axis, reconstructed once
    per pitch and worker: the session scope lets the cases run on either xdist worker (tests/conftest.py)."""
    @functools.cache
    def reconstructed(pitch: float) -> GaussiansArtifact:
        folder = tmp_path_factory.mktemp(f"ball_{pitch:g}")
        shape = Capsule(np.array([0.0, 0.0, 0.6]), np.array([1e-6, 0.0, 0.0]), SIZE / 2)
        scene = write_scene(folder, shape, width=192, height=144, iterations=50, pitch_deg=pitch)
        reconstruct(["--scene", str(scene), "--out", str(folder / "gaussians.h5"), "--device", "cpu"])
        return read_artifact(folder / "gaussians.h5", GaussiansArtifact)

    return reconstructed


@pytest.fixture(params=[0.0, 25.0], ids=["level", "pitched"])
def ball(request, reconstructed_balls):
    """(gaussians artifact, camera pitch in degrees)."""
    return reconstructed_balls(request.param), request.param


@pytest.mark.parametrize("material", [M.Rigid(), M.Metal(), M.Plasticine(), M.Jelly()],
                         ids=["rigid", "metal", "plasticine", "jelly"])
@pytest.mark.parametrize("ground", ["friction", "slip"])
def test_a_ball_tossed_straight_up_comes_down_where_it_went_up(ball, material, ground):
    gaussians, pitch = ball
    physics = PhysicsConfig(duration_s=1.0, fps=24, grid=GRID, ground={"type": ground, "friction": 0.4},
                            conditions=[{"type": "impulse", "velocity": [0.0, -SPEED, 0.0]}])
    sim = Simulation(physics, [material], gaussians.means, gaussians.object_id, pitch_deg=pitch,
                     solids=gaussians.solids())
    tr = sim.run()
    centre = (tr.masses @ tr.positions) / tr.masses.sum()
    along = (centre - centre[0]) @ sim.Q.T  # simulation frame: y up
    assert along[:, 1].max() > 0.05  # it flew (1.2 m/s rises 73 mm)
    assert np.max(np.linalg.norm(along[:, [0, 2]], axis=1)) <= 0.02 * SIZE
    assert max(turn_deg(tr.positions[0], tr.positions[f], tr.masses) for f in range(len(tr.time_s))) <= 3.0
    total = tr.kinetic_energy + tr.potential_energy
    assert np.max(total[1:] - total[1]) <= 0.02 * tr.kinetic_energy[1]
