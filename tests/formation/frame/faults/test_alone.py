"""A robot tested alone against the others' frame (agent/core/formation/frame/faults/alone.py):
where a robot without a record stands, its record against the rest, and the last resort
of the fleet's frame that names it."""

from __future__ import annotations

import math
import random
from dataclasses import dataclass

import numpy as np
import pytest
from scipy.special import chdtri

from agent.core.formation.frame.faults import alone as al
from agent.core.formation.frame.faults import fault_test as ft
from agent.core.formation.frame.faults.fault_test import ALPHA, FaultVerdict, RobotTest
from agent.core.formation.frame.faults.outsiders import outsider_places
from agent.core.formation.frame.poses import PoseFrame, build_poses, evaluate_poses
from agent.core.formation.frame.records import NeighborRecord
from tests.formation.frame.faults.test_fault_test import NOISE
from tests.formation.pose_fleets import fault, sim_layout, unaligned_records


def truth_fleet(
    seed: int, n: int = 8, kind: str = "", victim: int = 3, noise: bool = True
) -> tuple[list[NeighborRecord], np.ndarray, np.ndarray]:
    """Records of ``n`` robots at random headings (``kind``: ``victim``'s fault), their
    true positions and their fixed frames' ψ (heading − π/2), world frame."""
    rng = np.random.default_rng(seed)
    pos = sim_layout(rng, n)
    heads = rng.uniform(-math.pi, math.pi, n)
    recs = unaligned_records(list(range(1, n + 1)), pos, heads, rng if noise else None,
                             0.02, math.radians(1.0))  # fmt: skip
    if kind:
        recs = [fault(r, kind) if r.robot_id == victim else r for r in recs]
    return recs, pos, np.angle(np.exp(1j * (heads - math.pi / 2)))


def rest_at_truth(pos: np.ndarray, psi: np.ndarray, robot: int) -> PoseFrame:
    """The others' frame at their true poses (world frame), no measurements."""
    ids = tuple(i for i in range(1, len(pos) + 1) if i != robot)
    keep = [i - 1 for i in ids]
    return evaluate_poses(ids, (), pos[keep], psi[keep], ids[0])


# ------------------------------------------------------------ where it stands
def test_the_place_of_a_robot_without_a_record_is_where_the_others_saw_it() -> None:
    recs, pos, psi = truth_fleet(1, noise=False)
    rest = rest_at_truth(pos, psi, 3)
    place, seen = al.unrecorded_place(rest, [r for r in recs if r.robot_id != 3], NOISE, 3)
    assert place is not None and np.allclose(place, pos[2], atol=1e-9)
    watchers = sorted(
        k + 1 for k in range(8) if k != 2 and 0.5 <= np.hypot(*(pos[k] - pos[2])) <= 3.0
    )
    assert [m.owner for m in seen] == watchers and all(m.target == 3 for m in seen)


def test_nobody_off_the_robots_means_no_place() -> None:
    recs, pos, psi = truth_fleet(1, noise=False)
    rest = evaluate_poses(tuple(range(1, 9)), (), pos, psi, 1)
    assert al.unrecorded_place(rest, recs, NOISE) == (None, ())


def test_one_sighting_paired_wrongly_does_not_drag_the_place() -> None:
    recs, pos, psi = truth_fleet(2, noise=False)
    others = [r for r in recs if r.robot_id != 3]
    # a ghost: one owner's extra sighting 1.5 m beside robot 3, seen by nobody else
    o = others[0]
    ghost = (pos[2] + [1.5, 0.0] - pos[0]) @ np.array(
        [[math.cos(psi[0]), -math.sin(psi[0])], [math.sin(psi[0]), math.cos(psi[0])]]
    )
    others[0] = NeighborRecord(o.robot_id, np.vstack([o.neighbours, ghost]),
                               np.append(o.orientations, 0.0))  # fmt: skip
    place, seen = al.unrecorded_place(rest_at_truth(pos, psi, 3), others, NOISE, 3)
    assert place is not None and np.allclose(place, pos[2], atol=1e-9) and len(seen) >= 2


# ------------------------------------------------------------ r against the rest
def test_a_sound_robot_passes_alone_at_its_true_pose() -> None:
    for seed in range(1, 6):
        recs, pos, psi = truth_fleet(seed)
        a = al.alone_test(rest_at_truth(pos, psi, 3), recs, 3, NOISE)
        assert a.test.p > 0.01, a.describe()
        assert a.place is not None and np.hypot(*(a.place - pos[2])) < 0.1
        assert abs(math.remainder(a.heading - psi[2], 2 * math.pi)) < math.radians(3.0)


@pytest.mark.parametrize("kind", ["scale", "shift", "rotate"])
def test_a_faulty_robot_is_rejected_alone(kind: str) -> None:
    recs, pos, psi = truth_fleet(4, kind=kind)
    a = al.alone_test(rest_at_truth(pos, psi, 3), recs, 3, NOISE)
    assert a.test.p < ALPHA, a.describe()


def test_a_robot_nobody_saw_is_never_rejected_alone() -> None:
    recs, pos, psi = truth_fleet(1, kind="scale")
    others = [NeighborRecord(r.robot_id, np.zeros((0, 2))) if r.robot_id != 3 else r for r in recs]
    a = al.alone_test(rest_at_truth(pos, psi, 3), others, 3, NOISE)
    assert a.place is None and a.test.p == 1.0


def test_a_robot_one_other_saw_is_never_rejected_alone() -> None:
    recs, pos, psi = truth_fleet(1, kind="scale")
    kept = 0
    out = []
    for r in recs:
        k = r.robot_id - 1
        c, s = math.cos(psi[k]), math.sin(psi[k])
        at = pos[k] + r.neighbours @ np.array([[c, s], [-s, c]])  # R(ψ)·v, row-wise
        of_3 = np.hypot(*(at - pos[2]).T) < 0.2
        if r.robot_id != 3 and of_3.any():
            if kept:  # every other robot's sighting of robot 3 but the first's is lost
                keep = ~of_3
                r = NeighborRecord(r.robot_id, r.neighbours[keep], r.orientations[keep])
            kept += 1
        out.append(r)
    assert kept >= 2
    a = al.alone_test(rest_at_truth(pos, psi, 3), out, 3, NOISE)
    assert a.place is None and a.test.p == 1.0
    assert al.alone_test(rest_at_truth(pos, psi, 3), recs, 3, NOISE).test.p < ALPHA


def test_the_test_alone_is_the_same_for_records_in_any_order() -> None:
    recs, pos, psi = truth_fleet(5, kind="shift")
    rest = rest_at_truth(pos, psi, 3)
    first = al.alone_test(rest, recs, 3, NOISE)
    shuffled = list(recs)
    random.Random(7).shuffle(shuffled)
    again = al.alone_test(rest, shuffled, 3, NOISE)
    assert again.test == first.test and again.heading == first.heading
    assert first.place is not None and again.place is not None
    assert first.place.tobytes() == again.place.tobytes()


def test_alone_refuses_a_robot_of_the_rest() -> None:
    recs, pos, psi = truth_fleet(1)
    with pytest.raises(ValueError, match="left out"):
        al.alone_test(evaluate_poses(tuple(range(1, 9)), (), pos, psi, 1), recs, 3, NOISE)


def test_alone_refuses_a_robot_without_a_record() -> None:
    recs, pos, psi = truth_fleet(1)
    with pytest.raises(ValueError, match="no record"):
        al.alone_test(rest_at_truth(pos, psi, 3), [r for r in recs if r.robot_id != 3], 3, NOISE)


# ------------------------------------------------------------ the last resort
def _test(robot: int, p: float = 1.0, rejected: int = 0, lost: int = 0) -> RobotTest:
    return RobotTest(robot, 3, rejected, 1, lost, p, 0, 0.0, 1.0)


def _verdict(ok: bool, *tests: RobotTest) -> FaultVerdict:
    return FaultVerdict(ok, (), None, (), tests, "")


def test_suspects_are_the_rejected_robots() -> None:
    tests = [_test(1, 1e-6), _test(2, 0.5, rejected=1), _test(3)]
    assert [t.robot for t in al.suspects_of(_verdict(False, *tests))] == [1]


def test_a_wrong_frame_names_no_suspect() -> None:
    # three robots rejected of four: more than one fault and false alarms explain
    tests = [_test(1, 1e-6), _test(2, 1e-7), _test(3, 1e-8), _test(4)]
    assert al.suspects_of(_verdict(False, *tests)) == []


def test_a_failed_frame_nobody_rejects_suspects_the_robots_of_its_failures() -> None:
    tests = [_test(1, 0.01, rejected=2), _test(2, 0.3, lost=1), _test(3, 0.5)]
    assert [t.robot for t in al.suspects_of(_verdict(False, *tests))] == [1, 2]
    assert al.suspects_of(_verdict(True, *tests)) == []


@dataclass(frozen=True)
class Rest:
    frame_robot: int
    ids: tuple[int, ...]
    positions: np.ndarray
    headings: np.ndarray


def _framer(pos: np.ndarray, psi: np.ndarray, passes: set[int]):  # type: ignore[no-untyped-def]
    """The others framed at their true poses, when the robot set aside is in ``passes``."""

    def frame_rest(rest: list[NeighborRecord]) -> Rest | None:
        ids = tuple(sorted(r.robot_id for r in rest))
        (left,) = set(range(1, len(pos) + 1)) - set(ids)
        if left not in passes:
            return None
        keep = [i - 1 for i in ids]
        return Rest(ids[0], ids, pos[keep], psi[keep])

    return frame_rest


def test_set_aside_names_the_one_robot_whose_rest_passes_and_who_fails_alone() -> None:
    recs, pos, psi = truth_fleet(4, kind="scale")
    tested = rest_at_truth(pos, psi, 0)  # unused: the suspect has a place of its own
    suspects = {3: (0.02, tested), 5: (0.3, tested)}
    found = al.set_aside(recs, suspects, NOISE, _framer(pos, psi, {3}))
    assert found is not None and found.robot == 3 and "alone" in found.why
    assert np.hypot(*(found.place - pos[2])) < 0.1


def test_set_aside_names_nobody_whose_record_fits_the_rest() -> None:
    recs, pos, psi = truth_fleet(4)
    tested = rest_at_truth(pos, psi, 0)
    assert al.set_aside(recs, {3: (0.02, tested)}, NOISE, _framer(pos, psi, {3})) is None


def test_set_aside_names_nobody_when_two_are_found() -> None:
    recs, pos, psi = truth_fleet(4, kind="scale")
    tested = rest_at_truth(pos, psi, 0)
    # robot 5 rejected in the fit, its rest passing too: ambiguous
    suspects = {3: (0.02, tested), 5: (1e-6, tested)}
    assert al.set_aside(recs, suspects, NOISE, _framer(pos, psi, {3, 5})) is None
    assert al.set_aside(recs, suspects, NOISE, _framer(pos, psi, {5})) is not None


def test_set_aside_without_suspects_names_nobody() -> None:
    recs, pos, psi = truth_fleet(4, kind="scale")
    assert al.set_aside(recs, {}, NOISE, _framer(pos, psi, {3})) is None


def test_the_rest_is_not_blamed_for_seeing_the_robot_set_aside() -> None:
    recs, _, _ = truth_fleet(3)
    rest = [r for r in recs if r.robot_id != 3]
    poses = build_poses(rest)
    blind = ft.fault_test(poses, NOISE, rest, search=False)
    place, _ = al.unrecorded_place(poses, rest, NOISE)
    assert place is not None
    seeing = ft.fault_test(poses, NOISE, rest, search=False, elsewhere=place.reshape(1, 2))
    # its place given, or found where the rest's loose sightings agree (outsiders.py)
    assert sum(t.lost for t in blind.tests) == 0 and sum(t.lost for t in seeing.tests) == 0
    assert seeing.fleet is not None and blind.fleet is not None
    assert seeing.fleet.p == blind.fleet.p == 1.0
    # found once: a place given is not found again
    gate = float(chdtri(2, ft.ALPHA_SIGHTING))
    assert len(outsider_places(poses, rest, NOISE, gate)) == 1
    assert len(outsider_places(poses, rest, NOISE, gate, place.reshape(1, 2))) == 0


def test_a_place_elsewhere_holds_only_for_the_frame_as_tested() -> None:
    recs, _, _ = truth_fleet(3)
    poses = build_poses(recs)
    with pytest.raises(ValueError, match="search"):
        ft.fault_test(poses, NOISE, recs, search=True, elsewhere=np.zeros((1, 2)))


# ------------------------------------------------------------ the screen of a frame that passes
IDS = tuple(range(1, 9))


def test_a_sound_fleet_at_its_true_poses_screens_nobody() -> None:
    for seed in range(1, 6):
        recs, pos, psi = truth_fleet(seed)
        assert al.absorbed(IDS, pos, psi, recs, NOISE) == []


@pytest.mark.parametrize("kind", ["scale", "shift", "rotate"])
def test_a_faulty_robot_at_its_true_pose_is_screened(kind: str) -> None:
    recs, pos, psi = truth_fleet(4, kind=kind)
    got = al.absorbed(IDS, pos, psi, recs, NOISE)
    assert [r for r, _ in got] == [3] and got[0][1] < ALPHA


def test_a_heading_that_absorbed_a_turned_compass_is_screened_by_the_masks() -> None:
    recs, pos, psi = truth_fleet(4, kind="rotate")
    turned = psi.copy()
    turned[2] += math.radians(40.0)  # the fit turns robot 3 with its sightings: they all land
    got = al.absorbed(IDS, pos, turned, recs, NOISE)
    assert [r for r, _ in got] == [3] and got[0][1] < ALPHA


def test_a_robot_nobody_saw_is_never_screened() -> None:
    recs, pos, psi = truth_fleet(1, kind="scale")
    blind = [NeighborRecord(r.robot_id, np.zeros((0, 2))) if r.robot_id != 3 else r for r in recs]
    assert 3 not in [r for r, _ in al.absorbed(IDS, pos, psi, blind, NOISE)]
    assert al.absorbed((1,), pos[:1], psi[:1], recs[:1], NOISE) == []


def test_the_screen_is_the_same_for_records_in_any_order() -> None:
    recs, pos, psi = truth_fleet(5, kind="shift")
    first = al.absorbed(IDS, pos, psi, recs, NOISE)
    shuffled = list(recs)
    random.Random(3).shuffle(shuffled)
    assert al.absorbed(IDS, pos, psi, shuffled, NOISE) == first and first


def test_the_screen_refuses_poses_that_are_not_one_per_robot() -> None:
    recs, pos, psi = truth_fleet(1)
    with pytest.raises(ValueError, match="positions"):
        al.absorbed(IDS, pos[:-1], psi, recs, NOISE)
    with pytest.raises(ValueError, match="headings"):
        al.absorbed(IDS, pos, psi[:, None], recs, NOISE)
