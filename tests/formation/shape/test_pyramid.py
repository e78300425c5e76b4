"""Pyramid slots (AUV eqs. 5-7), frame (eqs. 12-13) and assignment (Lemma 1, AUV III.C)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agent.core.formation.params import D_E
from agent.core.formation.paths.assignment import assign, uncross
from agent.core.formation.paths.geometry import paths_cross
from agent.core.formation.shape.layout import placed
from agent.core.formation.shape.pyramid import (
    PyramidFrame,
    layer_of,
    parent_of,
    pca_axis,
    pyramid_frame,
    slot_positions,
)
from agent.core.formation.shape.spec import PYRAMID
from tests.formation.conftest import random_fleet

PHI = math.radians(30)


def test_layers_and_parents_known_answers() -> None:
    assert [layer_of(m) for m in range(11)] == [1, 2, 2, 3, 3, 3, 4, 4, 4, 4, 5]
    assert [parent_of(m) for m in range(10)] == [-1, 0, 0, 1, 2, 2, 3, 4, 5, 5]


@pytest.mark.parametrize("n", range(1, 22))
def test_slot_geometry_n_1_to_21(n: int) -> None:
    d_e = D_E
    s = slot_positions(n, d_e, PHI)
    assert s.shape == (n, 2)
    assert np.allclose(s[0], [0.0, 0.0])
    for m in range(1, n):
        p = parent_of(m)
        rel = s[m] - s[p]
        assert math.hypot(*rel) == pytest.approx(d_e)
        # φ_e off the backward axis, left child (-x) unless last of a full layer
        assert abs(math.atan2(rel[0], -rel[1])) == pytest.approx(PHI)
        assert s[m, 1] == pytest.approx(-(layer_of(m) - 1) * d_e * math.cos(PHI))
    # slots are distinct and at least d_e apart (triangular lattice)
    if n > 1:
        d = np.hypot(*(s[:, None, :] - s[None, :, :]).T)
        assert d[~np.eye(n, dtype=bool)].min() == pytest.approx(d_e)


def test_slot_errors() -> None:
    for bad in (0, -1, True, 2.5):
        with pytest.raises(ValueError, match="int >= 1"):
            slot_positions(bad, 1.0, PHI)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="d_e"):
        slot_positions(3, 0.0, PHI)
    with pytest.raises(ValueError, match="phi_e"):
        slot_positions(3, 1.0, math.pi / 2)
    with pytest.raises(ValueError, match="order"):
        layer_of(-1)
    with pytest.raises(ValueError, match="orientation"):
        pyramid_frame(np.zeros((2, 2)), "star")
    with pytest.raises(ValueError, match="placement"):
        placed(PYRAMID, 3, 1.0, PHI, np.zeros((3, 2)), "middle")


def test_frame_round_trip_and_eq13() -> None:
    fr = PyramidFrame(origin=np.array([1.0, 2.0]), beta=0.3)
    pts = np.random.default_rng(0).normal(size=(5, 2))
    assert np.allclose(fr.to_pyramid(fr.to_common(pts)), pts)
    # y_p unit vector maps to angle beta, x_p is to its right
    assert np.allclose(
        fr.to_common(np.array([0.0, 1.0])) - fr.origin, [math.cos(0.3), math.sin(0.3)]
    )
    assert np.allclose(
        fr.to_common(np.array([1.0, 0.0])) - fr.origin, [math.sin(0.3), -math.cos(0.3)]
    )


def test_pca_axis_sign_points_to_sparse_tail() -> None:
    # many robots at y=0, one far ahead at y=3: the pyramid faces +y
    pts = np.array([[-1.0, 0.0], [0.0, 0.0], [1.0, 0.0], [0.0, 3.0], [-0.5, 0.1], [0.5, -0.1]])
    pts[:, 0] *= 0.1
    assert pca_axis(pts) == pytest.approx(math.pi / 2, abs=0.1)
    assert pca_axis(pts * np.array([1.0, -1.0])) == pytest.approx(-math.pi / 2, abs=0.1)
    assert pca_axis(np.zeros((1, 2))) == pytest.approx(math.pi / 2)
    assert pca_axis(np.ones((3, 2))) == pytest.approx(math.pi / 2)
    # symmetric collinear distribution: tie -> +y half-plane
    assert pca_axis(np.array([[0.0, -1.0], [0.0, 0.0], [0.0, 1.0]])) == pytest.approx(math.pi / 2)
    assert pyramid_frame(pts, "north").beta == pytest.approx(math.pi / 2)


@pytest.mark.parametrize("strategy", ["paper", "optimal", "capt"])
def test_assignment_is_a_permutation(strategy: str) -> None:
    rng = np.random.default_rng(11)
    for n in (1, 2, 3, 7, 16, 40):
        s = rng.uniform(-3, 3, (n, 2))
        f = placed(PYRAMID, n, D_E, PHI, s, "centroid")
        perm = assign(s, f, strategy, D_E, PHI)
        assert sorted(perm.tolist()) == list(range(n))


def test_optimal_is_minimal_and_paper_matches_lemma1_within_pairs() -> None:
    rng = np.random.default_rng(5)
    for _ in range(20):
        s = random_fleet(rng, 10, 0.6)
        s = s - s.mean(axis=0)
        f = placed(PYRAMID, 10, 2.0, PHI, s, "centroid")
        tot = {
            k: np.hypot(*(s - f[assign(s, f, k, 2.0, PHI)]).T).sum()
            for k in ("paper", "optimal", "capt")
        }
        assert tot["optimal"] <= tot["paper"] + 1e-9
        assert tot["optimal"] <= tot["capt"] + 1e-9
        # the exact solver's paths never cross (Lemma 1)
        p = assign(s, f, "optimal", 2.0, PHI)
        a, b = np.triu_indices(10, 1)
        assert not paths_cross(s[a], f[p][a], s[b], f[p][b]).any()


def test_three_robots_by_hand() -> None:
    # pyramid frame = common frame here: robots right at three slots (shuffled) go home.
    s = slot_positions(3, 1.0, PHI)
    s = s - s.mean(axis=0)
    starts = s[[2, 0, 1]] + 0.01
    for k in ("paper", "optimal", "capt"):
        assert assign(starts, s, k, 1.0, PHI).tolist() == [2, 0, 1]


def test_uncross_removes_crossings() -> None:
    s = np.array([[0.0, 0.0], [1.0, 0.0]])
    t = np.array([[1.0, 1.0], [0.0, 1.0]])
    perm = uncross(s, t, 0.5)
    assert perm.tolist() == [1, 0]


def test_assign_errors() -> None:
    with pytest.raises(ValueError, match="strategy"):
        assign(np.zeros((2, 2)), np.ones((2, 2)), "greedy", 1.0, PHI)
    with pytest.raises(ValueError, match=r"\(N, 2\)"):
        assign(np.zeros((2, 2)), np.ones((3, 2)), "paper", 1.0, PHI)
