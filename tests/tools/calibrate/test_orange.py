"""The caps' colour range from a lab's pictures (tools/calibrate/orange.py): a tolerance box
of the caps' pixels, as wide as the background allows; synthetic views with known colours."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from agent.core.perception.camera import CameraModel
from tools.calibrate.orange import BACKGROUND_SHARE, MIN_KEPT, learn_orange

CAPS = (90, 205, 158)  # a teal cap (OpenCV HSV)


def _view(background: list[tuple[int, int, int]]) -> np.ndarray:
    """A grey view with the caps in the middle columns (rows shaded V 150-168) and patches
    of the given colours far outside the window of NAO-j."""
    cam = CameraModel()
    hsv = np.zeros((cam.height, cam.width, 3), np.uint8)
    hsv[..., 2] = 128
    cx = int(cam.cx)
    for i, row in enumerate(range(150, 330)):
        hsv[row, cx - 60 : cx + 60] = (CAPS[0], CAPS[1], 150 + (i % 19))
    for k, colour in enumerate(background):
        hsv[40 + 60 * k : 80 + 60 * k, 10:70] = colour
    return cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)


def test_the_range_keeps_the_caps_and_leaves_out_their_hue_in_other_shades() -> None:
    bright, dark = (88, 162, 213), (91, 224, 81)  # the room's teal: lighter and darker
    fit = learn_orange([_view([bright, dark])] * 3, 0.6)
    (h0, s0, v0), (h1, s1, v1) = fit.orange.low, fit.orange.high
    assert h0 <= CAPS[0] <= h1
    assert v0 > dark[2] and v1 < bright[2]  # a box bounded on both sides
    assert s0 <= CAPS[1] <= s1
    assert fit.kept >= 0.95 and fit.background_share <= BACKGROUND_SHARE
    # without the room's teal the floors go lower: as wide as the background allows
    wide = learn_orange([_view([])] * 3, 0.6).orange
    assert wide.low[2] < v0 and wide.high == fit.orange.high


def test_a_room_painted_in_the_caps_colour_lets_the_least_through_and_says_so() -> None:
    shades = [(CAPS[0], CAPS[1], v) for v in (150, 159, 168)]  # the caps' own shading
    fit = learn_orange([_view(shades)] * 2, 0.6)
    assert fit.background_share > BACKGROUND_SHARE  # reported, not hidden
    assert fit.kept >= MIN_KEPT  # still a range for the caps
    with pytest.raises(ValueError, match="no coloured caps"):
        learn_orange([_view([])[:, ::-1] * 0], 0.6)


def test_the_floors_keep_the_most_caps_the_background_allows() -> None:
    """Brute force over every pair of floors: none keeps more of the caps' pixels with the
    background share within the limit."""
    from tools.calibrate.orange import _box

    rng = np.random.default_rng(3)
    caps = np.c_[np.full(400, 90), rng.integers(60, 256, 400), rng.integers(40, 256, 400)]
    bg = np.c_[np.full(300, 90), rng.integers(0, 200, 300), rng.integers(0, 230, 300)]
    n_bg = 5 * 10**6  # the limit: 100 of the 300 background pixels
    o, share = _box(caps, bg, n_bg, 88, 92)
    (_, s0, v0), (_, s1, v1) = o.low, o.high
    assert share <= BACKGROUND_SHARE and (s1, v1) == (255, 255)

    def counts(px: np.ndarray, s: int, v: int) -> int:
        return int(np.count_nonzero((px[:, 1] >= s) & (px[:, 2] >= v)))

    best = counts(caps, s0, v0)
    for s in range(0, 256, 3):
        for v in range(0, 256, 3):
            if counts(bg, s, v) / n_bg <= BACKGROUND_SHARE:
                assert counts(caps, s, v) <= best
    assert best >= MIN_KEPT * len(caps)
