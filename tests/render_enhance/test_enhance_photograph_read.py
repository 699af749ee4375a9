"""pm-enhance reads the objects' colours from a band-limited copy of the photograph without the
silhouette's ringing: a flat disc with a hard edge on a bright background, read off the pixel grid,
against its own flat colour."""
import numpy as np

from stages.enhance.flow import band_limited_upsample, objects_continued, photograph_at

SIZE, RADIUS = 96, 30
DISC, WALL = np.array([200.0, 100.0, 40.0]), np.array([225.0, 220.0, 210.0])


def disc_photograph() -> tuple[np.ndarray, np.ndarray]:
    """(SIZE, SIZE, 3) float32 photograph of a flat disc, its edge hard (no antialiasing), and its mask."""
    rows, cols = np.mgrid[0:SIZE, 0:SIZE] + 0.5
    on = np.hypot(rows - SIZE / 2, cols - SIZE / 2) < RADIUS
    return np.where(on[..., None], DISC, WALL).astype(np.float32), on


def test_the_objects_colours_are_read_without_the_silhouettes_ringing():
    """Read a quarter and half a pixel off the grid, inside the disc (3 px from its edge) the objects'
    copy gives the disc's colour within half a level, where the photograph's own band-limited copy
    rings by more than 4 levels; on the grid it is the photograph, exactly, on the disc."""
    photo, on = disc_photograph()
    rows, cols = np.mgrid[0:SIZE, 0:SIZE]
    inner = np.hypot(rows + 0.5 - SIZE / 2, cols + 0.5 - SIZE / 2) < RADIUS - 3.5
    grid = np.stack([cols, rows], -1).astype(np.float32) + 0.5
    objects, plain = band_limited_upsample(objects_continued(photo, on)), band_limited_upsample(photo)
    for offset in (0.25, 0.5):
        read = photograph_at(objects, grid + offset)
        assert np.abs(read[inner] - DISC).max() <= 0.5, offset
        assert np.abs(photograph_at(plain, grid + offset)[inner] - DISC).max() > 4, offset
    np.testing.assert_allclose(photograph_at(objects, grid)[on], photo[on], atol=1e-3)
