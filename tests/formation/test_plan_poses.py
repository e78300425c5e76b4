"""Plans from records of robots set down facing any direction (docs/design.md §9).

Records are in each robot's own fixed frame, so turning a robot's start heading changes
its record; the plan, mapped back to the world through the frame robot's start pose,
must not change. Shuffled records give a bit-identical plan.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from agent.core.formation.params import D_E, PHI_E_DEG, PlanParams
from agent.core.formation.plan import Plan, plan_from_records
from agent.core.formation.view.own_frame import in_own_frame
from agent.core.perception.sighting_noise import SightingNoise
from tests.formation.pose_fleets import sim_layout, unaligned_records

IDS = [1, 2, 3, 4, 5]
PARAMS = PlanParams(d_e=D_E, phi_e=math.radians(PHI_E_DEG))


def _to_world(plan: Plan, pos: np.ndarray, headings: np.ndarray) -> np.ndarray:
    """The plan's targets in the world: the common frame is the frame robot's fixed frame
    (its start, its body facing +y)."""
    k = IDS.index(plan.frame_robot)
    psi = headings[k] - math.pi / 2
    c, s = math.cos(psi), math.sin(psi)
    return np.asarray(pos[k] + plan.targets() @ np.array([[c, s], [-s, c]]))


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 10_000), st.floats(-math.pi, math.pi))
# hypothesis found it: two groups of near-equal headings (145° and -95° ± 10°) whose
# papers' model landed exactly half of every robot's sightings, a wrong frame planned at
# once (reidentify.LAND_SHARE)
@example(seed=391, turn=0.0)
# hypothesis found them: four robots facing within 16° of each other and one turned
# 130° (seed 35), or two turned 45° and 60° (seed 75); the aligned model with its
# sightings identified where they land fits a wrong frame (robot 2 to 3: 1.43 m against
# the true 0.74 m) that passes the fault test at p 3-4·10⁻⁴, while the pose fit explains
# every sighting (p 1): the candidate that fits best is taken (fleet_frame)
@example(seed=35, turn=0.0)
@example(seed=75, turn=0.0)
def test_start_headings_leave_the_pyramid_in_the_world_unchanged(seed: int, turn: float) -> None:
    _same_pyramid_in_the_world(seed, turn, timed=False)


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 10_000), st.floats(-math.pi, math.pi))
# hypothesis found it on the records without times: the aligned model fits three robots
# half a turn off (the test below); with times, the masks together reject that frame
@example(seed=2681, turn=0.0)
def test_start_headings_leave_the_pyramid_in_the_world_unchanged_with_times(
    seed: int, turn: float
) -> None:
    """The property above on records with times, as today's agents send them: every mask
    turned back to its target's start heading (multi_start.half_turn_test weighs them)."""
    _same_pyramid_in_the_world(seed, turn, timed=True)


def _same_pyramid_in_the_world(seed: int, turn: float, timed: bool) -> None:
    rng = np.random.default_rng(seed)
    pos = sim_layout(rng, len(IDS))
    aligned = np.full(len(IDS), math.pi / 2)
    facing = rng.uniform(-math.pi, math.pi, len(IDS))
    a = plan_from_records(unaligned_records(IDS, pos, aligned, timed=timed), PARAMS)
    b = plan_from_records(unaligned_records(IDS, pos, facing, timed=timed), PARAMS)
    assert a.excluded == b.excluded == ()
    assert [r.parent for r in a.robots] == [r.parent for r in b.robots]
    np.testing.assert_allclose(_to_world(a, pos, aligned), _to_world(b, pos, facing), atol=1e-6)
    # a rigid motion of the whole fleet changes the records only by rounding: the same
    # plan in the common frame
    c, s = math.cos(turn), math.sin(turn)
    moved = pos @ np.array([[c, s], [-s, c]]) + np.array([3.0, -1.0])
    again = plan_from_records(unaligned_records(IDS, moved, facing + turn, timed=timed), PARAMS)
    assert [r.parent for r in again.robots] == [r.parent for r in b.robots]
    np.testing.assert_allclose(again.targets(), b.targets(), atol=1e-6)


@settings(max_examples=10, deadline=None)
@given(st.integers(0, 10_000), st.randoms(use_true_random=False), st.booleans())
def test_shuffled_records_give_a_bit_identical_plan(seed: int, rnd, timed: bool) -> None:  # type: ignore[no-untyped-def]
    rng = np.random.default_rng(seed)
    pos = sim_layout(rng, len(IDS))
    facing = rng.uniform(-math.pi, math.pi, len(IDS))
    recs = unaligned_records(IDS, pos, facing, rng, 0.05, math.radians(3), timed=timed)
    shuffled = list(recs)
    rnd.shuffle(shuffled)
    try:
        a = plan_from_records(recs, PARAMS)
    except ValueError:
        with pytest.raises(ValueError):
            plan_from_records(shuffled, PARAMS)
        return
    b = plan_from_records(shuffled, PARAMS)
    assert a.digest == b.digest and a.psi.tobytes() == b.psi.tobytes()


def test_a_known_answer_two_robots_facing_each_other() -> None:
    # robot 1 at the origin facing north; robot 2 one metre east facing west (ψ = +90°):
    # 1 sees 2 at (1, 0); 2 sees 1 straight ahead, (0, 1) in its own frame
    pos = np.array([[0.0, 0.0], [1.0, 0.0]])
    recs = unaligned_records([1, 2], pos, np.array([math.pi / 2, math.pi]))
    np.testing.assert_allclose(recs[1].neighbours, [[0.0, 1.0]], atol=1e-12)
    plan = plan_from_records(recs, PARAMS)
    assert plan.psi_of(1) == pytest.approx(0.0, abs=1e-9)
    assert plan.psi_of(2) == pytest.approx(math.pi / 2, abs=1e-9)
    # robot 2 walks its plan in its own frame: its goal turned by −90°
    r2 = plan.robot(2)
    mine = in_own_frame(plan, plan.psi_of(2)).robot(2)
    d = np.asarray(r2.target) - np.asarray(r2.start)
    np.testing.assert_allclose(np.asarray(mine.target) - np.asarray(mine.start), [d[1], -d[0]])


def test_aligned_starts_plan_exactly_as_the_papers() -> None:
    rng = np.random.default_rng(5)
    pos = sim_layout(rng, len(IDS))
    recs = unaligned_records(IDS, pos, np.full(len(IDS), math.pi / 2), rng, 0.05, 0.05)
    ours = plan_from_records(recs, PARAMS, noise=SightingNoise.synthetic(0.01, 0.05, 0.05))
    papers = plan_from_records(
        recs, PlanParams(d_e=D_E, phi_e=math.radians(PHI_E_DEG), frame_method="lsq")
    )
    assert ours.digest == papers.digest and len(ours.psi) == 0


def test_three_robots_of_five_half_a_turn_off_are_not_planned_on() -> None:
    """Found by hypothesis on the property above (seed 2681, no noise): the aligned model
    with its sightings identified where they land fits a frame in which robots 2, 4 and 5
    stand half a turn off their true headings, and every robot passes its test: their
    masks, each 180° off, read as front/back confusions one by one. Together, ten masks
    between {1, 3} and {2, 4, 5} all read the other way round reject that frame
    (multi_start.half_turn_test, p 5·10⁻⁵ < ALPHA), and the pose fit is planned on."""
    rng = np.random.default_rng(2681)
    pos = sim_layout(rng, len(IDS))
    aligned = np.full(len(IDS), math.pi / 2)
    facing = rng.uniform(-math.pi, math.pi, len(IDS))
    a = plan_from_records(unaligned_records(IDS, pos, aligned, timed=True), PARAMS)
    b = plan_from_records(unaligned_records(IDS, pos, facing, timed=True), PARAMS)
    np.testing.assert_allclose(_to_world(a, pos, aligned), _to_world(b, pos, facing), atol=1e-6)


@pytest.mark.xfail(strict=True, reason="records without times: masks cannot tell front from back")
def test_without_times_three_robots_of_five_half_a_turn_off_are_planned_on() -> None:
    """The fleet above with records without times (older agents): a mask as recorded may
    show its target after the half turn of its own search (52 % of them on the corpus
    read the other way round), so the masks say nothing of front and back and the joint
    test leaves them out; nothing else in the records rejects the aligned model's frame
    (its global test p 0.19), and the plan is laid facing the other way. Strict: once
    something does, this test says so."""
    rng = np.random.default_rng(2681)
    pos = sim_layout(rng, len(IDS))
    aligned = np.full(len(IDS), math.pi / 2)
    facing = rng.uniform(-math.pi, math.pi, len(IDS))
    a = plan_from_records(unaligned_records(IDS, pos, aligned), PARAMS)
    b = plan_from_records(unaligned_records(IDS, pos, facing), PARAMS)
    np.testing.assert_allclose(_to_world(a, pos, aligned), _to_world(b, pos, facing), atol=1e-6)
