"""The photograph's shadow found and divided out of the background (reconstruct/background.py), against
synthetic photographs drawn with and without it: a dark backdrop is no shadow, a floor below a lighter
wall is not lifted, and a hard-edged shadow leaves no outline."""
import cv2
import numpy as np
import pytest

from stages.reconstruct.background import dilation_px, inpaint_background

H, W = 150, 210
ROWS, COLS = np.mgrid[0:H, 0:W].astype(np.float64)


def floor_texture(level: float) -> np.ndarray:
    """(H, W, 3) float: a grained floor of mean brightness ``level`` (0-255), warm grey."""
    grain = 1 + 0.12 * np.sin(COLS / 2.3 + 0.4 * np.sin(ROWS / 5)) + 0.06 * np.sin(ROWS / 1.7)
    return level * grain[..., None] * np.array([1.0, 0.93, 0.85])


def superellipse(cx: float, cy: float, ax: float, ay: float) -> np.ndarray:
    """(H, W) bool: a loaf's outline, |(x - cx) / ax|^3 + |(y - cy) / ay|^3 < 1."""
    return np.abs((COLS - cx) / ax) ** 3 + np.abs((ROWS - cy) / ay) ** 3 < 1


def with_object(ground: np.ndarray, inside: np.ndarray) -> np.ndarray:
    """sRGB u8: the crusty object drawn over ``ground`` (H, W, 3)."""
    crust = np.array([170, 110, 40]) * (0.8 + 0.2 * np.sin(COLS / 1.5) * np.sin(ROWS / 1.9))[..., None]
    return np.clip(np.where(inside[..., None], crust, ground) + 0.5, 0, 255).astype(np.uint8)


def hole_of(inside: np.ndarray) -> np.ndarray:
    """(H, W) bool: what inpaint_background fills (the object dilated), and a pixel more."""
    radius = dilation_px(H, W) + 1
    return cv2.dilate(inside.astype(np.uint8), np.ones((2 * radius + 1,) * 2, np.uint8)) > 0


@pytest.mark.parametrize("case", ["cut by the border", "standing beside it"])
def test_a_dark_backdrop_is_no_shadow(case):
    """A dark region beside the object that is not its shadow (the room behind a cat's head, a dark patch
    on the wall beside an object's top) stays as photographed: all pixels outside the hole are exact."""
    backdrop = floor_texture(190)
    if case == "cut by the border":  # the object's contact is out of the picture
        inside = superellipse(80, 120, 60, 70)
        backdrop[:, 110:] *= 0.35
    else:  # on a floor, with a dark patch on the wall beside its upper half
        inside = superellipse(90, 80, 30, 45)
        backdrop[:, :] = np.where((ROWS > 125)[..., None], floor_texture(120), backdrop)
        backdrop[35:80, 125:185] *= 0.3
    photo = with_object(backdrop, inside)
    background = inpaint_background(photo, inside.astype(np.uint8))
    outside = ~hole_of(inside)
    changed = np.abs(background.astype(int) - photo)[outside].max(-1)
    assert (changed == 0).all(), f"{(changed > 0).sum()} pixels beside the object changed, up to {changed.max()}/255"


def test_floor_below_a_lighter_wall_keeps_its_brightness():
    """A column on a floor that meets a lighter wall just above its foot, with a soft shadow beside its
    foot: the floor along the wall is not lifted to the wall's brightness (it was by 23/255, read
    against the wall), and the shadow's core, darker than the floor's grain, goes."""
    inside = superellipse(70, 75, 16, 50)  # its foot at row 125
    edge = 115
    truth = np.where((ROWS < edge)[..., None], floor_texture(205), floor_texture(105))
    shadow = 0.45 * np.exp(-(((COLS - 90) / 28) ** 2 + ((ROWS - 124) / 5) ** 2)) * (ROWS >= edge)
    photo = with_object(truth * (1 - shadow)[..., None], inside)
    background = inpaint_background(photo, inside.astype(np.uint8)).astype(float)
    outside = ~hole_of(inside)
    truth_u8 = np.clip(truth + 0.5, 0, 255).astype(np.uint8)
    floor_edge = outside & (ROWS >= edge) & (ROWS < edge + 8) & (shadow < 0.01)
    lifted = (background - truth_u8)[floor_edge].mean()
    assert abs(lifted) < 2.0, f"the floor along the wall lifted by {lifted:.1f}/255"
    shadowed = outside & (shadow > 0.3)
    assert shadowed.sum() > 50
    left = np.abs(background - truth_u8)[shadowed].mean() / np.abs(photo.astype(float) - truth_u8)[shadowed].mean()
    assert left < 0.25, f"{100 * left:.0f}% of the shadow left"


def test_hard_edged_shadow_leaves_no_outline():
    """A loaf with a hard-edged shadow band under it, half as bright: inside the band, and along its
    edge, the background must come near the floor drawn without it (measured: 19 % of the band and
    16/255 around it left; smoothed on a coarser copy and divided out, it left 28 % and 25/255)."""
    inside = superellipse(105, 85, 75, 30)
    truth = floor_texture(150)
    band = ((COLS - 105) / 79) ** 2 + ((ROWS - 115) / 7) ** 2 < 1
    photo = with_object(truth * np.where(band & ~inside, 0.5, 1.0)[..., None], inside)
    background = inpaint_background(photo, inside.astype(np.uint8)).astype(float)
    truth_u8 = np.clip(truth + 0.5, 0, 255).astype(np.uint8)
    outside = ~hole_of(inside)
    ring = (cv2.dilate(band.astype(np.uint8), np.ones((7, 7), np.uint8)) > 0) & ~band & outside
    error = lambda pixels: np.abs(background - truth_u8)[pixels].mean()  # noqa: E731
    shadowed = band & outside
    assert shadowed.sum() > 200 and ring.sum() > 200
    photographed = np.abs(photo.astype(float) - truth_u8)[shadowed].mean()
    assert error(shadowed) < 0.25 * photographed, f"{error(shadowed):.1f}/255 left of {photographed:.1f} in the band"
    assert error(ring) < 20.0, f"{error(ring):.1f}/255 off around the band"
