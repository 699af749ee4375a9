"""DDIM+ inversion and sampling: the algebra is exact, and the real model's error falls with steps."""
import dataclasses

import pytest
import torch

from schemas.diffusion import DiffusionSettings
from stages.enhance.diffusion.components import Components
from stages.enhance.diffusion.inversion import CLEAN, inverse_scheduler, invert, stored_timesteps
from stages.enhance.diffusion.sampling import sample, sampling_timesteps
from testing.tiny_diffusion import tiny_components


@dataclasses.dataclass
class TimeOnly(Components):
    """A model whose output depends on the timestep only: DDIM inversion is then exactly invertible."""

    def predict(self, latents, timestep, text, controls, control_scale):
        pattern = torch.linspace(-1, 1, latents[0].numel()).view(latents.shape[1:])
        return (torch.sin(0.01 * timestep + 3 * pattern)).expand_as(latents).to(latents)


def _controls(frames: int, size: int = 64):
    return [torch.rand(frames, 3, size, size) for _ in range(2)]


def test_first_inversion_step_matches_the_ddim_formula():
    base = tiny_components("epsilon")
    model = TimeOnly(**{f.name: getattr(base, f.name) for f in dataclasses.fields(Components)})
    scheduler = inverse_scheduler(model, 1000, 20)
    x0 = torch.randn(2, 4, 8, 8)
    trajectory = invert(model, x0, model.encode_prompt("a cup"), _controls(2), 1.0, scheduler)
    t = 1  # SD 2.1: steps_offset 1; the step before it is the clean level alphas_cumprod[0]
    a_prev, a_t = base.scheduler.alphas_cumprod[0], base.scheduler.alphas_cumprod[t]
    eps = model.predict(x0, t, None, None, None)
    x0_pred = (x0 - (1 - a_prev).sqrt() * eps) / a_prev.sqrt()
    expected = a_t.sqrt() * x0_pred + (1 - a_t).sqrt() * eps
    assert stored_timesteps(scheduler)[:3] == [CLEAN, 1, 21]
    assert trajectory.shape == (2, 51, 4, 8, 8)
    torch.testing.assert_close(trajectory[:, 1], expected, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("stride,steps", [(20, 50), (100, 10)])
def test_sampling_undoes_inversion_exactly_for_a_time_only_model(stride, steps):
    base = tiny_components("epsilon")
    model = TimeOnly(**{f.name: getattr(base, f.name) for f in dataclasses.fields(Components)})
    scheduler = inverse_scheduler(model, 1000, stride)
    x0 = torch.randn(3, 4, 8, 8)
    text = model.encode_prompt("a red cup")
    controls = _controls(3)
    inverted = invert(model, x0, text, controls, 1.0, scheduler)
    settings = DiffusionSettings(steps=steps, inversion_stride=stride, frame_batch=2, keyframe_window=2)
    out = sample(model, inverted, stored_timesteps(scheduler), controls, text, model.encode_prompt(""), settings)
    torch.testing.assert_close(out, x0, rtol=0, atol=1e-5)


def test_sampling_needs_inverted_latents_at_its_timesteps():
    base = tiny_components("epsilon")
    scheduler = inverse_scheduler(base, 1000, 100)
    with pytest.raises(ValueError, match="not inverted"):
        sampling_timesteps(base, 50, stored_timesteps(scheduler))


def test_round_trip_error_falls_with_step_count_on_the_v_prediction_model(tiny):
    """One frame and CFG 1: the sampler (injection, keyframe attention and all) must replay the inversion."""
    assert tiny.scheduler.config.prediction_type == "v_prediction"
    x0 = tiny.encode_images(torch.rand(1, 3, 64, 64))
    text = tiny.encode_prompt("a red cup")
    controls = _controls(1)
    errors = []
    for stride in (250, 100, 25):
        scheduler = inverse_scheduler(tiny, 1000, stride)
        inverted = invert(tiny, x0, text, controls, 1.0, scheduler)
        settings = DiffusionSettings(steps=1000 // stride, inversion_stride=stride, guidance_scale=1.0)
        out = sample(tiny, inverted, stored_timesteps(scheduler), controls, text, tiny.encode_prompt(""), settings)
        errors.append((out - x0).abs().max().item() / x0.abs().max().item())
    assert errors[0] > errors[1] > errors[2], errors
