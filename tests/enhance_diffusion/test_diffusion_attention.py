"""Video attention processors, injection hooks, keyframe attention and propagation (Eq. 12-15)."""
import math

import numpy as np
import pytest
import torch

from schemas.diffusion import DiffusionSettings
from stages.enhance.diffusion.attention import SamplingState, VideoAttnProcessor
from stages.enhance.diffusion.injection import video_attention
from stages.enhance.diffusion.inversion import inverse_scheduler, invert, stored_timesteps
from stages.enhance.diffusion.keyframes import draw_keyframes, keyframe_neighbours, nearest_tokens, propagate
from stages.enhance.diffusion.sampling import sample


def _batch(tiny, frames: int, branches: int = 3, same: bool = False):
    """UNet inputs for ``branches`` x ``frames`` items, branch-major; distinct latents and prompts per branch."""
    latents = torch.randn(1 if same else branches, frames, 4, 8, 8).expand(branches, -1, -1, -1, -1)
    texts = [tiny.encode_prompt(p) for p in ("a red cup", "", "a red cup on a wooden table")[:branches]]
    text = torch.cat([(texts[0] if same else t).expand(frames, -1, -1) for t in texts])
    return latents.reshape(branches * frames, 4, 8, 8), text


def _unet(tiny, latents, text, t=500):
    with torch.no_grad():
        return tiny.unet(latents, t, encoder_hidden_states=text).sample


def test_processors_without_injection_are_bit_identical_to_stock_attention(tiny):
    latents, text = _batch(tiny, frames=2)
    stock = _unet(tiny, latents, text)
    with video_attention(tiny.unet, SamplingState(branches=3)):
        ours = _unet(tiny, latents, text)
    assert torch.equal(ours, stock)
    assert all(type(p).__name__ != "VideoAttnProcessor" for p in tiny.unet.attn_processors.values())


def test_injection_leaves_the_coarse_branch_unchanged_and_copies_decoder_features(tiny):
    latents, text = _batch(tiny, frames=2)
    stock = _unet(tiny, latents, text)
    seen = []
    with video_attention(tiny.unet, SamplingState(branches=3, inject_features=True, inject_qk=True)):
        # registered after the injection hook, so it sees what the next layer receives
        capture = tiny.unet.up_blocks[2].resnets[1].register_forward_hook(lambda m, i, o: seen.append(o))
        ours = _unet(tiny, latents, text)
        capture.remove()
    assert torch.equal(ours[:2], stock[:2])  # coarse branch: frames 0 and 1
    assert not torch.allclose(ours[2:], stock[2:], atol=1e-3)
    f_coarse, f_uncond, f_cond = seen[0].chunk(3)
    assert torch.equal(f_uncond, f_coarse) and torch.equal(f_cond, f_coarse)  # f_e <- f_c


def _attention_layer(tiny):
    return tiny.unet.up_blocks[1].attentions[0].transformer_blocks[0].attn1


def _reference_attention(attn, q, k, v):
    """softmax(q k^T / sqrt(d)) v per head, then the output projection; q, k, v: (N, C)."""
    h = attn.heads
    d = q.shape[-1] // h
    heads = [torch.softmax(q[:, i * d:(i + 1) * d] @ k[:, i * d:(i + 1) * d].T / math.sqrt(d), -1)
             @ v[:, i * d:(i + 1) * d] for i in range(h)]
    return attn.to_out[0](torch.cat(heads, -1))


def test_qk_injection_uses_coarse_queries_and_keys_with_own_values(tiny):
    attn = _attention_layer(tiny)
    x = torch.randn(3, 16, attn.to_q.in_features)  # 3 branches x 1 frame
    state = SamplingState(branches=3, inject_qk=True)
    with torch.no_grad():
        out = VideoAttnProcessor(state, "layer", in_decoder=True)(attn, x)
        for b in range(3):
            ref = _reference_attention(attn, attn.to_q(x[0]), attn.to_k(x[0]), attn.to_v(x[b]))
            torch.testing.assert_close(out[b], ref, rtol=1e-5, atol=1e-5)
        encoder = VideoAttnProcessor(state, "layer", in_decoder=False)(attn, x)  # no injection outside the decoder
        ref = _reference_attention(attn, attn.to_q(x[2]), attn.to_k(x[2]), attn.to_v(x[2]))
        torch.testing.assert_close(encoder[2], ref, rtol=1e-5, atol=1e-5)


def test_extended_attention_follows_eq_12_13(tiny):
    attn = _attention_layer(tiny)
    frames = 2
    x = torch.randn(3 * frames, 16, attn.to_q.in_features)
    state = SamplingState(branches=3, pass_kind="keyframes", frames=[0, 3], keyframes=[0, 3])
    with torch.no_grad():
        out = VideoAttnProcessor(state, "layer", in_decoder=False)(attn, x).view(3, frames, 16, -1)
        for b in (1, 2):
            own = x[b * frames:(b + 1) * frames]
            keys, values = attn.to_k(own.flatten(0, 1)), attn.to_v(own.flatten(0, 1))  # [K_j1, K_j2], [V_j1, V_j2]
            for f in range(frames):
                ref = _reference_attention(attn, attn.to_q(own[f]), keys, values)
                torch.testing.assert_close(out[b, f], ref, rtol=1e-5, atol=1e-5)
        coarse = _reference_attention(attn, *(p(x[1]) for p in (attn.to_q, attn.to_k, attn.to_v)))
        torch.testing.assert_close(out[0, 1], coarse, rtol=1e-5, atol=1e-5)  # coarse branch: per frame
    assert state.recorded["layer"].shape == (3, frames, 16, attn.to_q.in_features)


def test_extended_attention_over_one_keyframe_is_ordinary_self_attention(tiny):
    latents, text = _batch(tiny, frames=1)
    stock = _unet(tiny, latents, text)
    with video_attention(tiny.unet, SamplingState(branches=3, pass_kind="keyframes", frames=[0], keyframes=[0])):
        ours = _unet(tiny, latents, text)
    torch.testing.assert_close(ours, stock, rtol=1e-6, atol=1e-6)


def test_propagation_onto_the_keyframes_reproduces_their_outputs_exactly(tiny):
    latents, text = _batch(tiny, frames=2)
    state = SamplingState(branches=3, inject_features=True, inject_qk=True, keyframes=[0, 2])
    with video_attention(tiny.unet, state):
        state.pass_kind, state.frames = "keyframes", [0, 2]
        keyframe_pass = _unet(tiny, latents, text)
        state.pass_kind = "propagate"
        propagated = _unet(tiny, latents, text)
    assert torch.equal(propagated, keyframe_pass)


def test_nearest_tokens_is_the_cosine_nearest_neighbour_in_any_chunking():
    gen = torch.Generator().manual_seed(0)
    query, keys = torch.randn(50, 8, generator=gen), torch.randn(40, 8, generator=gen)
    distance = 1 - (query / query.norm(dim=1, keepdim=True)) @ (keys / keys.norm(dim=1, keepdim=True)).T
    expected = distance.argmin(dim=1)
    for rows in (1, 7, 50):
        assert torch.equal(nearest_tokens(query, keys, rows), expected)
    assert torch.equal(nearest_tokens(3 * keys, keys), torch.arange(40))  # scale does not matter


@pytest.mark.parametrize("frame,expected", [(0, (0, 0, 0.0)), (2, (0, 5, 0.4)), (5, (5, 5, 0.0)),
                                            (7, (5, 9, 0.5)), (11, (9, 9, 0.0))])
def test_keyframe_weights_follow_eq_14(frame, expected):
    assert keyframe_neighbours(frame, [0, 5, 9]) == pytest.approx(expected)


def test_propagate_blends_the_matched_outputs_of_both_neighbours():
    gen = torch.Generator().manual_seed(1)
    features = torch.randn(2, 12, 6, generator=gen)  # keyframes 0 and 4
    outputs = torch.randn(2, 2, 12, 6, generator=gen)  # 2 branches
    frame_features = features[1, torch.randperm(12, generator=gen)]  # the future keyframe's tokens, shuffled
    out = propagate(1, [0, 4], frame_features, features, outputs)
    past = [int(np.argmax([torch.cosine_similarity(f, g, dim=0) for g in features[0]])) for f in frame_features]
    future = [int(np.argmax([torch.cosine_similarity(f, g, dim=0) for g in features[1]])) for f in frame_features]
    expected = 0.25 * outputs[:, 1, future] + 0.75 * outputs[:, 0, past]
    torch.testing.assert_close(out, expected)
    torch.testing.assert_close(propagate(4, [0, 4], frame_features, features, outputs), outputs[:, 1])


def test_keyframes_hold_the_first_frame_and_one_per_window():
    rng = np.random.default_rng(0)
    draws = [draw_keyframes(12, 5, rng) for _ in range(40)]
    for keys in draws:
        assert keys[0] == 0 and len(keys) == 3
        assert 5 <= keys[1] < 10 and 10 <= keys[2] < 12
    assert len({tuple(k) for k in draws}) > 1  # redrawn, not fixed
    assert draw_keyframes(1, 5, rng) == [0]


def test_sampler_without_injection_on_one_frame_is_plain_ddim(tiny):
    """tau_f = tau_A = 0, one frame, CFG 1: the sampler must equal a DDIM loop written with diffusers alone."""
    from diffusers import DDIMScheduler

    x0 = tiny.encode_images(torch.rand(1, 3, 64, 64))
    text = tiny.encode_prompt("a red cup")
    controls = [torch.rand(1, 3, 64, 64) for _ in range(2)]
    scheduler = inverse_scheduler(tiny, 1000, 200)
    inverted = invert(tiny, x0, text, controls, 1.0, scheduler)
    settings = DiffusionSettings(steps=5, inversion_stride=200, guidance_scale=1.0, tau_f=0, tau_a=0)
    ours = sample(tiny, inverted, stored_timesteps(scheduler), controls, text, tiny.encode_prompt(""), settings)
    reference = DDIMScheduler.from_config(tiny.scheduler.config)
    reference.set_timesteps(5)
    x = inverted[:, -1]
    for t in reference.timesteps:
        x = reference.step(tiny.predict(x, int(t), text, controls, 1.0), t, x).prev_sample
    torch.testing.assert_close(ours, x, rtol=1e-5, atol=1e-5)
