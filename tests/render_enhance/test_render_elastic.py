"""An elastic solid's render stays its surface: a jelly sphere held at its base and pushed at its top (as the
coffee example's cup) never turns into grains, so no pixel of it shows a colour its surface does not have.

Known truth: the sphere's Gaussians are all one red, and its photograph is that red with scattered white pixels
(a glaze's specular highlights, which the fitted Gaussians average away). A jelly neither yields nor tears, so
every frame of its render is that red, shaded by its own coverage only: none of its pixels is paler."""
import numpy as np

from schemas import materials as M
from schemas.scene import PhysicsConfig
from stages.render.interior import LUMA
from stages.render.render import render_video
from stages.simulate.simulation import Simulation

from .test_render_flow import surfel_sphere

SIZE, FOCAL = 96, 200.0
RED = np.array([0.7, 0.15, 0.1])
HELD_AND_PUSHED = dict(duration_s=0.3, fps=20, grid=24, ground={"enabled": False}, conditions=[
    {"type": "fixed", "object": 0, "region": {"box": [0, 0.7, 0, 1, 1, 1]}},
    {"type": "force", "object": 0, "region": {"box": [0, 0, 0, 0.4, 0.4, 1]}, "force": [40.0, 0, 0],
     "start_s": 0.0, "end_s": 0.2}])


def glazed_sphere():
    """surfel_sphere in one red; its photograph that red with every eleventh pixel white."""
    gaussians = surfel_sphere(size=SIZE, focal=FOCAL)
    gaussians.colors[:] = RED
    rows, cols = np.indices((SIZE, SIZE))
    gaussians.photo[:] = np.where(((rows * 7 + cols * 3) % 11 == 0)[..., None], 255, np.round(255 * RED)).astype(np.uint8)
    return gaussians


def test_a_held_and_pushed_jelly_shows_no_paler_pixel():
    """Every pixel of at least half coverage has a luma at most 3 levels above the red's (u8 rounding): no white
    highlight of the photograph drawn as a grain, no pale speck where the surface stretches."""
    gaussians = glazed_sphere()
    trajectories = Simulation(PhysicsConfig(**HELD_AND_PUSHED), [M.Jelly(youngs_modulus=5e4)], gaussians.means,
                              gaussians.object_id, device="cpu").run()
    moved = np.abs(trajectories.positions[-1] - trajectories.positions[0]).max()
    assert moved > 0.01, f"the push moves the sphere {1000 * moved:.1f} mm"
    coarse = render_video(gaussians, trajectories, width=SIZE, device="cpu")
    red_luma = 255 * RED @ LUMA
    for t in range(len(trajectories.time_s)):
        covered = coarse.alpha[t] >= 0.5
        luma = coarse.rgb[t][covered].astype(float) @ LUMA
        paler = int((luma > red_luma + 3).sum())
        assert paler == 0, f"frame {t}: {paler} px paler than the surface (luma up to {luma.max():.0f}, red {red_luma:.0f})"
