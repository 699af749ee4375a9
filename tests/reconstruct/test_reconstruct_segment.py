"""Segmentation and background against a synthetic photograph whose mask is known."""
import cv2
import numpy as np
import pytest
import skimage.data
from scipy import ndimage

from schemas import InputError
from stages.reconstruct.background import EXEMPLAR_MAX_PX, SEAM_WIDTH, dilation_px, inpaint_background
from stages.reconstruct.geometry import intrinsics_from_fov
from stages.reconstruct.metrics import iou
from stages.reconstruct.segment import ObjectSpec, segment_objects
from testing.photographs import Capsule, photograph


@pytest.fixture(scope="module")
def capsule_photo():
    K = intrinsics_from_fov(40, 128, 96)
    return photograph(Capsule.tilted(), K, np.eye(4), 128, 96)


@pytest.mark.parametrize("scale", [1, 12])  # 128 x 96, and 1536 x 1152: segmented on a 1024 px copy
def test_grabcut_box_finds_the_object(capsule_photo, scale):
    size = (128 * scale, 96 * scale)
    rgb = cv2.resize(capsule_photo.rgb, size, interpolation=cv2.INTER_NEAREST)
    truth = cv2.resize(capsule_photo.mask.astype(np.uint8), size, interpolation=cv2.INTER_NEAREST) > 0
    rows, cols = np.nonzero(truth)
    margin = 6 * scale
    box = (cols.min() - margin, rows.min() - margin, cols.max() + 1 + margin, rows.max() + 1 + margin)
    labels = segment_objects(rgb, None, [ObjectSpec(box=box)])
    assert set(np.unique(labels)) == {0, 1}
    assert iou(labels == 1, truth) > 0.9


@pytest.mark.parametrize("box", [(15, 26, 73, 80), (120, 18, 190, 84)])
def test_grabcut_separates_an_object_from_look_alikes_elsewhere(box):
    """scikit-image's coins: two dozen bright coins on a dark ground. Learnt from the whole photograph,
    the background's colours hold the other coins and GrabCut found nothing in these boxes. The
    reference: Otsu's threshold inside the box, holes filled (bright coin, dark ground)."""
    gray = skimage.data.coins()
    x0, y0, x1, y1 = box
    roi = gray[y0:y1, x0:x1]
    threshold, _ = cv2.threshold(roi, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    reference = np.zeros(gray.shape, bool)
    reference[y0:y1, x0:x1] = ndimage.binary_fill_holes(roi > threshold)
    labels = segment_objects(np.repeat(gray[..., None], 3, axis=2), None, [ObjectSpec(box=box)])
    assert iou(labels == 1, reference) > 0.95


def test_a_box_that_misses_the_object_is_refused(capsule_photo):
    assert not capsule_photo.mask[:30, :60].any()
    problem = r"kept \d+ pixels, 0\.\d\d % of the box \[0, 0, 60, 30\] in the 128x96 photograph"
    with pytest.raises(InputError, match=problem) as err:
        segment_objects(capsule_photo.rgb, None, [ObjectSpec(box=(0, 0, 60, 30))], "s/scene.yaml")
    assert (err.value.file, err.value.field) == ("s/scene.yaml", "objects[0].box")


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


@pytest.mark.parametrize("texture", ["stripes", "checkerboard", "weave"])
def test_background_continues_the_texture_around_the_hole(texture):
    """A periodic backdrop behind a disc: past the seam, where the fill is by exemplar, it must
    be the backdrop itself (it is all around the hole to copy from); diffusion (Telea) smears it
    to its mean there."""
    rows, cols = np.mgrid[0:96, 0:128].astype(np.float64)
    value = {"stripes": 128 + 90 * np.sin(2 * np.pi * (cols + rows) / 8),
             "checkerboard": 128 + 90 * np.sign(np.sin(np.pi * (cols + 0.5) / 5) * np.sin(np.pi * (rows + 0.5) / 5)),
             "weave": 128 + 50 * np.sin(2 * np.pi * cols / 7) + 40 * np.cos(2 * np.pi * rows / 11)}[texture]
    backdrop = np.repeat(value[..., None], 3, axis=2).clip(0, 255).astype(np.uint8)
    distance = np.hypot(cols - 64, rows - 48)
    disc = distance < 20
    photo = backdrop.copy()
    photo[disc] = (255, 0, 0)
    background = inpaint_background(photo, disc.astype(np.uint8))
    radius = dilation_px(96, 128)
    hole = distance < 20 + radius + 1
    assert (background[~hole] == photo[~hole]).all()
    past_seam = distance < 20 + radius - SEAM_WIDTH * radius - 1
    assert np.abs(background[past_seam].astype(float) - backdrop[past_seam]).mean() < 2.0
    telea = cv2.inpaint(photo, cv2.dilate(disc.astype(np.uint8), np.ones((7, 7), np.uint8)), 5, cv2.INPAINT_TELEA)
    assert np.abs(telea[past_seam].astype(float) - backdrop[past_seam]).mean() > 20.0
    # and along the seam it continues the rim: no worse than diffusion alone
    seam = hole & ~past_seam
    assert np.abs(background[seam].astype(float) - backdrop[seam]).mean() <= \
        np.abs(telea[seam].astype(float) - backdrop[seam]).mean() + 1.0


def test_background_of_an_object_filling_the_photograph(capsule_photo, caplog):
    """Too little background to copy patches from: the hole is still filled (by diffusion), the
    rest kept, and the log says why."""
    labels = np.ones((96, 128), np.uint8)
    labels[:, :4] = 0
    background = inpaint_background(capsule_photo.rgb, labels)
    assert background.shape == capsule_photo.rgb.shape and background.dtype == np.uint8
    assert "diffusion alone" in caplog.text


def test_background_of_a_photograph_wider_than_the_exemplar_cap():
    """Past EXEMPLAR_MAX_PX the exemplar fill is computed on a shrunk copy and brought back: the
    texture still continues into the hole (up to the resampling), the known pixels stay exact."""
    width = EXEMPLAR_MAX_PX + 200
    rows, cols = np.mgrid[0:64, 0:width].astype(np.float64)
    backdrop = np.repeat((128 + 80 * np.sin(2 * np.pi * (cols + rows) / 16))[..., None], 3, axis=2).astype(np.uint8)
    distance = np.hypot(cols - width / 2, rows - 32)
    disc = distance < 20
    photo = backdrop.copy()
    photo[disc] = (255, 0, 0)
    background = inpaint_background(photo, disc.astype(np.uint8))
    radius = dilation_px(64, width)
    hole = distance < 20 + radius + 1
    assert (background[~hole] == photo[~hole]).all()
    past_seam = distance < 20 + radius - SEAM_WIDTH * radius - 1
    telea = cv2.inpaint(photo, hole.astype(np.uint8), 5, cv2.INPAINT_TELEA)
    error = np.abs(background[past_seam].astype(float) - backdrop[past_seam]).mean()
    assert error < 10.0 and np.abs(telea[past_seam].astype(float) - backdrop[past_seam]).mean() > 2 * error


def two_touching_discs(width=160, height=100):
    """Photograph (H,W,3) of two touching striped discs on a plain ground, and each disc's mask."""
    rows, cols = np.mgrid[0:height, 0:width]
    left = (cols - 55) ** 2 + (rows - 50) ** 2 < 30 ** 2
    right = ((cols - 110) ** 2 + (rows - 50) ** 2 < 27 ** 2) & ~left
    rgb = np.full((height, width, 3), (70, 110, 150), np.uint8)
    stripes = (cols // 4) % 2 == 0
    rgb[(left | right) & stripes] = (230, 60, 40)
    rgb[(left | right) & ~stripes] = (250, 210, 70)
    return rgb, left, right


def write_hints(path, shape, object_strokes=(), background_strokes=()):
    """A hint image as pm-setup writes it: transparent, opaque white and black polylines 5 px wide."""
    hints = np.zeros(shape + (4,), np.uint8)
    for strokes, colour in ((object_strokes, (255, 255, 255, 255)), (background_strokes, (0, 0, 0, 255))):
        for line in strokes:
            cv2.polylines(hints, [np.array(line, np.int32)], False, colour, 5)
    cv2.imwrite(str(path), hints)
    return path


def test_background_strokes_take_a_touching_look_alike_out_of_the_mask(tmp_path):
    """GrabCut alone keeps both discs (same colours, one component); one background stroke across the
    second disc leaves the first, as the user meant."""
    rgb, left, right = two_touching_discs()
    box = (15, 10, 145, 90)
    alone = segment_objects(rgb, None, [ObjectSpec(box=box)]) == 1
    assert iou(alone, left | right) > 0.9 and (alone & right).sum() > 0.9 * right.sum()
    hints = write_hints(tmp_path / "hints.png", rgb.shape[:2], background_strokes=[[(110, 28), (110, 72)],
                                                                                  [(96, 50), (128, 50)]])
    corrected = segment_objects(rgb, None, [ObjectSpec(box=box, hints=hints)]) == 1
    assert iou(corrected, left) > 0.9 and (corrected & right).sum() < 0.15 * right.sum()


def test_object_strokes_outside_the_box_grow_the_mask(tmp_path):
    """A box that cuts the disc's right side off; an object stroke over that side brings it back."""
    rgb, left, _ = two_touching_discs()
    rgb[:, 86:] = (70, 110, 150)  # the left disc alone
    box = (15, 10, 70, 90)
    cut = segment_objects(rgb, None, [ObjectSpec(box=box)]) == 1
    hints = write_hints(tmp_path / "hints.png", rgb.shape[:2], object_strokes=[[(72, 40), (80, 50), (72, 62)]])
    grown = segment_objects(rgb, None, [ObjectSpec(box=box, hints=hints)]) == 1
    assert iou(cut, left) < 0.85 < 0.9 < iou(grown, left)


def test_a_hint_image_of_another_size_is_refused(tmp_path):
    rgb, _, _ = two_touching_discs()
    hints = write_hints(tmp_path / "hints.png", (50, 80))
    with pytest.raises(InputError, match="hint image of the photograph's size"):
        segment_objects(rgb, None, [ObjectSpec(box=(15, 10, 145, 90), hints=hints)])
