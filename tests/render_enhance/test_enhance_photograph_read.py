"""pm-enhance reads the objects' colours from the photograph without the silhouette's ringing: a flat
disc with a hard edge on a bright background, read off the pixel grid, against its own flat colour."""
import numpy as np

from stages.enhance.flow import SILHOUETTE_PX, band_limited_upsample, objects_reader, photograph_at

SIZE, RADIUS = 96, 30
DISC, WALL = np.array([200.0, 100.0, 40.0]), np.array([225.0, 220.0, 210.0])


def test_the_objects_colours_are_read_without_the_silhouettes_ringing():
    """Read a quarter and half a pixel off the grid, inside the disc (SILHOUETTE_PX + 1 px from its edge)
    the objects' reader gives the disc's colour within half a level, where the photograph's band-limited
    copy rings by more than 4 levels; on the grid it is the photograph, exactly, everywhere."""
    rows, cols = np.mgrid[0:SIZE, 0:SIZE]
    radius = np.hypot(rows + 0.5 - SIZE / 2, cols + 0.5 - SIZE / 2)
    on = radius < RADIUS  # a hard edge: no antialiasing
    photo = np.where(on[..., None], DISC, WALL).astype(np.float32)
    inner = radius < RADIUS - SILHOUETTE_PX - 1.5
    grid = np.stack([cols, rows], -1).astype(np.float32) + 0.5
    read, plain = objects_reader(photo, on), band_limited_upsample(photo)
    for offset in (0.25, 0.5):
        assert np.abs(read(grid + offset)[inner] - DISC).max() <= 0.5, offset
        assert np.abs(photograph_at(plain, grid + offset)[inner] - DISC).max() > 4, offset
    np.testing.assert_allclose(read(grid), photo, atol=1e-3)
