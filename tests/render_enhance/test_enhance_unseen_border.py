"""A source across the photograph's border (the cut of an object the border cuts, as it moves) reads the
border's colour under its own shading, not the zeros beyond the border: a plain photograph reads plain.

Reference: a photograph of one colour, shaded evenly; whatever a source reads of it is that colour.
"""
import numpy as np

from stages.enhance.compositing import sample_at
from stages.enhance.relight import to_linear
from stages.enhance.unseen import Albedo, Continuation


def test_a_source_across_the_border_reads_the_border_s_colour_at_gain_one():
    """Sources from 2 px inside the lower border to 1.5 px beyond it, surface as lit as at rest and unmoved
    in facing: the colour read is the photograph's (linear, within 1e-4) wherever the source is on it, and
    its part of the object fades to 0 beyond it. Read with the border's zeros, a source's shading falls
    towards 0 beyond it and its gain rises towards MAX_GAIN: 0.45 off (pale outlines along the cat's cut
    base, benchmarks/scenes/cat, where its sources cross the photograph's lower border)."""
    height, width = 24, 32
    colour = np.array([200.0, 150.0, 120.0], np.float32)
    photo = np.broadcast_to(colour, (height, width, 3)).astype(np.float32)
    ones = np.ones((height, width), np.float32)
    albedo = Albedo(shading_rest=ones, recorded=ones, inside=ones, facing_rest=ones, coverage=ones,
                    continued=np.broadcast_to(to_linear(colour), (height, width, 3)).astype(np.float32))
    continuation = Continuation(None, albedo, None, 1.0, None, None, None, None, lambda uv: sample_at(photo, uv))
    count = 15
    uv = np.stack([np.full(count, width / 2), np.linspace(height - 2, height + 1.5, count)], -1)[None]
    flat = np.ones((1, count), np.float32)
    read, _, inside = continuation.read(uv.astype(np.float32), flat, flat, np.zeros((1, count), np.float32))
    on = inside[0] > 0
    assert on.sum() >= 5 and (~on).sum() >= 3  # the sources cross the border
    off = np.abs(read[0][on] - to_linear(colour)).max()
    assert off <= 1e-4, f"read {off:.4f} off the photograph's colour (linear) next to its border"
