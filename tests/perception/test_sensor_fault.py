"""Injected sensor faults (agent/core/perception/sensor_fault.py): known answers, errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from agent.core.perception.sensor_fault import SensorFault

PTS = np.array([[1.0, 0.0], [0.0, 2.0]])
ORI = np.array([0.0, math.pi])


def test_rotate_turns_every_sighting_not_the_line_of_sight_orientations() -> None:
    pts, ori = SensorFault.parse("rotate:90").apply(PTS, ORI)
    np.testing.assert_allclose(pts, [[0.0, 1.0], [-2.0, 0.0]], atol=1e-12)
    np.testing.assert_array_equal(ori, ORI)


def test_scale_multiplies_distances_and_keeps_bearings() -> None:
    pts, ori = SensorFault.parse("scale:1.4").apply(PTS, ORI)
    np.testing.assert_allclose(pts, [[1.4, 0.0], [0.0, 2.8]])
    np.testing.assert_array_equal(ori, ORI)


def test_shift_moves_every_sighting_along_x() -> None:
    pts, _ = SensorFault.parse("shift:0.5").apply(PTS, ORI)
    np.testing.assert_allclose(pts, [[1.5, 0.0], [0.5, 2.0]])


def test_a_record_without_orientations_stays_without() -> None:
    pts, ori = SensorFault.parse("rotate:40").apply(PTS, np.zeros(0))
    assert pts.shape == (2, 2) and ori.size == 0


@given(st.floats(-360, 360), st.lists(st.tuples(st.floats(-3, 3), st.floats(-3, 3)), max_size=8))
def test_rotation_keeps_distances(deg: float, raw: list[tuple[float, float]]) -> None:
    pts = np.array(raw, dtype=np.float64).reshape(-1, 2)
    out, _ = SensorFault("rotate", deg).apply(pts, np.zeros(len(pts)))
    np.testing.assert_allclose(np.hypot(*out.T), np.hypot(*pts.T), atol=1e-9)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("rotate", "KIND:AMOUNT"),
        ("rotate:", "KIND:AMOUNT"),
        ("spin:4", "kind"),
        ("scale:x", "not a number"),
        ("scale:0", r"\[0.1, 10\]"),
        ("rotate:400", "360"),
        ("shift:9", r"\[-5, 5\]"),
        ("shift:nan", "finite"),
    ],
)
def test_parse_refuses(text: str, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        SensorFault.parse(text)


def test_orientations_must_match_the_points() -> None:
    with pytest.raises(ValueError, match="orientations"):
        SensorFault.parse("scale:2").apply(PTS, np.zeros(3))


def test_str_round_trips() -> None:
    for text in ("rotate:40", "scale:1.4", "shift:0.5", "shift:-0.25"):
        assert str(SensorFault.parse(text)) == text
