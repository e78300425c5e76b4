"""The whole plan: invariants, digest, safety, obstacles, errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agent.core.formation import plan as plan_module
from agent.core.formation.frame.records import NeighborRecord
from agent.core.formation.params import D_E, PlanParams
from agent.core.formation.plan import Plan, plan_from_positions, plan_from_records
from agent.core.formation.shape.pyramid import parent_of
from agent.core.formation.waves.obstacles import SLOT_CLEARANCE
from agent.core.formation.waves.safety import check_safety
from tests.formation.conftest import random_fleet, records_from_positions


def _rot(theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


def test_three_robots_by_hand() -> None:
    # robots exactly on a pyramid of d_e = 1 facing north: the plan keeps them there.
    h = math.cos(math.radians(30))
    pos = np.array([[0.0, 0.0], [-0.5, -h], [0.5, -h]]) + np.array([2.0, 1.0])
    plan = plan_from_positions([5, 8, 3], pos[[0, 1, 2]], PlanParams(d_e=1.0))
    assert plan.leader == 5
    assert plan.axis == pytest.approx(math.pi / 2)
    r5, r8, r3 = plan.robot(5), plan.robot(8), plan.robot(3)
    assert (r5.order, r8.order, r3.order) == (0, 1, 2)
    assert (r5.parent, r8.parent, r3.parent) == (-1, 5, 5)
    for r in plan.robots:
        assert r.distance == pytest.approx(0.0, abs=1e-9)
        assert r.heading == pytest.approx(plan.axis)  # nothing to walk: face the axis
    assert plan.robot(5).wave == 0 and plan.robot(5).after == ()  # the leader goes first


@pytest.mark.parametrize("strategy", ["paper", "optimal", "capt", "default"])
def test_random_fleets_are_safe_and_consistent(strategy: str) -> None:
    rng = np.random.default_rng(42)
    for n in (1, 2, 3, 5, 8, 12, 15):
        pos = random_fleet(rng, n, spacing=0.6)
        ids = [int(i) for i in rng.permutation(100)[:n]]
        plan = plan_from_positions(ids, pos, PlanParams(d_e=D_E, strategy=strategy))
        assert [r.robot_id for r in plan.robots] == sorted(ids)
        assert sorted(r.order for r in plan.robots) == list(range(n))
        assert check_safety(plan.paths(), plan.wave_of(), 0.2) == []
        by_order = {r.order: r for r in plan.robots}
        for r in plan.robots:
            if r.order == 0:
                assert r.parent == -1 and r.robot_id == plan.leader
            else:
                par = by_order[parent_of(r.order)]
                assert r.parent == par.robot_id
                assert math.hypot(*(r.target - par.target)) == pytest.approx(D_E)
            first = r.waypoints()[0]
            assert math.hypot(*(first - r.start)) == pytest.approx(r.distance)
        assert sorted(i for w in plan.waves for i in w) == sorted(ids)


def test_shuffled_records_give_bit_identical_digest() -> None:
    rng = np.random.default_rng(7)
    pos = random_fleet(rng, 9, spacing=0.6)
    ids = list(range(10, 19))
    recs = records_from_positions(ids, pos, noise=0.03, rng=rng)
    base = plan_from_records(recs)
    for _ in range(5):
        order = rng.permutation(len(recs))
        shuffled = []
        for k in order:
            r = recs[k]
            p = rng.permutation(r.count)
            shuffled.append(NeighborRecord(r.robot_id, r.neighbours[p]))
        assert plan_from_records(shuffled).digest == base.digest
    # plan in the frame robot's fixed frame: it starts at the origin
    assert np.allclose(base.robot(base.frame_robot).start, 0.0)


def test_rigid_motion_moves_the_plan() -> None:
    rng = np.random.default_rng(9)
    for _ in range(5):
        pos = random_fleet(rng, 10, spacing=0.6)
        ids = list(range(10))
        theta, shift = rng.uniform(-math.pi, math.pi), rng.uniform(-5, 5, 2)
        moved = pos @ _rot(theta).T + shift
        for strategy in ("paper", "optimal"):
            a = plan_from_positions(ids, pos, PlanParams(strategy=strategy))
            b = plan_from_positions(ids, moved, PlanParams(strategy=strategy))
            assert a.leader == b.leader
            assert [r.order for r in a.robots] == [r.order for r in b.robots]
            assert np.allclose(a.targets() @ _rot(theta).T + shift, b.targets(), atol=1e-6)
            d = (b.axis - a.axis - theta + math.pi) % (2 * math.pi) - math.pi
            assert abs(d) < 1e-6


def test_collinear_and_clustered_fleets() -> None:
    line = np.stack([np.arange(8) * 0.7, np.zeros(8)], axis=1)
    plan = plan_from_positions(list(range(8)), line)
    assert check_safety(plan.paths(), plan.wave_of(), 0.2) == []
    rng = np.random.default_rng(1)
    cluster = random_fleet(rng, 12, spacing=0.45, spread=1.0)
    plan = plan_from_positions(list(range(12)), cluster, PlanParams(d_e=2.0))
    assert check_safety(plan.paths(), plan.wave_of(), 0.2) == []


def test_obstacles_take_part_and_the_pyramid_moves_out() -> None:
    # the paper's procedure (5.1.2): obstacles as robots, then the sideways shift
    rng = np.random.default_rng(2)
    pts = random_fleet(rng, 11, spacing=0.8)
    robots, obstacles = pts[:8], pts[8:]
    params = PlanParams(d_e=D_E, obstacle_method="paper")
    plan = plan_from_positions(list(range(8)), robots, params, obstacles=obstacles)
    assert _safe_with(plan, obstacles)
    t = plan.targets()
    d = np.hypot(*(t[:, None, :] - obstacles[None, :, :]).T)
    assert d.min() >= 0.8 - 1e-9  # final pyramid clear of obstacles (4·radius)
    assert sorted(r.order for r in plan.robots) == list(range(8))


def _safe_with(plan: Plan, obstacles: np.ndarray) -> bool:
    paths = plan.paths() + [np.vstack([o, o]) for o in obstacles]
    waves = list(plan.wave_of()) + [10**6] * len(obstacles)  # obstacles never move
    return check_safety(paths, waves, 0.2) == []


def test_near_keeps_the_pattern_when_the_obstacle_is_only_in_the_way() -> None:
    # three robots, one 4 m south of the two others; an obstacle on the middle of the
    # longest straight path, > 0.6 m (SLOT_CLEARANCE) from every slot: the pattern of the
    # obstacle-free plan is already clear (ring 0); ring 1 (d_e/4 = 0.25 m) shortens the
    # bent path, so the pattern moves by one ring at most, the paper's shift much more
    pos = np.array([[0.0, -4.0], [-0.5, 0.0], [0.5, 0.0]])
    free = plan_from_positions([1, 2, 3], pos, PlanParams(d_e=1.0))
    longest = max(free.robots, key=lambda r: r.length())
    assert longest.robot_id == 1
    obstacle = ((longest.start + longest.target) / 2)[None, :]
    assert np.hypot(*(free.targets() - obstacle).T).min() > 0.7
    assert np.hypot(*(pos - obstacle).T).min() > 0.5
    plan = plan_from_positions([1, 2, 3], pos, PlanParams(d_e=1.0), obstacles=obstacle)
    shift = plan.targets() - free.targets()
    np.testing.assert_allclose(shift, np.repeat(shift[:1], 3, axis=0), atol=1e-12)
    assert np.hypot(*shift[0]) <= 0.25 + 1e-9
    np.testing.assert_allclose(plan.origin - free.origin, shift[0], atol=1e-12)
    assert _safe_with(plan, obstacle)
    assert not plan.robot(2).via and not plan.robot(3).via
    paper = plan_from_positions(
        [1, 2, 3], pos, PlanParams(d_e=1.0, obstacle_method="paper"), obstacles=obstacle
    )
    assert sum(r.length() for r in plan.robots) < sum(r.length() for r in paper.robots)
    assert np.hypot(*(paper.origin - free.origin)) > 0.5


def test_near_moves_the_pattern_by_the_smallest_clear_ring() -> None:
    rng = np.random.default_rng(2)
    pts = random_fleet(rng, 11, spacing=0.8)
    robots, obstacles = pts[:8], pts[8:]
    params = PlanParams(d_e=D_E, obstacle_method="near")
    free = plan_from_positions(list(range(8)), robots, PlanParams(d_e=D_E))
    plan = plan_from_positions(list(range(8)), robots, params, obstacles=obstacles)
    assert _safe_with(plan, obstacles)
    t = plan.targets()
    d = np.hypot(*(t[:, None, :] - obstacles[None, :, :]).T)
    assert d.min() >= SLOT_CLEARANCE * 0.2 - 1e-9
    shift = plan.origin - free.origin  # a ring of step d_e/4
    assert np.hypot(*shift) / 0.2 == pytest.approx(round(np.hypot(*shift) / 0.2), abs=1e-9)
    assert plan.axis == free.axis  # the pattern of the robots alone, only translated
    assert sorted(r.order for r in plan.robots) == list(range(8))
    # bit-identical whatever the order of the robots
    perm = rng.permutation(8)
    again = plan_from_positions(perm.tolist(), robots[perm], params, obstacles=obstacles)
    assert again.digest == plan.digest


def test_default_falls_back_to_the_paper_procedure(monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(2)
    pts = random_fleet(rng, 11, spacing=0.8)
    robots, obstacles = pts[:8], pts[8:]
    near = plan_from_positions(list(range(8)), robots, obstacles=obstacles)
    monkeypatch.setattr(plan_module, "plan_near_obstacles", lambda *a: None)
    fallback = plan_from_positions(list(range(8)), robots, obstacles=obstacles)
    paper = plan_from_positions(
        list(range(8)), robots, PlanParams(obstacle_method="paper"), obstacles=obstacles
    )
    assert fallback.digest == paper.digest != near.digest
    with pytest.raises(ValueError, match="near placement"):
        plan_from_positions(
            list(range(8)), robots, PlanParams(obstacle_method="near"), obstacles=obstacles
        )


def test_plan_errors() -> None:
    with pytest.raises(ValueError, match="duplicate"):
        plan_from_positions([1, 1], np.zeros((2, 2)))
    with pytest.raises(ValueError, match="no robots"):
        plan_from_positions([], np.zeros((0, 2)))
    with pytest.raises(ValueError, match="shape"):
        plan_from_positions([1], np.zeros((1, 3)))
    with pytest.raises(ValueError, match="2 ids but 1"):
        plan_from_positions([1, 2], np.zeros((1, 2)))
    with pytest.raises(ValueError, match="non-finite"):
        plan_from_positions([1], np.array([[np.nan, 0.0]]))
    with pytest.raises(ValueError, match="non-negative"):
        plan_from_positions([-1], np.zeros((1, 2)))
    with pytest.raises(ValueError, match="obstacles"):
        plan_from_positions([1], np.zeros((1, 2)), obstacles=np.zeros((2, 3)))
    with pytest.raises(ValueError, match="not in the plan"):
        plan_from_positions([1], np.zeros((1, 2))).robot(2)
