"""The planner's parameters: every invalid setting is refused."""

from __future__ import annotations

import math

import pytest

from agent.core.formation.params import FRONT_MAX_N, OPTIMAL_MAX_N, SCHEDULE_MAX_N, PlanParams
from agent.core.formation.shape.spec import BUILTIN, TREE, Shape


def test_params_errors() -> None:
    for kw, msg in (
        ({"d_e": -1.0}, "d_e"),
        ({"phi_e": 2.0}, "phi_e"),
        ({"radius": 0.0}, "radius"),
        ({"strategy": "x"}, "strategy"),
        ({"orientation": "x"}, "orientation"),
        ({"frame_method": "x"}, "frame_method"),
        ({"epsilon": -1.0}, "epsilon"),
        ({"placement": "x"}, "placement"),
        ({"obstacle_method": "x"}, "obstacle_method"),
    ):
        with pytest.raises(ValueError, match=msg):
            PlanParams(**kw)  # type: ignore[arg-type]


def test_a_shape_must_be_one_whose_slots_two_robots_can_hold() -> None:
    with pytest.raises(ValueError, match="shape must be a Shape"):
        PlanParams(shape="line")  # type: ignore[arg-type]
    tight = Shape("tight", TREE, ((0, 1.0, math.pi / 2), (1, 0.3, math.pi)))
    with pytest.raises(ValueError, match=r"'tight': slots 1 and 2 are 0.300 m apart, closer "):
        PlanParams(shape=tight)
    PlanParams(shape=tight, radius=0.14)  # smaller robots fit
    assert PlanParams(shape=BUILTIN["grid"]).shape.name == "grid"


def test_default_strategy_attempts_by_fleet_size() -> None:
    p = PlanParams()
    assert p.resolved_strategy(OPTIMAL_MAX_N) == "optimal"
    assert p.resolved_strategy(OPTIMAL_MAX_N + 1) == "paper"
    assert p.attempts(10) == [
        ("optimal", "centroid"),
        ("paper", "centroid"),
        ("optimal", "front"),
        ("paper", "front"),
    ]
    assert p.attempts(FRONT_MAX_N + 1) == [("paper", "centroid")]
    assert p.attempts(SCHEDULE_MAX_N + 1) == []  # straight to the banded plan
    assert PlanParams(strategy="banded").attempts(5) == []
    assert PlanParams(strategy="capt", placement="front").attempts(5) == [("capt", "front")]
