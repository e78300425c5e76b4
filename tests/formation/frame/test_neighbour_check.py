"""Neighbour check (Algorithm 2, eq. 9) and common frame (eq. 10, least squares)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.formation.frame.common_frame import build_common_frame, choose_frame_robot
from agent.core.formation.frame.neighbour_check import (
    identify_neighbours,
    meets_eq9,
    mutual_support,
)
from agent.core.formation.frame.records import NeighborRecord
from tests.formation.conftest import random_fleet, records_from_positions

# Three robots worked by hand: 0 at (0, 0), 1 at (1, 0), 2 at (0, 1); fixed frames parallel.
POS3 = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])


def test_three_robots_by_hand() -> None:
    recs = records_from_positions([0, 1, 2], POS3)
    g = identify_neighbours(recs, epsilon=0.2)
    assert [(p.i, p.j) for p in g.pairs] == [(0, 1), (0, 2), (1, 2)]
    assert np.allclose(g.pairs[0].v_ij, [1.0, 0.0]) and np.allclose(g.pairs[0].v_ji, [-1.0, 0.0])
    assert g.degree() == {0: 2, 1: 2, 2: 2}
    assert choose_frame_robot(g) == 0  # tie on degree -> lowest id
    for method in ("bfs", "lsq"):
        cf = build_common_frame(g, method)
        assert cf.frame_robot == 0
        assert np.allclose(cf.positions, POS3)


def test_eq9_threshold() -> None:
    assert meets_eq9(np.array([1.0, 0.0]), np.array([-0.9, 0.05]), 0.2)[0]
    ok, ed = meets_eq9(np.array([1.0, 0.0]), np.array([-0.7, 0.0]), 0.2)
    assert not ok and ed == pytest.approx(0.3)


def test_one_sided_and_spurious_detections_do_not_break_it() -> None:
    recs = records_from_positions([0, 1, 2], POS3)
    # robot 2 misses robot 1; robot 1 sees clutter far away
    r2 = NeighborRecord(2, np.array([[0.0, -1.0]]))
    r1 = NeighborRecord(1, np.vstack([recs[1].neighbours, [[5.0, 5.0]]]))
    g = identify_neighbours([recs[0], r1, r2], epsilon=0.2)
    assert [(p.i, p.j) for p in g.pairs] == [(0, 1), (0, 2)]
    assert (1, 2) in g.unidentified()  # the clutter detection
    cf = build_common_frame(g, "lsq")
    assert np.allclose(cf.positions, POS3)
    assert cf.frame_robot == 0


def test_minimum_error_wins_among_candidates() -> None:
    # robot 1 reports two detections both within ε of -v_01; the closer one must be matched.
    r0 = NeighborRecord(0, np.array([[1.0, 0.0]]))
    r1 = NeighborRecord(1, np.array([[-0.9, 0.0], [-1.02, 0.0]]))
    g = identify_neighbours([r0, r1], epsilon=0.3)
    assert len(g.pairs) == 1 and g.pairs[0].b == 0  # index in the canonical (sorted) record
    assert np.allclose(g.pairs[0].v_ji, [-1.02, 0.0])


def test_noisy_fleet_identified_and_lsq_beats_bfs() -> None:
    rng = np.random.default_rng(3)
    errs = {"bfs": [], "lsq": []}
    for _ in range(20):
        pos = random_fleet(rng, 10, spacing=0.6)
        ids = list(range(10))
        recs = records_from_positions(ids, pos, seen=1.45, noise=0.05, rng=rng)
        g = identify_neighbours(recs, epsilon=0.35)
        for method in ("bfs", "lsq"):
            try:
                cf = build_common_frame(g, method)
            except ValueError:
                continue
            truth = pos - pos[ids.index(cf.frame_robot)]
            errs[method].append(np.mean(np.hypot(*(cf.positions - truth).T)))
    assert errs["lsq"] and np.mean(errs["lsq"]) < np.mean(errs["bfs"])


def test_disconnected_fleet_names_unreachable_robots() -> None:
    pos = np.array([[0.0, 0.0], [1.0, 0.0], [10.0, 0.0], [11.0, 0.0]])
    g = identify_neighbours(records_from_positions([0, 1, 2, 3], pos), epsilon=0.2)
    with pytest.raises(ValueError, match=r"robots \[2, 3\] cannot be reached from frame robot 0"):
        build_common_frame(g)
    lonely = [*records_from_positions([0, 1], pos[:2]), NeighborRecord(9, np.zeros((0, 2)))]
    with pytest.raises(ValueError, match="no identified neighbour"):
        build_common_frame(identify_neighbours(lonely, epsilon=0.2))


def test_errors() -> None:
    with pytest.raises(ValueError, match="epsilon"):
        identify_neighbours(records_from_positions([0], POS3[:1]), epsilon=0.0)
    with pytest.raises(ValueError, match="no records"):
        identify_neighbours([])
    g = identify_neighbours(records_from_positions([0, 1, 2], POS3), epsilon=0.2)
    with pytest.raises(ValueError, match="frame method"):
        build_common_frame(g, "magic")


def test_single_robot() -> None:
    g = identify_neighbours([NeighborRecord(4, np.zeros((0, 2)))])
    cf = build_common_frame(g)
    assert cf.frame_robot == 4 and np.allclose(cf.positions, [[0.0, 0.0]])


def test_robot_half_way_does_not_fool_the_check() -> None:
    # 0 at (0,0), 1 at (1,0), 2 at (2,0): 0 sees 1 at +x, 2 sees 1 at -x (ε = 0 for the
    # wrong pair 0<->2 through robot 1); mutual support must pick the right pairs.
    pos = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    g = identify_neighbours(records_from_positions([0, 1, 2], pos, seen=2.5), epsilon=0.2)
    assert [(p.i, p.j) for p in g.pairs] == [(0, 1), (0, 2), (1, 2)]
    assert np.allclose(
        build_common_frame(g, "bfs").positions - build_common_frame(g, "bfs").positions[1],
        pos - pos[1],
    )
    for p in g.pairs:
        assert np.allclose(p.v_ij, pos[p.j] - pos[p.i])


def _support_one_by_one(
    r2: np.ndarray, c2: np.ndarray, owner: np.ndarray, vecs: np.ndarray, eps: float
) -> np.ndarray:
    """The support worked candidate by candidate (the definition in mutual_support's doc)."""
    out = np.zeros(r2.shape[0], dtype=np.int64)
    for t in range(r2.shape[0]):
        mine = np.flatnonzero(owner == owner[r2[t]])
        theirs = vecs[owner == owner[c2[t]]]
        for d in mine[mine != r2[t]]:
            q = vecs[d] - vecs[r2[t]]
            out[t] += int(np.min(np.hypot(*(theirs - q).T)) < eps)
    return out


@settings(max_examples=60, deadline=None)
@given(
    st.integers(2, 6),
    st.integers(0, 2**31 - 1),
    st.integers(0, 4),
    st.booleans(),
)
def test_support_counts_equal_the_one_by_one_definition(
    owners: int, seed: int, tenths: int, shuffled: bool
) -> None:
    # sightings on a 0.1 m grid (ties on purpose) and ε half-way between grid distances:
    # no distance lies within rounding of ε, so the two counts cannot differ by it
    eps = (tenths + 0.5) / 10.0
    rng = np.random.default_rng(seed)
    owner = rng.integers(0, owners, size=int(rng.integers(2, 30)))
    if not shuffled:
        owner = np.sort(owner)
    vecs = np.round(rng.uniform(-1.5, 1.5, size=(owner.size, 2)), 1)
    pairs = [(a, b) for a in range(owner.size) for b in range(owner.size)
             if owner[a] != owner[b]]  # fmt: skip
    if not pairs:
        return
    r2 = np.array([a for a, _ in pairs])
    c2 = np.array([b for _, b in pairs])
    got = mutual_support(r2, c2, owner, vecs, eps)
    assert got.dtype == np.int64
    assert np.array_equal(got, _support_one_by_one(r2, c2, owner, vecs, eps))


def test_support_of_no_candidates_is_empty() -> None:
    out = mutual_support(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(3, np.int64),
                   np.zeros((3, 2)), 0.3)  # fmt: skip
    assert out.shape == (0,)
