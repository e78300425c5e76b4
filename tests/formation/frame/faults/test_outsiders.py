"""NAOs without a record (agent/core/formation/frame/faults/outsiders.py): a bystander seen by
several members stands where their loose sightings agree and is not held against them;
a ghost seen by one is not a bystander; a member the fit misplaced is not one either."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest
from scipy.special import chdtri

from agent.core.formation.frame.faults import fault_test as ft
from agent.core.formation.frame.faults import outsiders as out
from agent.core.formation.frame.fleet_frame import fleet_frame
from agent.core.formation.frame.poses import PoseFrame, evaluate_poses
from agent.core.formation.frame.records import NeighborRecord
from tests.formation.frame.faults.test_alone import truth_fleet
from tests.formation.frame.faults.test_fault_test import NOISE

GATE = float(chdtri(2, ft.ALPHA_SIGHTING))


def with_bystander(seed: int, n: int = 8) -> tuple[list[NeighborRecord], PoseFrame, np.ndarray]:
    """Records of ``n`` members and a bystander (id ``n + 1``, no record), the members'
    frame at their true poses, and where the bystander stands (world frame)."""
    recs, pos, psi = truth_fleet(seed, n + 1, noise=False)
    members = tuple(range(1, n + 1))
    frame = evaluate_poses(members, (), pos[:n], psi[:n], 1)
    return [r for r in recs if r.robot_id in members], frame, pos[n]


def seen_by(recs: list[NeighborRecord], frame: PoseFrame, at: np.ndarray) -> int:
    """How many members have a sighting landing on ``at`` (within 1 cm)."""
    count = 0
    for r in recs:
        pts = frame.to_common(r.robot_id, r.neighbours)
        count += bool(len(pts)) and float(np.hypot(*(pts - at).T).min()) < 0.01
    return count


def test_a_bystander_stands_where_the_members_saw_it() -> None:
    found = 0
    for seed in range(1, 8):
        recs, frame, at = with_bystander(seed)
        places = out.outsider_places(frame, recs, NOISE, GATE)
        if seen_by(recs, frame, at) >= out.WITNESSES:
            assert places.shape == (1, 2) and np.allclose(places[0], at, atol=1e-9), seed
            found += 1
        else:
            assert places.shape == (0, 2), seed
    assert found >= 5


def test_a_bystanders_sightings_are_not_lost_strays() -> None:
    recs, frame, at = with_bystander(1)
    assert seen_by(recs, frame, at) >= 2
    tests = ft.robot_tests(frame, NOISE, recs)
    assert all(t.lost == 0 for t in tests), [t.describe() for t in tests]
    assert ft.fleet_count(frame, NOISE, recs).failures == 0


def test_the_fleet_plans_with_every_member_beside_a_bystander() -> None:
    for seed in (1, 2, 3):
        recs, _, _ = with_bystander(seed)
        ff = fleet_frame(recs, 0.3, NOISE)
        assert ff.excluded == () and len(ff.ids) == 8, (seed, ff.reason)


def test_one_owners_ghost_is_no_bystander() -> None:
    recs, frame, _ = with_bystander(2, n=8)
    members = list(recs)
    o = members[0]
    ghost = np.array([[0.2, 1.7]])  # nobody else saw anything there
    members[0] = NeighborRecord(o.robot_id, np.vstack([o.neighbours, ghost]),
                                np.append(o.orientations, 0.0))  # fmt: skip
    base = out.outsider_places(frame, recs, NOISE, GATE)
    again = out.outsider_places(frame, members, NOISE, GATE)
    assert np.array_equal(base, again)
    assert ft.robot_tests(frame, NOISE, members)[0].lost == 1


def test_a_member_fitted_away_from_where_it_stands_is_no_bystander() -> None:
    recs, pos, psi = truth_fleet(1, noise=False)
    moved = pos.copy()
    moved[2] += [0.6, 0.0]  # robot 3 fitted 0.6 m from where it stands
    frame = evaluate_poses(tuple(range(1, 9)), (), moved, psi, 1)
    assert 3 in out.unseen(frame, recs, NOISE, GATE)
    loose = out.loose_sightings(frame, recs, NOISE, GATE)
    assert len(out.agreeing_sets(loose, NOISE, GATE)) >= 1  # its true place, as a bystander's
    assert out.outsider_places(frame, recs, NOISE, GATE).shape == (0, 2)  # but cancelled


def test_two_bystanders_are_two_places() -> None:
    recs, pos, psi = truth_fleet(4, 10, noise=False)
    members = tuple(range(1, 9))
    frame = evaluate_poses(members, (), pos[:8], psi[:8], 1)
    mine = [r for r in recs if r.robot_id in members]
    places = out.outsider_places(frame, mine, NOISE, GATE)
    expect = [pos[k] for k in (8, 9) if seen_by(mine, frame, pos[k]) >= 2]
    assert len(places) == len(expect) >= 1
    for p in expect:
        assert min(float(np.hypot(*(p - q))) for q in places) < 1e-9


def test_shuffled_records_give_the_same_places() -> None:
    recs, frame, _ = with_bystander(3)
    base = out.outsider_places(frame, recs, NOISE, GATE)
    rng = random.Random(7)
    for _ in range(5):
        shuffled = recs[:]
        rng.shuffle(shuffled)
        assert np.array_equal(out.outsider_places(frame, shuffled, NOISE, GATE), base)


def test_no_sightings_no_sets() -> None:
    assert out.agreeing_sets([], NOISE, GATE) == []
    assert out.largest_set(np.zeros((0, 0), dtype=bool), []) == []


def test_turn_is_the_inverse_rotation() -> None:
    p = np.array([[1.0, 0.0]])
    assert np.allclose(out.turn(math.pi / 2, p), [[0.0, -1.0]])
    assert np.allclose(out.turn(-math.pi / 2, out.turn(math.pi / 2, p)), p)


@pytest.mark.parametrize("witnesses", [1, 2, 3])
def test_a_set_needs_its_witnesses(witnesses: int) -> None:
    recs, frame, at = with_bystander(1)
    loose = out.loose_sightings(frame, recs, NOISE, GATE)
    sets = out.agreeing_sets(loose, NOISE, GATE, witnesses)
    owners = seen_by(recs, frame, at)
    assert (len(sets) >= 1) == (owners >= witnesses)


def test_a_place_a_members_record_fits_better_is_that_member() -> None:
    recs, pos, psi = truth_fleet(1, noise=False)
    moved = pos.copy()
    moved[2] += [0.0, 2.0]  # robot 3 fitted 2 m from where it stands
    frame = evaluate_poses(tuple(range(1, 9)), (), moved, psi, 1)
    none = np.zeros((0, 2))
    assert out.member_fits_there(frame, recs, NOISE, GATE, pos[2:3], none) == [3]
    right = evaluate_poses(tuple(range(1, 9)), (), pos, psi, 1)
    away = pos[2:3] + np.array([0.0, 2.0])
    assert out.member_fits_there(right, recs, NOISE, GATE, away, none) == [None]
    assert out.member_fits_there(frame, recs, NOISE, GATE, none, none) == []


def test_no_members_record_fits_where_a_bystander_stands() -> None:
    for seed in (1, 2, 3):
        recs, frame, at = with_bystander(seed)
        assert out.member_fits_there(frame, recs, NOISE, GATE, at, np.zeros((0, 2))) == [None]


def test_the_best_heading_of_a_robot_at_its_true_place_is_its_own() -> None:
    recs, pos, psi = truth_fleet(2, noise=False)
    others = np.delete(pos, 0, axis=0) - pos[0]
    heading, lands = out.best_heading(others, recs[0].neighbours, NOISE, GATE)
    assert lands == len(recs[0].neighbours)
    assert abs(math.remainder(heading - psi[0], 2 * math.pi)) <= math.radians(1.0)
    assert out.best_heading(others, np.zeros((0, 2)), NOISE, GATE) == (0.0, 0)
