"""The pairs a dense fleet's first fit can trust (agent/core/formation/frame/firm_pairs.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agent.core.formation.frame.firm_pairs import (
    FIRM_SUPPORT,
    firm_graph,
    firm_start,
    pair_supports,
)
from agent.core.formation.frame.neighbour_check import DEFAULT_EPSILON, identify_neighbours
from agent.core.formation.frame.records import NeighborRecord
from tests.formation.pose_fleets import dense_records, sim_layout, unaligned_records


def _square() -> list[NeighborRecord]:
    """Four robots on a unit square, everyone seeing everyone (aligned frames)."""
    pos = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    return [
        NeighborRecord(k + 1, np.array([pos[j] - pos[k] for j in range(4) if j != k]))
        for k in range(4)
    ]


def _connected(ids: tuple[int, ...], pairs: tuple) -> bool:  # type: ignore[type-arg]
    seen, todo = {ids[0]}, [ids[0]]
    while todo:
        r = todo.pop()
        for p in pairs:
            for a, b in ((p.i, p.j), (p.j, p.i)):
                if a == r and b not in seen:
                    seen.add(b)
                    todo.append(b)
    return seen == set(ids)


def test_support_of_a_square_worked_by_hand() -> None:
    """Each pair of the square has two common neighbours, each closing a triangle from
    both sides: support 2 + 2 = 4, for the four sides and the two diagonals."""
    graph = identify_neighbours(_square(), DEFAULT_EPSILON)
    assert len(graph.pairs) == 6
    assert pair_supports(graph, 0.1).tolist() == [4] * 6


def test_a_shifted_sighting_loses_its_triangles() -> None:
    """Robot 1 sees robot 3 at (1.3, 1) instead of (1, 1): within ε of eq. 9 (1-3 is still a
    pair), but beyond a 0.1 m support tolerance. Worked by hand: pair 1-2 from 1's side,
    (1.3, 1) − (1, 0) = (0.3, 1) misses 2's (0, 1), (0, 1) − (1, 0) = (−1, 1) hits; from
    2's side, (0, 1) − (−1, 0) = (1, 1) misses 1's (1.3, 1), (−1, 1) − (−1, 0) = (0, 1) hits:
    2 (1-4 alike). Pair 1-3 from 1's side: both shifted by (1.3, 1) miss; from 3's side both
    hit: 2. The pairs without robot 1 keep 4."""
    recs = _square()
    nb = recs[0].neighbours.copy()
    nb[1] += [0.3, 0.0]  # robot 1's sighting of robot 3
    recs[0] = NeighborRecord(1, nb)
    graph = identify_neighbours(recs, DEFAULT_EPSILON)
    got = dict(zip(((p.i, p.j) for p in graph.pairs), pair_supports(graph, 0.1).tolist()))
    assert got == {(1, 2): 2, (1, 3): 2, (1, 4): 2, (2, 3): 4, (2, 4): 4, (3, 4): 4}


def test_a_high_threshold_leaves_a_maximum_support_spanning_tree() -> None:
    rng = np.random.default_rng(3)
    pos = sim_layout(rng, 10)
    recs = unaligned_records(list(range(1, 11)), pos, np.full(10, math.pi / 2), rng, 0.03, 0.03)
    graph = identify_neighbours(recs, DEFAULT_EPSILON)
    tree = firm_graph(graph, min_support=10_000)
    assert len(tree.pairs) == len(graph.ids) - 1
    assert _connected(graph.ids, tree.pairs)
    assert firm_graph(graph, min_support=0).pairs == graph.pairs


def test_firm_pairs_of_a_dense_fleet_are_right_and_connect_it() -> None:
    """A dense aligned room (60 NAOs, 30 % of sightings occluded): the eq. 9 pairs include
    chance ones; the firm graph keeps only pairs of robots that truly see each other."""
    pos, _, recs = dense_records(np.random.default_rng(0), 60)
    graph = identify_neighbours(recs, DEFAULT_EPSILON)

    def right(p) -> bool:  # type: ignore[no-untyped-def]
        return bool(np.hypot(*(pos[p.i - 1] + p.v_ij - pos[p.j - 1])) < 0.3)

    wrong_all = sum(not right(p) for p in graph.pairs)
    firm = firm_start(graph)
    assert firm is not None and _connected(graph.ids, firm.pairs)
    assert wrong_all > 10
    assert sum(not right(p) for p in firm.pairs) == 0


def test_a_sparse_fleet_has_no_firm_start() -> None:
    rng = np.random.default_rng(18)
    pos = sim_layout(rng, 6)
    recs = unaligned_records(list(range(1, 7)), pos, np.full(6, math.pi / 2), rng, 0.03, 0.03)
    graph = identify_neighbours(recs, DEFAULT_EPSILON)
    assert max(pair_supports(graph, DEFAULT_EPSILON / 2), default=0) < FIRM_SUPPORT
    assert firm_start(graph) is None


def test_shuffled_records_give_the_same_firm_graph() -> None:
    _, _, recs = dense_records(np.random.default_rng(1), 40)
    want = firm_graph(identify_neighbours(recs, DEFAULT_EPSILON))
    for seed in range(3):
        order = np.random.default_rng(seed).permutation(len(recs))
        got = firm_graph(identify_neighbours([recs[k] for k in order], DEFAULT_EPSILON))
        assert [(p.i, p.j, p.a, p.b) for p in got.pairs] == [
            (p.i, p.j, p.a, p.b) for p in want.pairs
        ]


@pytest.mark.parametrize("bad", [-1, 1.5, True, None])
def test_min_support_must_be_a_non_negative_int(bad: object) -> None:
    graph = identify_neighbours(_square(), DEFAULT_EPSILON)
    with pytest.raises(ValueError, match="min_support"):
        firm_graph(graph, min_support=bad)  # type: ignore[arg-type]


@pytest.mark.parametrize("bad", [0.0, -0.1, math.nan, math.inf])
def test_tolerance_must_be_finite_and_positive(bad: float) -> None:
    graph = identify_neighbours(_square(), DEFAULT_EPSILON)
    with pytest.raises(ValueError, match="tolerance"):
        pair_supports(graph, bad)


def test_a_graph_without_pairs_has_no_support() -> None:
    graph = identify_neighbours(
        [NeighborRecord(1, np.zeros((0, 2))), NeighborRecord(2, np.zeros((0, 2)))]
    )
    assert pair_supports(graph, 0.1).shape == (0,)
    assert firm_start(graph) is None
