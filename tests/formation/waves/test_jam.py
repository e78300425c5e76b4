"""The jam rules (agent/core/formation/waves/jam.py): known answers, determinism under shuffled
inputs, one test per error branch."""

from __future__ import annotations

import random

import numpy as np
import pytest

from agent.core.formation.waves.jam import (
    FLEET_STOP,
    STOP,
    WAIT,
    at_start,
    blocker_of,
    expected_places,
    jam_verdict,
    stop_reason,
    waits_for,
    yields,
)

STARTS = {1: np.array([0.0, 0.0]), 2: np.array([1.0, 0.0]), 3: np.array([2.0, 0.0])}
TARGETS = {1: np.array([0.0, 1.0]), 2: np.array([1.0, 1.0]), 3: np.array([2.0, 1.0])}


def _shuffled(d: dict, seed: int) -> dict:
    items = list(d.items())
    random.Random(seed).shuffle(items)
    return dict(items)


def test_expected_places_follow_the_phases() -> None:
    places = expected_places(STARTS, TARGETS, {1: "hold", 2: "move", 3: "wait"}, {2: 0.2})
    assert sorted(places) == [1, 3]  # the walking robot has no expected place
    assert places[1].tolist() == [0.0, 1.0] and places[3].tolist() == [2.0, 0.0]
    # nothing heard yet: still where it started; failed: unknown
    places = expected_places(STARTS, TARGETS, {1: "failed"})
    assert sorted(places) == [2, 3] and places[2].tolist() == [1.0, 0.0]


def test_a_robot_in_its_move_phase_that_has_walked_nothing_is_at_its_start() -> None:
    # robot 2 turns towards its path, or waits for its own way: still where it started
    places = expected_places(STARTS, TARGETS, {1: "hold", 2: "move", 3: "move"}, {3: 0.4})
    assert sorted(places) == [1, 2] and places[2].tolist() == [1.0, 0.0]
    assert blocker_of(np.array([1.1, 0.05]), places, 0.3) == 2
    assert blocker_of(np.array([2.0, 0.1]), places, 0.3) == -1  # robot 3 walks: unknown
    # with the paths known, a robot beyond its start is expected where its status puts it
    paths = {i: np.vstack([STARTS[i], TARGETS[i]]) for i in STARTS}
    places = expected_places(STARTS, TARGETS, {2: "move", 3: "move"}, {3: 0.4}, paths)
    assert places[3].tolist() == [2.0, 0.4] and places[2].tolist() == [1.0, 0.0]
    assert blocker_of(np.array([2.0, 0.5]), places, 0.3) == 3
    assert at_start("move") and at_start("move", 0.0) and at_start("wait", 3.0)
    assert at_start("") and not at_start("move", 0.01) and not at_start("hold")


def test_expected_places_need_the_same_robots() -> None:
    with pytest.raises(ValueError, match="same robots"):
        expected_places(STARTS, {1: TARGETS[1]}, {})
    with pytest.raises(ValueError, match="finite"):
        expected_places({1: np.array([np.nan, 0.0])}, {1: TARGETS[1]}, {})


def test_the_blocker_is_the_nearest_expected_place_within_the_tolerance() -> None:
    places = expected_places(STARTS, TARGETS, {1: "hold", 2: "wait", 3: "wait"})
    assert blocker_of(np.array([1.1, 0.05]), places, 0.3) == 2
    assert blocker_of(np.array([0.1, 0.9]), places, 0.3) == 1
    assert blocker_of(np.array([0.5, 0.5]), places, 0.3) == -1  # nobody expected there
    # a tie goes to the lower id, whatever the order of the places
    tie = {5: np.array([1.0, 0.0]), 4: np.array([-1.0, 0.0])}
    assert blocker_of(np.zeros(2), tie, 1.0) == 4
    with pytest.raises(ValueError, match="tolerance"):
        blocker_of(np.zeros(2), places, -1.0)


def test_waits_for_is_transitive() -> None:
    after = {3: (2,), 2: (1,), 1: ()}
    assert waits_for(after, 3, 1) and waits_for(after, 3, 2) and waits_for(after, 2, 1)
    assert not waits_for(after, 1, 3) and not waits_for(after, 1, 1)
    assert not waits_for({1: (2,), 2: (1,)}, 1, 3)  # a cycle ends the search


def test_a_robot_that_waits_for_its_claimant_yields() -> None:
    after = {1: (), 2: (1,), 3: (1, 2)}
    # robot 1 walks to a slot robot 3 stands too near: 3 waits for 1 (and 2, which holds)
    assert yields(after, 3, [1], {1: 3, 2: -1}) == [1]
    # 3 also waits for 2, which itself waits for the claimant 1: still a deadlock
    assert yields(after, 3, [1, 2], {1: 3}) == [1]
    # no claim on 3, or a claim on someone else: wait
    assert yields(after, 3, [1], {1: -1}) == []
    assert yields(after, 3, [1], {1: 2}) == []
    # nothing pending: nothing to yield (the robot starts anyway)
    assert yields(after, 3, [], {1: 3}) == []


def test_no_yield_while_something_else_is_pending() -> None:
    after = {1: (), 2: (), 3: (1, 2)}
    # robot 2 walks on its own and does not wait for the claimant: 3 waits its turn
    assert yields(after, 3, [1, 2], {1: 3}) == []


def test_yields_is_deterministic_under_shuffled_inputs() -> None:
    after = {1: (), 2: (1,), 4: (2,), 5: (1, 4), 6: (5,)}
    claims = {1: 6, 2: 6, 4: -1, 5: 3}
    want = yields(after, 6, [5, 1, 2, 4], claims)
    assert want == [1, 2]
    for seed in range(20):
        pend = [5, 1, 2, 4]
        random.Random(seed).shuffle(pend)
        assert yields(_shuffled(after, seed), 6, pend, _shuffled(claims, seed)) == want


def test_jam_verdict_waits_longer_for_a_robot_that_has_not_moved() -> None:
    assert jam_verdict(4, 2, "wait", 59, 60, 600).action == WAIT
    assert jam_verdict(4, 2, "wait", 60, 60, 600).action == WAIT
    v = jam_verdict(4, 2, "wait", 600, 60, 600)
    assert v == jam_verdict(4, 2, "wait", 600, 60, 600)
    assert v.action == STOP and v.reason == (
        "robot 4 cannot reach its slot: robot 2 (wait) in its way for 600 polls"
    )
    hold = jam_verdict(4, 2, "hold", 60, 60, 600)
    assert hold.action == STOP and "robot 2 (hold)" in hold.reason
    unknown = jam_verdict(4, -1, "", 60, 60, 600)
    assert unknown.action == STOP and "a NAO not in the plan" in unknown.reason
    assert jam_verdict(4, -1, "", 59, 60, 600).action == WAIT


def test_jam_verdict_waits_long_for_a_member_in_its_move_phase() -> None:
    # named in its move phase (at its start, or holding at a gate): it walks on
    assert jam_verdict(4, 2, "move", 60, 60, 600).action == WAIT
    assert jam_verdict(4, 2, "move", 599, 60, 600).action == WAIT
    v = jam_verdict(4, 2, "move", 600, 60, 600)
    assert v.action == STOP and "robot 2 (move)" in v.reason


def test_jam_verdict_rejects_bad_bounds() -> None:
    with pytest.raises(ValueError, match="max_polls"):
        jam_verdict(1, 2, "wait", 0, 60, 10)
    with pytest.raises(ValueError, match="polls"):
        jam_verdict(1, 2, "wait", -1, 60, 600)


def test_the_fleet_stops_naming_the_root_failure() -> None:
    assert stop_reason({}) == ""
    root = "robot 4 cannot reach its slot: robot 2 (hold) in its way for 60 polls"
    want = f"{FLEET_STOP}robot 4 failed: {root}"
    assert stop_reason({4: root}) == want
    # a fleet stop heard before the root is copied from the marker on: the same text
    assert stop_reason({1: want}) == want
    assert stop_reason({1: f"AgentFailure: {want}"}) == want
    assert stop_reason({1: f"AgentFailure: {want}", 4: f"AgentFailure: {root}"}) == (
        f"{FLEET_STOP}robot 4 failed: AgentFailure: {root}"
    )
    assert stop_reason({1: want, 4: root}) == want
    # several roots: the lowest id, whatever the order heard
    other = "contact while walking at believed [0.1, 0.2]"
    both = {7: other, 4: root, 2: want}
    for seed in range(10):
        assert stop_reason(_shuffled(both, seed)) == want
    assert stop_reason({3: ""}) == f"{FLEET_STOP}robot 3 failed: no reason given"
