"""The banded plan (the plan that always exists): safe by construction, any fleet."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.formation.params import D_E, PHI_E_DEG, PlanParams
from agent.core.formation.paths.fallback import banded_plan
from agent.core.formation.plan import plan_from_positions
from agent.core.formation.shape.pyramid import pyramid_frame
from agent.core.formation.waves.execution import check_dependencies
from agent.core.formation.waves.safety import check_safety

R = 0.2
PHI_E = math.radians(PHI_E_DEG)


def _paths(starts: np.ndarray, vias: tuple[tuple[np.ndarray, ...], ...], targets: np.ndarray):  # type: ignore[no-untyped-def]
    return [np.vstack([starts[k], *vias[k], targets[k]]) for k in range(starts.shape[0])]


def _check(pos: np.ndarray, d_e: float = D_E, radius: float = R) -> None:
    frame = pyramid_frame(pos)
    bp = banded_plan(pos, frame, d_e, math.radians(30), radius)
    n = pos.shape[0]
    assert sorted(bp.order.tolist()) == list(range(n))
    paths = _paths(pos, bp.vias, bp.targets)
    assert check_safety(paths, bp.waves, radius) == []
    assert check_dependencies(paths, [list(a) for a in bp.after], bp.waves, radius) == []
    for k in range(n):  # a robot waits only for robots of earlier waves
        assert all(bp.waves[j] < bp.waves[k] for j in bp.after[k])


def test_dense_blob_and_duplicates_are_safe() -> None:
    rng = np.random.default_rng(3)
    _check(rng.uniform(0, 1.0, (40, 2)))  # far closer than the clearance
    _check(np.array([[0.0, 0.0], [0.0, 0.0], [0.1, 0.0], [0.0, 0.1]]))  # duplicates
    _check(np.zeros((1, 2)))
    _check(np.c_[np.arange(12.0), np.zeros(12)])  # a line across the axis


def test_legs_rise_to_the_corridor_and_to_the_slot() -> None:
    rng = np.random.default_rng(4)
    pos = rng.uniform(0, 6.0, (15, 2))
    frame = pyramid_frame(pos)
    bp = banded_plan(pos, frame, D_E, PHI_E, R)
    axis = np.array([math.cos(frame.beta), math.sin(frame.beta)])
    for k in range(15):
        pts = np.vstack([pos[k], *bp.vias[k], bp.targets[k]])
        legs = np.diff(pts, axis=0)
        first, last = legs[0], legs[-1]
        for leg in (first, last):
            assert leg[0] * axis[1] - leg[1] * axis[0] == pytest.approx(0.0, abs=1e-9)
            assert leg @ axis > 0


@pytest.mark.parametrize(
    ("starts", "radius", "match"),
    [
        (np.zeros((0, 2)), R, "non-empty"),
        (np.zeros((3, 3)), R, "non-empty"),
        (np.array([[0.0, math.nan]]), R, "non-finite"),
        (np.zeros((2, 2)), 0.0, "radius"),
    ],
)
def test_bad_input(starts: np.ndarray, radius: float, match: str) -> None:
    frame = pyramid_frame(np.zeros((1, 2)))
    with pytest.raises(ValueError, match=match):
        banded_plan(starts, frame, D_E, PHI_E, radius)


def test_banded_strategy_rejects_obstacles() -> None:
    with pytest.raises(ValueError, match="obstacles"):
        plan_from_positions(
            [1, 2],
            np.array([[0.0, 0.0], [2.0, 0.0]]),
            PlanParams(strategy="banded"),
            obstacles=np.array([[5.0, 5.0]]),
        )


coords = st.floats(-20.0, 20.0, allow_nan=False, allow_infinity=False)


@settings(max_examples=40, deadline=None)
@given(
    pts=st.lists(st.tuples(coords, coords), min_size=1, max_size=30),
    d_e=st.floats(0.2, 3.0),
    radius=st.floats(0.05, 0.6),
)
def test_property_banded_plan_is_always_safe(
    pts: list[tuple[float, float]], d_e: float, radius: float
) -> None:
    _check(np.array(pts, dtype=np.float64), d_e, radius)


def test_plan_falls_back_to_the_banded_plan_when_scheduling_fails(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import agent.core.formation.waves.scheduled as scheduled_mod

    def fail(*args: object, **kwargs: object) -> None:
        raise ValueError("no safe schedule found after 10 rounds of slot swaps")

    monkeypatch.setattr(scheduled_mod, "schedule_with_repair", fail)
    rng = np.random.default_rng(8)
    pos = rng.uniform(0, 8.0, (25, 2))
    ids = [int(i) for i in rng.permutation(1000)[:25]]
    plan = plan_from_positions(ids, pos, PlanParams(d_e=2.0))
    assert plan.strategy == "banded"
    row = {r.robot_id: k for k, r in enumerate(plan.robots)}
    after = [[row[j] for j in r.after] for r in plan.robots]
    assert check_safety(plan.paths(), plan.wave_of(), R) == []
    assert check_dependencies(plan.paths(), after, plan.wave_of(), R) == []
    perm = rng.permutation(25)
    again = plan_from_positions([ids[k] for k in perm], pos[perm], PlanParams(d_e=2.0))
    assert again.digest == plan.digest


def test_large_banded_plan_is_canonical_and_safe() -> None:
    rng = np.random.default_rng(9)
    n = 1500
    g = np.stack(np.meshgrid(np.arange(39), np.arange(39)), -1).reshape(-1, 2)[:n]
    pos = (g + rng.uniform(-0.15, 0.15, g.shape)) * 1.8
    ids = [int(i) for i in rng.permutation(n)]
    params = PlanParams(d_e=2.0, strategy="banded")
    plan = plan_from_positions(ids, pos, params)
    assert check_safety(plan.paths(), plan.wave_of(), R) == []
    perm = rng.permutation(n)
    assert plan_from_positions([ids[k] for k in perm], pos[perm], params).digest == plan.digest
