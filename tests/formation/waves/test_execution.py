"""Execution rules and makespans; the plan-level property tests (safe, found, canonical)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.formation.params import D_E, PlanParams
from agent.core.formation.plan import Plan, plan_from_positions
from agent.core.formation.waves.execution import (
    capt_makespan,
    check_dependencies,
    dependency_makespan,
    optimal_total,
    path_lengths,
    wave_makespan,
)
from agent.core.formation.waves.safety import check_safety

R = 0.2


def P(*pts: tuple[float, float]) -> np.ndarray:
    return np.array(pts, dtype=np.float64)


def test_makespans_by_hand() -> None:
    lens = np.array([1.0, 2.0, 3.0, 0.5])
    assert wave_makespan(lens, [0, 1, 1, 2]) == pytest.approx(1.0 + 3.0 + 0.5)
    # 1 and 2 wait for 0; 3 waits for 1 only: chains 0-1-3 = 3.5, 0-2 = 4
    assert dependency_makespan(lens, [[], [0], [0], [1]], [0, 1, 1, 2]) == pytest.approx(4.0)
    assert path_lengths([P((0, 0), (3, 4)), P((1, 1)), P((0, 0), (0, 1), (1, 1))]).tolist() == [
        5.0,
        0.0,
        2.0,
    ]
    s, t = P((0, 0), (10, 0)), P((10, 1), (0, 1))
    assert capt_makespan(s, t) == pytest.approx(1.0)
    assert optimal_total(s, t) == pytest.approx(2.0)


def test_dependency_rule_orders_close_pairs() -> None:
    # robot 1 stands 0.1 m beside robot 0's path: it must leave first
    paths = [P((0, 0), (4, 0)), P((2, 0.1), (2, 3))]
    assert check_dependencies(paths, [[1], []], [1, 0], R) == []
    v = check_dependencies(paths, [[], []], [0, 0], R)
    assert len(v) == 1 and v[0].kind == "paths"
    v = check_dependencies(paths, [[], [0]], [0, 1], R)  # wrong order
    assert len(v) == 1 and v[0].kind == "path-vs-standing"
    # transitively through a third robot far away
    paths3 = [*paths, P((50, 50), (51, 50))]
    assert check_dependencies(paths3, [[2], [], [1]], [2, 0, 1], R) == []
    assert check_dependencies([], [], [], R) == []


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: wave_makespan(np.ones(2), [0]), "wave numbers"),
        (lambda: wave_makespan(np.ones(1), [-1]), ">= 0"),
        (lambda: dependency_makespan(np.ones(2), [[]], [0, 1]), "dependency lists"),
        (lambda: dependency_makespan(np.ones(2), [[], [5]], [0, 1]), "not a robot row"),
        (lambda: dependency_makespan(np.ones(2), [[], [1]], [0, 1]), "itself"),
        (lambda: dependency_makespan(np.ones(2), [[], [0]], [0]), "wave numbers"),
        (lambda: dependency_makespan(np.ones(2), [[1], []], [0, 1]), "later wave"),
        (lambda: check_dependencies([P((0, 0))], [[]], [0], 0.0), "radius"),
        (lambda: check_dependencies([P((0, 0))], [[]], [0, 1], R), "wave numbers"),
        (lambda: capt_makespan(np.zeros((2, 2)), np.zeros((3, 2))), "must both be"),
        (lambda: optimal_total(np.zeros((0, 2)), np.zeros((0, 2))), "must both be"),
    ],
)
def test_bad_input(call, match: str) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ValueError, match=match):
        call()


def _rows_after(plan: Plan) -> list[list[int]]:
    row = {r.robot_id: k for k, r in enumerate(plan.robots)}
    return [[row[j] for j in r.after] for r in plan.robots]


def _assert_safe(plan: Plan, radius: float) -> None:
    paths = plan.paths()
    waves = plan.wave_of()
    assert check_safety(paths, waves, radius) == []
    assert check_dependencies(paths, _rows_after(plan), waves, radius) == []
    assert sorted(i for w in plan.waves for i in w) == sorted(plan.ids)
    for r in plan.robots:
        assert all(plan.robot(j).wave < r.wave for j in r.after)


coords = st.floats(-15.0, 15.0, allow_nan=False, allow_infinity=False)


@settings(max_examples=30, deadline=None)
@given(
    pts=st.lists(st.tuples(coords, coords), min_size=1, max_size=18),
    d_e=st.sampled_from([D_E, 2.0]),  # the NAOs' and the papers' simulations'
    radius=st.sampled_from([0.1, 0.2, 0.4]),
    seed=st.integers(0, 2**16),
)
def test_property_default_plan_always_found_safe_and_canonical(
    pts: list[tuple[float, float]], d_e: float, radius: float, seed: int
) -> None:
    pos = np.array(pts, dtype=np.float64)
    n = pos.shape[0]
    ids = list(range(100, 100 + n))
    params = PlanParams(d_e=d_e, radius=radius)
    plan = plan_from_positions(ids, pos, params)  # never "no safe schedule"
    _assert_safe(plan, radius)
    perm = np.random.default_rng(seed).permutation(n)
    again = plan_from_positions([ids[k] for k in perm], pos[perm], params)
    assert again.digest == plan.digest
