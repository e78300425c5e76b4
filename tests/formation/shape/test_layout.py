"""Where a shape goes on the fleet (agent/core/formation/shape/layout.py): its frame, its
placement, its slot columns, the closest slots of a formation file; the pyramid's exactly
as before."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agent.core.formation.shape.layout import (
    centred,
    closest_slots,
    column_step,
    columns,
    placed,
    shape_frame,
)
from agent.core.formation.shape.pyramid import pca_axis, pyramid_frame, slot_positions
from agent.core.formation.shape.spec import BUILTIN, PYRAMID, TREE, Shape

D, PHI = 0.8, math.radians(30)


def test_a_depth_shape_lies_as_the_pyramid_a_width_shape_across() -> None:
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(9, 2)) * np.array([3.0, 0.5])  # spread along x
    for name in ("pyramid", "column", "circle"):
        fr = shape_frame(pts, "pca", BUILTIN[name])
        ref = pyramid_frame(pts, "pca")
        assert fr.beta == ref.beta and fr.origin.tobytes() == ref.origin.tobytes()
    for name in ("line", "wedge", "grid"):
        fr = shape_frame(pts, "pca", BUILTIN[name])
        assert fr.beta == pytest.approx(math.remainder(pca_axis(pts) + math.pi / 2, 2 * math.pi))
        # the fleet's principal axis is the shape's left-right axis (x_p)
        right = fr.to_common(np.array([1.0, 0.0])) - fr.origin
        assert abs(right[1]) < 0.2 * abs(right[0])
        assert shape_frame(pts, "north", BUILTIN[name]).beta == pytest.approx(math.pi / 2)
    with pytest.raises(ValueError, match="orientation"):
        shape_frame(pts, "south", BUILTIN["line"])


@pytest.mark.parametrize("n", [1, 2, 5, 21, 100])
@pytest.mark.parametrize("placement", ["centroid", "front"])
def test_the_pyramid_is_placed_by_its_own_slots(n: int, placement: str) -> None:
    """The pyramid's slots (NAO paper 4.2's pattern, slot_positions), centred on o_p, and
    for ``front`` moved along +y_p until the rearmost is d_e ahead of the front-most
    start."""
    starts = np.random.default_rng(n).uniform(-3, 3, (n, 2))
    got = placed(PYRAMID, n, D, PHI, starts, placement)
    s = slot_positions(n, D, PHI)
    want = s - s.mean(axis=0)
    if placement == "front":
        want = want + np.array([0.0, max(0.0, starts[:, 1].max() + D - want[:, 1].min())])
    np.testing.assert_allclose(got, want, atol=1e-12)


def test_placement() -> None:
    starts = np.array([[0.0, 0.0], [1.0, 2.0], [-1.0, 1.0]])
    line = BUILTIN["line"]
    c = centred(line, 3, D, PHI)
    np.testing.assert_allclose(c.mean(axis=0), 0.0, atol=1e-12)
    front = placed(line, 3, D, PHI, starts, "front")
    assert float(np.min(front[:, 1])) == pytest.approx(2.0 + D)  # d_e ahead of the front
    with pytest.raises(ValueError, match="placement"):
        placed(line, 3, D, PHI, starts, "middle")


def test_columns_and_their_step() -> None:
    assert columns(np.array([0.5, -1.0, 0.5 + 1e-12, 2.0])).tolist() == [1, 0, 1, 2]
    assert column_step(PYRAMID, np.zeros(3), D, PHI) == D * math.sin(PHI)
    grid = centred(BUILTIN["grid"], 9, D, PHI)
    assert column_step(BUILTIN["grid"], grid[:, 0], D, PHI) == pytest.approx(D)
    col = centred(BUILTIN["column"], 4, D, PHI)
    assert column_step(BUILTIN["column"], col[:, 0], D, PHI) == math.inf
    # the wedge's columns: d_e sin 45° apart (its two arms interleave)
    w = centred(BUILTIN["wedge"], 7, D, PHI)
    assert column_step(BUILTIN["wedge"], w[:, 0], D, PHI) == pytest.approx(
        D * math.sin(math.radians(45))
    )


def test_closest_slots_of_a_file() -> None:
    t = Shape("t", TREE, ((0, 1.0, math.pi / 2), (0, 1.0, -math.pi / 2), (2, 0.3, math.pi)))
    a, b, d = closest_slots(t, D, PHI)
    assert (a, b) == (2, 3) and d == pytest.approx(0.3)
    far = Shape("far", TREE, ((0, 5.0, 0.0),))
    assert closest_slots(far, D, PHI) == (0, 1, pytest.approx(5.0))
    with pytest.raises(ValueError, match="no fixed slots"):
        closest_slots(PYRAMID, D, PHI)
