"""The wave scheduler: waves and detours that pass the safety checker."""

from __future__ import annotations

import numpy as np

from agent.core.formation.waves.safety import check_safety
from agent.core.formation.waves.scheduler import schedule

R = 0.2


def P(*pts: tuple[float, float]) -> np.ndarray:
    return np.array(pts, dtype=np.float64)


def test_schedule_orders_a_queue() -> None:
    # a queue: each robot's path runs through the start of the one in front of it
    starts = P((0, 0), (0, 1), (0, 2))
    targets = P((0, 3), (0, 4), (0, 5))
    sch = schedule(starts, targets, leader=1, priority=np.array([2, 0, 1]), radius=R)
    paths = [np.vstack([s, *v, t]) for s, v, t in zip(starts, sch.vias, targets)]
    assert check_safety(paths, sch.waves, R) == []
    assert sch.waves.tolist() == [2, 1, 0]  # the front robot goes first, leader or not


def test_schedule_adds_a_detour() -> None:
    # the leader's straight path runs through a robot that never moves (already on its slot)
    starts = P((0, 0), (2, 0.05))
    targets = P((4, 0), (2, 0.05))
    sch = schedule(starts, targets, leader=0, priority=np.array([0, 1]), radius=R)
    assert len(sch.vias[0]) == 1
    paths = [np.vstack([s, *v, t]) for s, v, t in zip(starts, sch.vias, targets)]
    assert check_safety(paths, sch.waves, R) == []
