"""The corridor check before each step (agent/core/control/corridor.py): known answers,
hypothesis invariants, one test per error branch."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.control.corridor import (
    FORGET_NEAR,
    GO,
    LEFT,
    MAX_VIA_TURN,
    RIGHT,
    VIA,
    WAIT,
    CorridorParams,
    back_off,
    blocking,
    check_step,
    closest_approach,
    confirmed,
    in_view,
    patience,
    plan_rank,
)
from agent.core.formation.params import PlanParams
from agent.core.nao import CAMERA_HFOV

NORTH = math.pi / 2
CP = CorridorParams()  # radius 0.2, margin 0.05: clearance 0.45 m


def test_clearance_is_twice_the_planners_radius_plus_the_margin() -> None:
    assert CP.radius == PlanParams().radius
    assert CP.clearance == pytest.approx(2 * 0.2 + 0.05)


def test_closest_approach_known_answers() -> None:
    pts = np.array([[0.0, 0.5], [0.3, 0.1], [0.0, -0.4], [3.0, 4.0]])
    d = closest_approach(np.array([0.0, 0.2]), pts)
    assert d == pytest.approx([0.3, 0.3, 0.4, math.hypot(3.0, 3.8)])
    assert closest_approach(np.zeros(2), pts) == pytest.approx(np.hypot(*pts.T))


def test_free_corridor_goes() -> None:
    # a NAO 1 m ahead: a 20 cm step ends 0.8 m from it
    v = check_step(0.2, NORTH, np.array([[0.0, 1.0], [-1.0, 0.0]]), CP)
    assert v.action == GO and len(v.blockers) == 0
    assert check_step(0.2, NORTH, np.zeros((0, 2)), CP).action == GO


def test_nao_ahead_makes_the_robot_wait_then_step_aside() -> None:
    # a NAO 0.6 m ahead: the step ends 0.4 m from it (< 0.45)
    ahead = np.array([[0.0, 0.6]])
    assert blocking(0.2, NORTH, ahead, CP.clearance).tolist() == [True]
    w = check_step(0.2, NORTH, ahead, CP, waited=0, rank=0)
    assert w.action == WAIT
    assert w.blockers == pytest.approx(ahead)
    # rank 0: one poll of patience, then a via step, on the right on a tie
    v = check_step(0.2, NORTH, ahead, CP, waited=1, rank=0)
    assert v.action == VIA and v.side == RIGHT and v.walk == 0.2
    # the tangent to the circle of 0.55 m round the NAO: asin(0.55 / 0.6) to the right
    assert v.heading == pytest.approx(NORTH - math.asin(0.55 / 0.6))
    assert not blocking(0.2, v.heading, ahead, CP.clearance).any()


def test_via_passes_on_the_side_the_blocker_is_not() -> None:
    # the NAO stands a little to the right of the line (x > 0 while facing north)
    v = check_step(0.2, NORTH, np.array([[0.1, 0.55]]), CP, waited=5)
    assert v.action == VIA and v.side == LEFT and v.heading > NORTH
    v = check_step(0.2, NORTH, np.array([[-0.1, 0.55]]), CP, waited=5)
    assert v.action == VIA and v.side == RIGHT and v.heading < NORTH


def test_head_on_both_pass_on_their_right() -> None:
    # A at the origin facing north, B 0.6 m ahead facing south, 2 cm to A's left
    a_sees_b = np.array([[-0.02, 0.6]])
    b_sees_a = -a_sees_b
    va = check_step(0.2, NORTH, a_sees_b, CP, waited=10)
    vb = check_step(0.2, -NORTH, b_sees_a, CP, waited=10)
    assert va.side == RIGHT and vb.side == RIGHT
    # the two via steps move the robots apart sideways (x): A east, B west
    assert math.cos(va.heading) > 0 > math.cos(vb.heading)


def test_a_detour_keeps_its_side_and_falls_back_to_the_other() -> None:
    ahead = np.array([[0.0, 0.6]])
    assert check_step(0.2, NORTH, ahead, CP, waited=5, side=LEFT).side == LEFT
    # a second NAO on the right blocks the right tangent: the left one is taken
    both = np.array([[0.0, 0.6], [0.35, 0.35]])
    v = check_step(0.2, NORTH, both, CP, waited=5, side=RIGHT)
    assert v.action == VIA and v.side == LEFT
    # walled in on both sides: wait
    walled = np.array([[0.0, 0.6], [0.35, 0.35], [-0.35, 0.35]])
    assert check_step(0.2, NORTH, walled, CP, waited=5).action == WAIT


def test_a_via_step_clears_the_members_standing_unseen() -> None:
    """A NAO ahead, a little left: the right tangent round it passes a member standing by
    the plan at (0.2, 0.55), unseen, within the clearance, so the tangent widens round
    it too (to 90° off the way, the most a via step turns); one standing where even that
    is blocked sends the via to the left; walled in on both sides: wait."""
    ahead = np.array([[-0.2, 0.6]])
    plain = check_step(0.2, NORTH, ahead, CP, waited=5)
    assert plain.action == VIA and plain.side == RIGHT
    assert plain.heading == pytest.approx(
        NORTH + math.atan2(0.2, 0.6) - math.asin(0.55 / math.hypot(0.2, 0.6))
    )
    member = np.array([[0.2, 0.55]])
    assert blocking(0.2, plain.heading, member, CP.clearance).any()
    v = check_step(0.2, NORTH, ahead, CP, waited=5, members=member)
    assert v.action == VIA and v.side == RIGHT and v.heading == pytest.approx(0.0, abs=1e-9)
    assert not blocking(0.2, v.heading, np.vstack([ahead, member]), CP.clearance).any()
    v = check_step(0.2, NORTH, ahead, CP, waited=5, members=np.array([[0.45, 0.1]]))
    assert v.action == VIA and v.side == LEFT
    # standing members never make a planned step wait
    assert check_step(0.2, NORTH, np.zeros((0, 2)), CP, members=ahead).action == GO
    walled = np.array([[0.45, 0.1], [-0.45, 0.1]])
    assert check_step(0.2, NORTH, ahead, CP, waited=5, members=walled).action == WAIT


def test_a_nao_on_the_goal_is_waited_for_not_walked_round() -> None:
    ahead = np.array([[0.0, 0.6]])
    v = check_step(0.2, NORTH, ahead, CP, waited=5, goal=np.array([0.0, 0.9]))
    assert v.action == WAIT
    v = check_step(0.2, NORTH, ahead, CP, waited=5, goal=np.array([0.0, 1.2]))
    assert v.action == VIA


def test_stepping_away_from_a_close_nao_goes() -> None:
    # a NAO 0.3 m behind-left: the step north takes us away from it
    assert check_step(0.2, NORTH, np.array([[-0.2, -0.2]]), CP).action == GO
    # backward steps are not checked (the camera looks ahead)
    assert check_step(-0.1, NORTH, np.array([[0.0, -0.3]]), CP).action == GO


def test_patience_grows_with_the_plan_rank() -> None:
    assert [patience(k, CP) for k in range(4)] == [1, 2, 3, 4]
    assert patience(1000, CP) == CP.max_polls
    order = [(1, 5), (0, 3), (1, 2), (2, 1)]  # (wave, id)
    assert [plan_rank(order, r) for r in (3, 2, 5, 1)] == [0, 1, 2, 3]


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"radius": 0.0}, "radius"),
        ({"margin": -0.1}, "margin"),
        ({"via_extra": math.nan}, "via_extra"),
        ({"poll": math.inf}, "poll"),
        ({"tie": -1.0}, "tie"),
        ({"base_polls": 61}, "base_polls"),
    ],
)
def test_bad_params(kwargs: dict[str, float], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        CorridorParams(**kwargs)  # type: ignore[arg-type]


def test_the_lookahead_sees_a_nao_beside_the_way_while_it_is_still_in_the_image() -> None:
    # a NAO 0.25 m right of the way, 0.7 m ahead (in the image: 20° off the heading):
    # a 20 cm step ends hypot(0.25, 0.5) = 0.56 m from it (> 0.45: go) ...
    beside = np.array([[0.25, 0.7]])
    assert check_step(0.2, NORTH, beside, CP).action == GO
    # ... the way 0.5 m beyond passes it at 0.25 m: wait, then round it on the left
    w = check_step(0.2, NORTH, beside, CP, ahead=CP.lookahead)
    assert w.action == WAIT and w.blockers == pytest.approx(beside)
    v = check_step(0.2, NORTH, beside, CP, waited=1, ahead=CP.lookahead)
    assert v.action == VIA and v.side == LEFT
    # the tangent to the 0.55 m circle round it, on its left: asin(0.55 / 0.744) off its bearing
    rho = math.hypot(0.25, 0.7)
    assert v.heading == pytest.approx(math.atan2(0.7, 0.25) + math.asin(0.55 / rho))
    # a NAO beyond the lookahead's reach does not block yet
    far = np.array([[0.25, 1.3]])
    assert check_step(0.2, NORTH, far, CP, ahead=CP.lookahead).action == GO
    assert CP.lookahead == 0.5


def test_bad_inputs() -> None:
    with pytest.raises(ValueError, match="rank"):
        patience(-1, CP)
    with pytest.raises(ValueError, match="not in the plan"):
        plan_rank([(0, 1)], 2)
    with pytest.raises(ValueError, match="finite"):
        check_step(0.2, NORTH, np.array([[math.nan, 1.0]]), CP)
    with pytest.raises(ValueError, match="walk"):
        check_step(2.0, NORTH, np.zeros((0, 2)), CP)
    with pytest.raises(ValueError, match="heading"):
        check_step(0.2, math.inf, np.zeros((0, 2)), CP)
    with pytest.raises(ValueError, match="waited"):
        check_step(0.2, NORTH, np.zeros((0, 2)), CP, waited=-1)
    with pytest.raises(ValueError, match="side"):
        check_step(0.2, NORTH, np.zeros((0, 2)), CP, side=2)
    with pytest.raises(ValueError, match="ahead"):
        check_step(0.2, NORTH, np.zeros((0, 2)), CP, ahead=-0.1)
    with pytest.raises(ValueError, match="lookahead"):
        CorridorParams(lookahead=math.nan)
    with pytest.raises(ValueError, match="clearance"):
        blocking(0.2, NORTH, np.zeros((0, 2)), -1.0)


coord = st.floats(-3.0, 3.0, allow_nan=False)
points = st.lists(st.tuples(coord, coord), min_size=0, max_size=6)


@settings(max_examples=200, deadline=None)
@given(
    walk=st.floats(0.01, 0.2),
    heading=st.floats(-math.pi, math.pi),
    pts=points,
    waited=st.integers(0, 10),
    rank=st.integers(0, 9),
    still=points,
)
def test_invariants(
    walk: float,
    heading: float,
    pts: list[tuple[float, float]],
    waited: int,
    rank: int,
    still: list[tuple[float, float]],
) -> None:
    others = np.array(pts, dtype=np.float64).reshape(-1, 2)
    standing = np.array(still, dtype=np.float64).reshape(-1, 2)
    v = check_step(walk, heading, others, CP, waited, rank, members=standing)
    # deterministic
    again = check_step(walk, heading, others.copy(), CP, waited, rank, members=standing.copy())
    assert (again.action, again.heading, again.side) == (v.action, v.heading, v.side)
    c = CP.clearance
    if v.action == VIA:  # a via step clears the standing members as it clears the NAOs seen
        assert not blocking(walk, v.heading, standing, c).any()
    # the standing members change no verdict but a via step's
    plain = check_step(walk, heading, others, CP, waited, rank)
    assert (plain.action == GO) == (v.action == GO)
    if v.action in (GO, VIA):
        # the step taken never comes within the clearance of a NAO unless it moves away
        h = heading if v.action == GO else v.heading
        end = walk * np.array([math.cos(h), math.sin(h)])
        closest = closest_approach(end, others)
        now = np.hypot(*others.T) if len(others) else np.zeros(0)
        assert np.all((closest >= c) | (closest >= now - 1e-9))
    if v.action == VIA:
        assert abs(math.remainder(v.heading - heading, 2 * math.pi)) <= MAX_VIA_TURN + 1e-9
    if v.action == GO:
        assert len(v.blockers) == 0
    else:
        assert len(v.blockers) >= 1
        assert np.all(blocking(walk, heading, v.blockers, c))
    if waited < patience(rank, CP):
        assert v.action != VIA  # the rank's patience comes first


# ------------------------------------------------------------------ back_off


HFOV = CAMERA_HFOV


def test_back_off_known_answers() -> None:
    ahead = np.array([[0.0, 0.62]])  # remembered 0.62 m straight ahead, facing north
    # not in the image: step back to FORGET_NEAR + margin = 0.75 m, i.e. 0.13 m
    assert back_off(ahead, np.zeros((0, 2)), NORTH, HFOV, CP) == pytest.approx(0.13)
    # much nearer: at most back_max
    assert back_off(np.array([[0.0, 0.45]]), np.zeros((0, 2)), NORTH, HFOV, CP) == 0.15
    # the image shows it (within 2·margin): it is there, no need to look again
    assert back_off(ahead, np.array([[0.05, 0.65]]), NORTH, HFOV, CP) == 0.0
    # far enough to be seen, or behind the robot (stepping back comes nearer): 0
    assert back_off(np.array([[0.0, FORGET_NEAR + 0.01]]), np.zeros((0, 2)), NORTH, HFOV, CP) == 0
    assert back_off(np.array([[0.3, -0.1]]), np.zeros((0, 2)), NORTH, HFOV, CP) == 0.0
    # beside and a little ahead, 0.67 m at 36° off the heading: back until 0.75 m away
    b = 0.67 * np.array([[math.cos(NORTH - math.radians(36)), math.sin(NORTH - math.radians(36))]])
    d = back_off(b, np.zeros((0, 2)), NORTH, HFOV, CP)
    assert math.hypot(b[0, 0], b[0, 1] + d) == pytest.approx(FORGET_NEAR + CP.margin)
    assert 0.09 < d < 0.1


def test_a_nao_believed_near_the_edge_or_just_past_view_near_is_not_forgotten() -> None:
    """At 100 NAOs: robot 91 stepped back from robot 99 to a believed ~0.6 m,
    forgot it when the image did not show it (truly 0.58 m, 35° off the heading), walked
    on and touched it. An image forgets only what it surely shows: believed at least
    FORGET_NEAR away and FORGET_EDGE inside the field of view (30.45° - 10° = 20.45°)."""

    def at(r: float, deg: float) -> np.ndarray:
        a = NORTH + math.radians(deg)
        return np.array([[r * math.cos(a), r * math.sin(a)]])

    assert not in_view(at(0.62, -22.0), NORTH, HFOV)[0]  # the incident: too near
    assert not in_view(at(0.8, -22.0), NORTH, HFOV)[0]  # near the edge
    assert in_view(at(0.8, -20.0), NORTH, HFOV)[0]
    assert in_view(at(FORGET_NEAR + 1e-9, 0.0), NORTH, HFOV)[0]
    assert not in_view(at(FORGET_NEAR - 0.01, 0.0), NORTH, HFOV)[0]
    assert in_view(at(0.62, -22.0), NORTH, HFOV, near=0.6, edge=math.radians(5))[0]  # before
    with pytest.raises(ValueError, match="edge"):
        in_view(at(1.0, 0.0), NORTH, HFOV, edge=math.nan)


def test_confirmed_known_answers() -> None:
    b = np.array([0.0, 0.52])
    assert confirmed(b, np.array([[0.05, 0.55]]), CP)  # 5.8 cm < 2·margin
    assert not confirmed(b, np.array([[0.2, 0.52]]), CP)
    assert not confirmed(b, np.zeros((0, 2)), CP)


def test_back_off_errors() -> None:
    with pytest.raises(ValueError, match="one blocker"):
        back_off(np.zeros((2, 2)), np.zeros((0, 2)), NORTH, HFOV, CP)
    with pytest.raises(ValueError, match="heading"):
        back_off(np.zeros((1, 2)), np.zeros((0, 2)), math.nan, HFOV, CP)
    with pytest.raises(ValueError, match="finite"):
        back_off(np.array([[math.inf, 0.0]]), np.zeros((0, 2)), NORTH, HFOV, CP)
    with pytest.raises(ValueError, match="back_max"):
        CorridorParams(back_max=-0.1)


@settings(max_examples=200, deadline=None)
@given(x=st.floats(-1.0, 1.0), y=st.floats(-1.0, 1.0), h=st.floats(-math.pi, math.pi))
def test_back_off_never_exceeds_back_max_and_ends_at_the_view_range(
    x: float, y: float, h: float
) -> None:
    b = back_off(np.array([[x, y]]), np.zeros((0, 2)), h, HFOV, CP)
    assert 0.0 <= b <= CP.back_max + 1e-12
    if b > 0.0:
        assert math.hypot(x, y) < FORGET_NEAR
        assert x * math.cos(h) + y * math.sin(h) >= 0.0  # never backs towards it
        after = math.hypot(x + b * math.cos(h), y + b * math.sin(h))
        assert b == CP.back_max or after == pytest.approx(FORGET_NEAR + CP.margin)
