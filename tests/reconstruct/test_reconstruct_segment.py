"""Segmentation and background against a synthetic photograph whose mask is known."""
import cv2
import numpy as np
import pytest

from schemas import InputError
from stages.reconstruct.background import inpaint_background
from stages.reconstruct.geometry import intrinsics_from_fov
from stages.reconstruct.metrics import iou
from stages.reconstruct.segment import ObjectSpec, segment_objects
from stages.reconstruct.synthetic import Capsule, photograph


@pytest.fixture(scope="module")
def capsule_photo():
    K = intrinsics_from_fov(40, 128, 96)
    return photograph(Capsule.tilted(), K, np.eye(4), 128, 96)


def test_grabcut_box_finds_the_object(capsule_photo):
    rows, cols = np.nonzero(capsule_photo.mask)
    box = (cols.min() - 6, rows.min() - 6, cols.max() + 7, rows.max() + 7)
    labels = segment_objects(capsule_photo.rgb, None, [ObjectSpec(box=box)])
    assert set(np.unique(labels)) == {0, 1}
    assert iou(labels == 1, capsule_photo.mask) > 0.9


def test_alpha_is_the_mask_and_mask_files_are_checked(capsule_photo, tmp_path):
    alpha = capsule_photo.mask.astype(np.uint8) * 255
    assert (segment_objects(capsule_photo.rgb, alpha, [ObjectSpec()]) == capsule_photo.mask).all()
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), alpha[:50])
    with pytest.raises(InputError, match="photograph is 128x96") as err:
        segment_objects(capsule_photo.rgb, None, [ObjectSpec(mask=small)])
    assert err.value.file == str(small)


def test_several_objects_get_their_own_labels_and_need_masks_or_boxes(capsule_photo, tmp_path):
    left = np.zeros((96, 128), np.uint8)
    left[:, :64] = 255
    paths = []
    for name, image in (("left.png", left), ("whole.png", np.full_like(left, 255))):
        paths.append(tmp_path / name)
        cv2.imwrite(str(paths[-1]), image)
    labels = segment_objects(capsule_photo.rgb, None, [ObjectSpec(mask=p) for p in paths])
    assert (labels[:, :64] == 1).all() and (labels[:, 64:] == 2).all()  # the earlier object keeps the overlap
    with pytest.raises(InputError, match="neither mask nor box") as err:
        segment_objects(capsule_photo.rgb, None, [ObjectSpec(mask=paths[0]), ObjectSpec()])
    assert err.value.field == "objects[1]"


def test_background_inpaints_the_object_away(capsule_photo):
    background = inpaint_background(capsule_photo.rgb, capsule_photo.mask.astype(np.uint8))
    backdrop = capsule_photo.rgb[0, 0].astype(int)  # the synthetic backdrop is one flat grey
    assert np.abs(background.astype(int) - backdrop).max() <= 4
