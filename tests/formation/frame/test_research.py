"""Re-search decision (NAO paper 4.1.3 rule 2): who searches again, and where it walks."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.formation.frame.records import NeighborRecord
from agent.core.formation.frame.research import (
    BLIND,
    DEFAULT_APPROACH,
    DEFAULT_STEP,
    GOLDEN_ANGLE,
    NORTH,
    Research,
    decide_research,
    step_blocked,
)
from tests.formation.conftest import records_from_positions

# 1, 2, 3 within sight of each other; 4 is 3.5 m north of 3: beyond the 3 m range.
POS4 = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 0.8], [0.5, 4.3]])


def test_connected_fleet_searches_nobody() -> None:
    r = decide_research(records_from_positions([1, 2, 3], POS4[:3], seen=3.0), 1)
    assert r.connected and r.searchers == () and r.moves == ()
    assert r.kept == (1, 2, 3) and r.components == ((1, 2, 3),) and r.isolated == ()
    assert np.allclose(r.move(1), 0.0)


def test_robot_beyond_sight_searches_again_on_a_spiral() -> None:
    recs = records_from_positions([1, 2, 3, 4], POS4, seen=3.0)
    assert recs[3].count == 0
    r1 = decide_research(recs, 1)
    assert not r1.connected
    assert r1.searchers == (4,) and r1.isolated == (4,) and r1.kept == (1, 2, 3)
    assert r1.components == ((1, 2, 3), (4,))
    assert "robots [4] outside the group of robots [1, 2, 3]" in r1.reason
    assert "no identified neighbour: [4]" in r1.reason
    h = NORTH + 4 * GOLDEN_ANGLE
    assert np.allclose(r1.move(4), DEFAULT_STEP * np.array([math.cos(h), math.sin(h)]))
    # round 2: the next leg of the square spiral, twice as long, 90° to the left
    r2 = decide_research(recs, 2)
    h2 = h + math.pi / 2
    assert np.allclose(r2.move(4), 2 * DEFAULT_STEP * np.array([math.cos(h2), math.sin(h2)]))
    r3 = decide_research(recs, 1, step=0.5)
    assert float(np.hypot(*r3.move(4))) == pytest.approx(0.5)


def test_one_sided_sighting_is_approached() -> None:
    recs = records_from_positions([1, 2, 3, 4], POS4, seen=3.0)
    # 4 saw robot 3 at 3.5 m (a long sighting); 3 did not see 4
    recs[3] = NeighborRecord(4, np.array([[0.0, -3.5]]))
    r = decide_research(recs, 1)
    assert r.searchers == (4,)
    assert np.allclose(r.move(4), [0.0, -(3.5 - DEFAULT_APPROACH)])
    # too close to help (the other robot would have seen it): the spiral instead
    recs[3] = NeighborRecord(4, np.array([[0.0, -1.2]]))
    h = NORTH + 4 * GOLDEN_ANGLE
    assert np.allclose(
        decide_research(recs, 1).move(4), DEFAULT_STEP * np.array([np.cos(h), np.sin(h)])
    )


def test_a_component_moves_as_a_block_and_ignores_its_own_members() -> None:
    # {1, 2, 3} and {7, 8} 5 m apart; 8 reports 7 once more (a duplicate, unpaired)
    pos = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 0.8], [5.0, 0.0], [5.9, 0.0]])
    recs = records_from_positions([1, 2, 3, 7, 8], pos, seen=3.0)
    recs[4] = NeighborRecord(8, np.vstack([recs[4].neighbours, [[-0.8, 0.1]]]))
    r = decide_research(recs, 1)
    assert r.kept == (1, 2, 3) and r.searchers == (7, 8) and r.isolated == ()
    assert np.allclose(r.move(7), r.move(8))
    h = NORTH + 7 * GOLDEN_ANGLE  # the component's lowest id
    assert np.allclose(r.move(7), DEFAULT_STEP * np.array([math.cos(h), math.sin(h)]))


def test_ties_keep_the_component_with_the_lowest_id() -> None:
    pos = np.array([[0.0, 0.0], [1.0, 0.0], [6.0, 0.0], [6.0, 0.9]])  # no equal vectors (eq. 9)
    r = decide_research(records_from_positions([5, 6, 2, 9], pos, seen=3.0), 1)
    assert r.kept == (2, 9) and r.searchers == (5, 6)
    assert not r.blind


def test_nobody_walks_blind_when_no_robot_saw_any_other() -> None:
    far = np.array([[0.0, 0.0], [5.0, 0.0], [0.0, 5.0]])
    r = decide_research(records_from_positions([3, 1, 2], far, seen=3.0), 1)
    assert r.blind and not r.connected and r.kept == () and r.moves == ()
    assert r.searchers == (1, 2, 3) and r.isolated == (1, 2, 3)
    assert r.reason == BLIND and np.allclose(r.move(2), 0.0)
    # one sighting, even one that no pair explains, is a group to walk towards
    one = records_from_positions([1, 2], np.array([[0.0, 0.0], [2.5, 0.0]]), seen=3.0)
    seen = [one[0], NeighborRecord(2, np.zeros((0, 2)))]
    r = decide_research(seen, 1)
    assert not r.blind and r.searchers and r.kept


def test_bad_arguments() -> None:
    recs = records_from_positions([1, 2], POS4[:2], seen=3.0)
    for bad_round in (0, -1, True, 1.0):
        with pytest.raises(ValueError, match="round"):
            decide_research(recs, bad_round)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="step"):
        decide_research(recs, 1, step=0.0)
    with pytest.raises(ValueError, match="approach"):
        decide_research(recs, 1, approach=math.nan)
    with pytest.raises(ValueError, match="no records"):
        decide_research([], 1)
    with pytest.raises(ValueError, match="clearance"):
        step_blocked(np.zeros((1, 2)), 0.0, 0.2, 0.0)


def test_step_blocked_known_answers() -> None:
    pts = np.array([[0.0, 0.6], [0.0, -0.4], [0.6, 0.3], [0.1, 0.4]])
    # walking north 0.2 m, clearance 0.5: (0.1, 0.4) first, (0, 0.6) also inside
    assert step_blocked(pts, NORTH, 0.2, 0.5) == 3
    assert step_blocked(pts[:1], NORTH, 0.2, 0.5) == 0
    assert step_blocked(pts[:1], NORTH, 0.2, 0.3) is None  # 0.6 > 0.2 + 0.3
    assert step_blocked(pts[1:2], NORTH, 0.2, 0.5) is None  # behind
    assert step_blocked(pts[1:2], NORTH, -0.2, 0.5) == 0  # behind, stepping backwards
    assert step_blocked(pts[2:3], NORTH, 0.2, 0.5) is None  # beside
    assert step_blocked(np.zeros((0, 2)), NORTH, 0.2, 0.5) is None


def _shuffled(recs: list[NeighborRecord], rng: np.random.Generator) -> list[NeighborRecord]:
    out = []
    for r in recs:
        idx = rng.permutation(r.count)
        out.append(NeighborRecord(r.robot_id, r.neighbours[idx]))
    return [out[k] for k in rng.permutation(len(out))]


def _same(a: Research, b: Research) -> bool:
    return a == b


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(1, 9),
    seed=st.integers(0, 2**31 - 1),
    round_=st.integers(1, 4),
    spread=st.floats(1.0, 8.0),
)
def test_every_agent_decides_alike_from_shuffled_records(
    n: int, seed: int, round_: int, spread: float
) -> None:
    rng = np.random.default_rng(seed)
    pos = np.round(rng.uniform(0.0, spread, (n, 2)), 3)
    ids = sorted(int(i) for i in rng.choice(100, n, replace=False))
    recs = records_from_positions(ids, pos, seen=3.0, noise=0.05, rng=rng)
    r = decide_research(recs, round_)
    for _ in range(3):
        assert _same(decide_research(_shuffled(recs, rng), round_), r)
    # invariants: kept and searchers split the fleet; the kept group is the largest
    assert sorted(r.kept + r.searchers) == ids
    assert set(r.kept).isdisjoint(r.searchers)
    assert r.connected == (len(r.components) == 1)
    if r.blind:  # nobody saw anybody: nobody walks
        assert not any(rec.count for rec in recs) and r.moves == ()
        return
    assert all(len(r.kept) >= len(c) for c in r.components)
    assert [m[0] for m in r.moves] == list(r.searchers)
    assert not set(r.isolated) & set(r.kept) or r.kept == (min(ids),)
    for i in r.searchers:
        assert 0.0 < float(np.hypot(*r.move(i))) <= max(round_ * DEFAULT_STEP, 3.0) + 1e-9
