"""The background fill continues the hole's surroundings and copies no salient object from elsewhere."""
import cv2
import numpy as np

from stages.reconstruct.background import inpaint_background

SKIN, EYE = np.array([230, 180, 150]), np.array([20, 30, 90])


def mottled_wall_with_a_face(size=256):
    """A mottled grey backdrop (fine grain and broad clouds, like a studio backdrop), a tall object
    standing from the photograph's top border down to past its middle, and a face (a skin-coloured disc
    with two dark eyes) beside it: the backdrop (H, W, 3 u8), the photograph, the object's mask."""
    rng = np.random.default_rng(0)
    rows, cols = np.mgrid[0:size, 0:size].astype(np.float64)
    grain = cv2.GaussianBlur(rng.normal(0, 12, (size, size)), (0, 0), 1.5)
    clouds = cv2.GaussianBlur(rng.normal(0, 60, (size, size)), (0, 0), 12)
    backdrop = np.stack([170 + grain + clouds, 160 + grain + clouds, 150 + grain + clouds], -1)
    backdrop = backdrop.clip(0, 255).astype(np.uint8)
    photo = backdrop.copy()
    face = (0.25 * size, 0.35 * size)
    photo[np.hypot(rows - face[0], cols - face[1]) < 0.12 * size] = SKIN
    for side in (-1, 1):
        photo[np.hypot(rows - face[0], cols - face[1] - side * 0.05 * size) < 0.025 * size] = EYE
    obj = (rows < 0.55 * size) & (np.abs(cols - 0.78 * size) < 0.1 * size)
    photo[obj] = (255, 0, 0)
    return backdrop, photo, obj


def test_the_fill_continues_the_backdrop_and_copies_no_face():
    """Where the object stood the fill is the backdrop's continuation: no pixel of it looks more like the
    face's skin or eyes than like the backdrop there (by more than 40/255), and its mean error is within
    the backdrop's own mottling. Searched over the whole photograph, starting from black at a pyramid level
    one patch across, the fill carried the dark eyes in from the border (87 pixels, mean error 4.3)."""
    backdrop, photo, obj = mottled_wall_with_a_face()
    background = inpaint_background(photo, obj.astype(np.uint8))
    inner = cv2.erode(obj.astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
    filled, truth = background[inner].astype(float), backdrop[inner].astype(float)
    off = np.abs(filled - truth).max(-1)
    like_the_face = np.minimum(np.abs(filled - SKIN).max(-1), np.abs(filled - EYE).max(-1)) < off
    assert (like_the_face & (off > 40)).sum() == 0
    assert np.abs(filled - truth).mean() < 3.5
    outside = cv2.dilate(obj.astype(np.uint8), np.ones((9, 9), np.uint8)) == 0
    assert (background[outside] == photo[outside]).all()
