"""The safety rule and its checker (speed-independent clearance >= 2·radius)."""

from __future__ import annotations

import numpy as np
import pytest

from agent.core.formation.paths.geometry import point_seg_dist, seg_seg_dist
from agent.core.formation.waves.safety import check_safety, pair_flags

R = 0.2


def P(*pts: tuple[float, float]) -> np.ndarray:
    return np.array(pts, dtype=np.float64)


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


def test_checker_errors() -> None:
    with pytest.raises(ValueError, match="radius"):
        check_safety([P((0, 0), (1, 0))], [0], 0.0)
    with pytest.raises(ValueError, match="wave numbers"):
        check_safety([P((0, 0), (1, 0))], [0, 1], R)
    assert check_safety([], [], R) == []


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
