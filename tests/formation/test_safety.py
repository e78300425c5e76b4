"""Waves and the safety checker (speed-independent clearance >= 2·radius)."""

from __future__ import annotations

import numpy as np
import pytest

from agent.core.formation.safety import (
    candidate_segment_pairs,
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


def test_candidate_segment_pairs_is_exact_against_brute_force() -> None:
    # every segment pair of different owners within c is found, and no other: random,
    # point, vertical, horizontal and long segments, owners in any order
    rng = np.random.default_rng(1)
    for trial in range(120):
        m = int(rng.integers(1, 30))
        a = rng.uniform(-5, 5, (m, 2))
        b = a + rng.normal(0, float(rng.choice([0.01, 1.0, 4.0])), (m, 2))
        z = rng.random(m) < 0.2
        b[z] = a[z]
        v = rng.random(m) < 0.1
        b[v, 0] = a[v, 0]
        hz = rng.random(m) < 0.1
        b[hz, 1] = a[hz, 1]
        owner = rng.integers(0, m, m)
        c = float(rng.choice([0.1, 0.4, 2.0]))
        s, t = candidate_segment_pairs(a, b, owner, c)
        got = set(zip(s.tolist(), t.tolist(), strict=True))
        want = {
            (i, j)
            for i in range(m)
            for j in range(m)
            if owner[i] < owner[j] and seg_seg_dist(a[i], b[i], a[j], b[j]) <= c
        }
        assert got == want, trial


def _brute_violations(paths: list[np.ndarray], waves: list[int], r: float) -> set[tuple[int, int]]:
    c = 2 * r
    bad = set()
    for i in range(len(paths)):
        for k in range(i + 1, len(paths)):
            pi, pk = paths[i], paths[k]
            req = min(c, float(np.hypot(*(pi[0] - pk[0]))), float(np.hypot(*(pi[-1] - pk[-1]))))
            req *= 1 - 1e-9

            def path_d(p: np.ndarray, q: np.ndarray) -> float:
                return min(
                    float(seg_seg_dist(p[u], p[u + 1], q[w], q[w + 1]))
                    for u in range(len(p) - 1)
                    for w in range(len(q) - 1)
                )

            def pt_d(p: np.ndarray, x: np.ndarray) -> float:
                return min(float(point_seg_dist(x, p[u], p[u + 1])) for u in range(len(p) - 1))

            if waves[i] == waves[k]:
                d = path_d(pi, pk)
            elif waves[i] < waves[k]:  # i walks while k stands at its start, then k walks
                d = min(pt_d(pi, pk[0]), pt_d(pk, pi[-1]))
            else:
                d = min(pt_d(pk, pi[0]), pt_d(pi, pk[-1]))
            if d < req:
                bad.add((i, k))
    return bad


def test_checker_agrees_with_brute_force_on_random_plans() -> None:
    rng = np.random.default_rng(7)
    for _ in range(60):
        n = int(rng.integers(2, 12))
        paths = []
        for _ in range(n):
            k = int(rng.integers(1, 4))
            pts = rng.uniform(0, 3, (k, 2))
            paths.append(np.vstack([pts, pts[-1:]]) if k == 1 else pts)
        waves = [int(w) for w in rng.integers(0, 3, n)]
        got = {(v.robot_a, v.robot_b) for v in check_safety(paths, waves, R)}
        assert got == _brute_violations(paths, waves, R)


def test_collinear_disjoint_segments_are_not_a_crossing() -> None:
    # two legs on one slanted line (rounding makes the orientations tiny, of any sign)
    u = np.array([np.cos(0.7), np.sin(0.7)])
    for k in range(50):
        a0, a1 = 0.1 * k * u, (0.1 * k + 1.0) * u
        b0, b1 = (0.1 * k + 3.0) * u, (0.1 * k + 5.0) * u
        assert seg_seg_dist(a0, a1, b0, b1) == pytest.approx(2.0)
