import math
from dataclasses import dataclass

import numpy as np
import pytest

from agent.core.perception.localise import (
    cluster_sightings,
    local_position,
    merge_sightings,
    rotate,
    to_fixed_frame,
)


@dataclass(frozen=True)
class S:
    distance: float
    bearing: float


def test_eq3_eq7_known_answers() -> None:
    assert local_position(1.0, 0.0) == pytest.approx((0.0, 1.0))  # ahead = local +y
    assert local_position(2.0, math.pi / 2) == pytest.approx((-2.0, 0.0))  # left = -x
    assert local_position(1.0, -math.pi / 2) == pytest.approx((1.0, 0.0))  # right = +x


def test_eq8_fixed_frame_at_start_and_after_turns() -> None:
    dets = [S(1.0, 0.0), S(0.5, math.pi / 2)]
    np.testing.assert_allclose(to_fixed_frame(dets, math.pi / 2), [[0, 1], [-0.5, 0]], atol=1e-12)
    # turned 180°: ahead is now south, left is east
    np.testing.assert_allclose(to_fixed_frame(dets, -math.pi / 2), [[0, -1], [0.5, 0]], atol=1e-12)
    # turned 90° left (facing west): ahead is -x
    np.testing.assert_allclose(to_fixed_frame([S(1.0, 0.0)], math.pi), [[-1, 0]], atol=1e-12)
    assert to_fixed_frame([], 0.3).shape == (0, 2)


def test_rotate_preserves_norm() -> None:
    pts = np.array([[1.0, 2.0], [-3.0, 0.5]])
    out = rotate(pts, 0.7)
    np.testing.assert_allclose(np.linalg.norm(out, axis=1), np.linalg.norm(pts, axis=1))


def test_merge_sightings_of_overlapping_images() -> None:
    pts = np.array([[0.0, 1.0], [0.05, 1.02], [1.0, 1.0], [0.02, 0.98]])
    conf = np.array([0.8, 0.9, 0.7, 0.6])
    labels = cluster_sightings(pts, conf, 0.25)
    assert labels.tolist() == [0, 0, 1, 0]  # seed = most confident (index 1)
    merged = merge_sightings(pts, conf, 0.25)
    assert merged.shape == (2, 2)
    w = conf[[0, 1, 3]]
    np.testing.assert_allclose(merged[0], (pts[[0, 1, 3]] * w[:, None]).sum(0) / w.sum())
    np.testing.assert_allclose(merged[1], [1.0, 1.0])
    assert merge_sightings(np.zeros((0, 2)), np.zeros(0)).shape == (0, 2)


def test_bad_inputs() -> None:
    with pytest.raises(ValueError, match="finite"):
        local_position(-1.0, 0.0)
    with pytest.raises(ValueError, match=r"\(k, 2\)"):
        rotate(np.zeros((3,)), 0.1)
    with pytest.raises(ValueError, match="theta"):
        rotate(np.zeros((1, 2)), float("nan"))
    with pytest.raises(ValueError, match="heading"):
        to_fixed_frame([S(1, 0)], float("inf"))
    with pytest.raises(ValueError, match="confidences"):
        cluster_sightings(np.zeros((2, 2)), np.zeros(3), 0.2)
    with pytest.raises(ValueError, match="radius"):
        cluster_sightings(np.zeros((2, 2)), np.zeros(2), 0.0)
    with pytest.raises(ValueError, match=r"\(k, 2\)"):
        cluster_sightings(np.zeros((2, 3)), np.zeros(2), 0.2)
    with pytest.raises(ValueError, match="finite"):
        cluster_sightings(np.full((1, 2), np.nan), np.zeros(1), 0.2)
