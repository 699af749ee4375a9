"""Model backends load real transformers models from a local folder: tiny random ones built from configs."""
import numpy as np
import pytest
import torch
from transformers import (DPTConfig, DPTForDepthEstimation, DPTImageProcessor, SamConfig, SamMaskDecoderConfig,
                          SamModel, SamProcessor, SamPromptEncoderConfig, SamVisionConfig)

from schemas import InputError
from schemas.artifacts import GaussiansArtifact, read_artifact
from stages.reconstruct.cli import main
from testing.photographs import Capsule, write_scene
from stages.reconstruct.depth import DptDepth, unit_distance_shape
from stages.reconstruct.segment import SamSegmenter


@pytest.fixture(scope="module")
def tiny_dpt(tmp_path_factory):
    folder = tmp_path_factory.mktemp("dpt")
    torch.manual_seed(0)
    config = DPTConfig(hidden_size=16, num_hidden_layers=4, num_attention_heads=2, intermediate_size=32, image_size=32,
                       patch_size=8, neck_hidden_sizes=[8, 8, 8, 8], fusion_hidden_size=8, head_hidden_size=8,
                       backbone_out_indices=[0, 1, 2, 3])
    DPTForDepthEstimation(config).save_pretrained(folder)
    DPTImageProcessor(size={"height": 32, "width": 32}).save_pretrained(folder)
    return folder


@pytest.fixture(scope="module")
def tiny_sam(tmp_path_factory):
    from transformers import SamImageProcessorPil

    folder = tmp_path_factory.mktemp("sam")
    torch.manual_seed(0)
    vision = SamVisionConfig(hidden_size=16, output_channels=16, num_hidden_layers=2, num_attention_heads=2,
                             image_size=64, patch_size=16, mlp_dim=32, global_attn_indexes=[1], window_size=2,
                             num_pos_feats=8)
    prompt = SamPromptEncoderConfig(hidden_size=16, image_size=64, patch_size=16, mask_input_channels=4)
    decoder = SamMaskDecoderConfig(hidden_size=16, num_hidden_layers=2, num_attention_heads=2, mlp_dim=32,
                                   iou_head_hidden_dim=16)
    SamModel(SamConfig(vision_config=vision.to_dict(), prompt_encoder_config=prompt.to_dict(),
                       mask_decoder_config=decoder.to_dict())).save_pretrained(folder)
    processor = SamImageProcessorPil(size={"longest_edge": 64}, pad_size={"height": 64, "width": 64},
                                     mask_size={"longest_edge": 16}, mask_pad_size={"height": 16, "width": 16})
    SamProcessor(image_processor=processor).save_pretrained(folder)
    return folder


def test_dpt_backend_gives_a_photo_sized_map_that_aligns_to_the_inflation(tiny_dpt):
    photo = np.random.default_rng(0).integers(0, 255, (40, 56, 3), dtype=np.uint8)
    inverse = DptDepth(tiny_dpt).inverse_depth(photo)
    assert inverse.shape == (40, 56) and np.isfinite(inverse).all()
    mask = np.zeros((40, 56), bool)
    mask[8:32, 10:46] = True
    # Alignment in inverse depth: a map that is an affine function of the inflation's own inverse depth
    # must come back as the inflation's front exactly.
    reference = unit_distance_shape(mask, 50.0)
    aligned = unit_distance_shape(mask, 50.0, np.where(mask, 3.0 / reference.front - 1.0, 0.0))
    assert np.allclose(aligned.front[mask], reference.front[mask], rtol=1e-6)


def test_missing_model_files_are_named(tmp_path):
    with pytest.raises(InputError, match="depth-estimation model file is missing") as err:
        DptDepth(tmp_path)
    assert err.value.file.endswith("config.json")
    (tmp_path / "config.json").write_text("{}")
    with pytest.raises(InputError, match="SAM processor file is missing"):
        SamSegmenter(tmp_path)


def test_sam_backend_returns_a_mask_of_the_photo(tiny_sam):
    photo = np.random.default_rng(1).integers(0, 255, (48, 64, 3), dtype=np.uint8)
    mask = SamSegmenter(tiny_sam).segment(photo, (8, 8, 40, 36))
    assert mask.shape == (48, 64) and mask.dtype == bool


def test_program_runs_with_both_model_backends(tiny_dpt, tiny_sam, tmp_path):
    scene = write_scene(tmp_path, Capsule.tilted(), width=64, height=48, iterations=2)
    # A box instead of the mask, so that SAM segments the object.
    scene.write_text(scene.read_text().replace("mask: mask.png", "box: [8, 6, 56, 42]"))
    main(["--scene", str(scene), "--out", str(tmp_path / "g.h5"), "--device", "cpu",
          "--depth-model", str(tiny_dpt), "--sam-model", str(tiny_sam)])
    g = read_artifact(tmp_path / "g.h5", GaussiansArtifact)
    on = g.mask > 0
    assert on.any() and np.isfinite(g.depth_prior[on]).all() and np.isnan(g.depth_prior[~on]).all()
    assert len(g.means) > 0
