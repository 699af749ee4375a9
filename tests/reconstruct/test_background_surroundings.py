"""The background fill continues the hole's surroundings and copies no salient object from elsewhere."""
import cv2
import numpy as np

from stages.reconstruct.background import inpaint_background

SKIN, EYE = np.array([230, 180, 150]), np.array([20, 30, 90])
RED, YELLOW = np.array([220, 30, 30]), np.array([230, 210, 60])


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


def fill_and_copies(photo, hole, truth, *distractors):
    """Fill the hole (H, W bool) of the photograph and compare the fill, away from the hole's edge, with the
    truth (H, W, 3 u8): the fill (H, W, 3 u8), the mean absolute error over the inner hole (levels) and the
    number of inner pixels that look more like one of the distractor colours (3,) than like the truth there
    and are more than 40 levels off it (a copy of the distractor)."""
    background = inpaint_background(photo, hole.astype(np.uint8))
    inner = cv2.erode(hole.astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
    filled, wanted = background[inner].astype(float), truth[inner].astype(float)
    off = np.abs(filled - wanted).max(-1)
    nearest_distractor = np.min([np.abs(filled - colour).max(-1) for colour in distractors], axis=0)
    copies = ((nearest_distractor < off) & (off > 40)).sum()
    return background, np.abs(filled - wanted).mean(), copies


def test_the_fill_continues_the_backdrop_and_copies_no_face():
    """Where the object stood the fill is the backdrop's continuation: no pixel of it looks more like the
    face's skin or eyes than like the backdrop there (by more than 40/255), and its mean error is within
    the backdrop's own mottling. Searched over the whole photograph, starting from black at a pyramid level
    one patch across, the fill carries the dark eyes in from the border (87 pixels, mean error 4.3)."""
    backdrop, photo, obj = mottled_wall_with_a_face()
    background, error, copies = fill_and_copies(photo, obj, backdrop, SKIN, EYE)
    assert copies == 0
    assert error < 3.5
    outside = cv2.dilate(obj.astype(np.uint8), np.ones((9, 9), np.uint8)) == 0
    assert (background[outside] == photo[outside]).all()


def striped_ball_on_a_grained_table(height=240, width=320):
    """A table of wavy horizontal grain (like the example ball's wood), a red and yellow striped ball
    on it at the left and a hole in the table at the right: the table (H, W, 3 u8), the photograph
    (the hole painted blue), the hole's mask."""
    rng = np.random.default_rng(0)
    rows, cols = np.mgrid[0:height, 0:width].astype(np.float64)
    grain = 20 * np.sin(2 * np.pi * rows / 6 + 0.8 * np.sin(cols / 23))
    grain += cv2.GaussianBlur(rng.normal(0, 10, (height, width)), (0, 0), 1)
    wood = 110 + 30 * rows / height + grain
    table = np.stack([wood + 40, 0.6 * wood + 10, 0.35 * wood], -1).clip(0, 255).astype(np.uint8)
    photo = table.copy()
    ball = np.hypot(rows - 120, cols - 90) < 70
    stripes = ((cols + rows) // 14) % 2 == 0
    photo[ball & stripes], photo[ball & ~stripes] = RED, YELLOW
    hole = np.hypot(rows - 110, cols - 240) < 40
    photo[hole] = (0, 0, 255)
    return table, photo, hole


def test_the_fill_of_a_hole_in_the_table_copies_no_ball():
    """The hole in the table is filled with table: no pixel of it looks more like the ball's stripes
    than like the table there (by more than 40/255), and its mean error stays within the grain's phase
    (the grain's amplitude is 20). With a coarsest level one patch across for the whole photograph, the
    fill is a second striped ball (3176 pixels, mean error 45.9)."""
    table, photo, hole = striped_ball_on_a_grained_table()
    _, error, copies = fill_and_copies(photo, hole, table, RED, YELLOW)
    assert copies == 0
    assert error < 12
