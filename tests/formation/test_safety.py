"""Waves and the safety checker (speed-independent clearance >= 2·radius)."""

from __future__ import annotations

import numpy as np
import pytest

from agent.formation.safety import (
    check_safety,
    pair_flags,
    point_seg_dist,
    schedule,
    seg_seg_dist,
)

R = 0.2


def P(*pts: tuple[float, float]) -> np.ndarray:
    return np.array(pts, dtype=np.float64)


def test_geometry_known_answers() -> None:
    assert point_seg_dist(P((0, 1)), P((-1, 0)), P((1, 0)))[0] == pytest.approx(1.0)
    assert point_seg_dist(P((3, 4)), P((0, 0)), P((0, 0)))[0] == pytest.approx(5.0)
    assert seg_seg_dist(P((0, 0)), P((2, 2)), P((0, 2)), P((2, 0)))[0] == 0.0  # crossing
    assert seg_seg_dist(P((0, 0)), P((1, 0)), P((0, 0.3)), P((1, 0.3)))[0] == pytest.approx(0.3)


def test_rejects_non_crossing_paths_too_close_in_same_wave() -> None:
    # non-crossing straight paths that start and end far apart but pass 0.3 m apart
    paths = [P((0, 0), (4, 0)), P((1, 1), (3, 0.3))]
    v = check_safety(paths, [1, 1], R)
    assert len(v) == 1 and v[0].kind == "paths" and v[0].distance == pytest.approx(0.3)
    assert check_safety(paths, [1, 2], R) == []  # robot 0 first: fine
    v = check_safety(paths, [2, 1], R)  # robot 1 first: robot 0 then passes it
    assert len(v) == 1 and v[0].kind == "path-vs-standing"
    assert check_safety([P((0, 0), (3, 0)), P((0, 1), (3, 1))], [1, 1], R) == []


def test_rejects_path_past_standing_robot() -> None:
    # robot 0 walks past robot 1's start (0.1 m off its path) while 1 waits for a later wave
    paths = [P((0, 0), (4, 0)), P((2, 0.1), (2, 3))]
    v = check_safety(paths, [0, 1], R)
    assert v and v[0].kind == "path-vs-standing"
    # if robot 1 leaves first, robot 0 may go afterwards
    assert check_safety(paths, [1, 0], R) == []


def test_rejects_path_past_finished_robot() -> None:
    # robot 1 arrives at (2, 0.1) first, then robot 0's path passes it
    paths = [P((0, 0), (4, 0)), P((2, 3), (2, 0.1))]
    assert check_safety(paths, [1, 0], R)
    assert check_safety(paths, [0, 1], R) == []


def test_pair_flags_relax_for_starts_already_close() -> None:
    f = pair_flags([P((0, 0), (0, -2)), P((0.3, 0), (0.3, 2))], 2 * R)
    assert f.required[0] == pytest.approx(0.3, rel=1e-6)
    assert f.same_ok[0]


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


def test_checker_errors() -> None:
    with pytest.raises(ValueError, match="radius"):
        check_safety([P((0, 0), (1, 0))], [0], 0.0)
    with pytest.raises(ValueError, match="wave numbers"):
        check_safety([P((0, 0), (1, 0))], [0, 1], R)
    assert check_safety([], [], R) == []
