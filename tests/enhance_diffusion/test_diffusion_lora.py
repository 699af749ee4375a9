"""LoRA personalisation: a step lowers the loss, the LoRA survives a save/load round trip, the training images."""
import numpy as np
import torch

from stages.enhance.diffusion.lora import add_lora, diffusion_loss, load_lora, save_lora, training_images
from testing.tiny_diffusion import tiny_components


def test_a_training_step_lowers_the_loss_on_its_batch():
    model = tiny_components("v_prediction", seed=5)
    parameters = add_lora(model.unet, rank=4)
    assert parameters and all("lora" in n for n, p in model.unet.named_parameters() if p.requires_grad)
    latents, text = torch.randn(2, 4, 8, 8), model.encode_prompt("a red cup").expand(2, -1, -1)
    optimizer = torch.optim.SGD(parameters, lr=1e-2)
    before = diffusion_loss(model, latents, text, torch.Generator().manual_seed(0))  # same noise and t after
    before.backward()
    optimizer.step()
    with torch.no_grad():
        after = diffusion_loss(model, latents, text, torch.Generator().manual_seed(0))
    assert after < before


def test_the_loss_targets_v_for_v_prediction():
    model = tiny_components("v_prediction", seed=5)
    latents = torch.randn(1, 4, 8, 8)
    generator = torch.Generator().manual_seed(7)
    noise = torch.randn(latents.shape, generator=generator)
    t = torch.randint(0, 1000, (1,), generator=generator)
    a = model.scheduler.alphas_cumprod[t]
    v = a.sqrt() * noise - (1 - a).sqrt() * latents  # v = sqrt(a) eps - sqrt(1 - a) x0
    noisy = a.sqrt() * latents + (1 - a).sqrt() * noise
    text = model.encode_prompt("")
    with torch.no_grad():
        expected = torch.mean((model.unet(noisy, t, text).sample - v) ** 2)
        loss = diffusion_loss(model, latents, text, torch.Generator().manual_seed(7))
    torch.testing.assert_close(loss, expected, rtol=1e-5, atol=1e-6)


def test_a_saved_lora_loads_back_into_a_fresh_unet(tmp_path):
    trained = tiny_components(seed=5)
    parameters = add_lora(trained.unet, rank=2)
    with torch.no_grad():
        for p in parameters:
            p.add_(0.1 * torch.randn_like(p))
    save_lora(trained.unet, tmp_path / "lora")
    fresh, base = tiny_components(seed=5), tiny_components(seed=5)
    load_lora(fresh.unet, tmp_path / "lora")
    x, text = torch.randn(1, 4, 8, 8), trained.encode_prompt("a cup")
    with torch.no_grad():
        outputs = [m.unet(x, 300, text).sample for m in (trained, fresh, base)]
    assert torch.equal(outputs[0], outputs[1])
    assert not torch.allclose(outputs[1], outputs[2], atol=1e-4)


def test_training_images_show_the_object_on_white_and_the_extra_views():
    photo = np.zeros((40, 60, 3), np.uint8)
    photo[10:20, 30:50] = (200, 20, 20)
    mask = np.zeros((40, 60), np.uint8)
    mask[10:20, 30:50] = 1
    view = np.full((30, 50, 3), 7, np.uint8)
    images = training_images(photo, mask, [view], size=32)
    assert images.shape == (2, 32, 32, 3)
    assert np.array_equal(images[0, 16, 16], [200, 20, 20])  # object in the middle
    assert np.array_equal(images[0, 2, 2], [255, 255, 255]) and np.array_equal(images[0, 16, 1], [255, 255, 255])
    assert (images[1] == 7).all()
