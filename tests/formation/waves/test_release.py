"""Release points (agent/core/formation/waves/release.py): how far a robot must have
walked before a robot waiting for it may start, worked by hand and as properties."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.core.formation.paths.geometry import seg_seg_dist
from agent.core.formation.waves.execution import (
    check_dependencies,
    dependency_makespan,
    path_lengths,
)
from agent.core.formation.waves.packing import pack
from agent.core.formation.waves.release import NONE, last_within, tail
from agent.core.formation.waves.safety import pair_flags

R = 0.2
C = 2 * R


def P(*pts: tuple[float, float]) -> np.ndarray:
    return np.array(pts, dtype=np.float64)


def _dist(p: np.ndarray, q: np.ndarray) -> float:
    p = p if p.shape[0] > 1 else np.vstack([p, p])
    q = q if q.shape[0] > 1 else np.vstack([q, q])
    return float(np.min(seg_seg_dist(p[:-1, None], p[1:, None], q[None, :-1], q[None, 1:])))


def test_last_point_of_a_segment_within_a_capsule_worked_by_hand() -> None:
    a, b = np.array([[0.0, 0.0]]), np.array([[4.0, 0.0]])
    r = np.array([1.0])
    # along the band: y = 0.5 leaves the capsule at x = 4 + sqrt(1 - 0.25)
    u = last_within(np.array([[0.0, 0.5]]), np.array([[10.0, 0.5]]), a, b, r)
    assert u[0] == pytest.approx((4 + math.sqrt(0.75)) / 10)
    # across it: x = 2 from y = -3 to y = 3 leaves at y = 1, u = 4/6
    u = last_within(np.array([[2.0, -3.0]]), np.array([[2.0, 3.0]]), a, b, r)
    assert u[0] == pytest.approx(4 / 6)
    # never within, or within to its end, or a standing point
    far = last_within(np.array([[0.0, 2.0]]), np.array([[4.0, 2.0]]), a, b, r)
    assert far[0] == NONE
    inside = last_within(np.array([[1.0, 0.2]]), np.array([[3.0, -0.2]]), a, b, r)
    assert inside[0] == 1.0
    point = last_within(np.array([[9.0, 0.0]]), np.array([[9.0, 0.0]]), a, b, r)
    assert point[0] == NONE
    # a point segment as the capsule (a robot already on its slot): a disc
    u = last_within(np.array([[-3.0, 0.0]]), np.array([[3.0, 0.0]]), a, a, r)
    assert u[0] == pytest.approx(4 / 6)


def test_tail_cuts_a_polyline_at_an_arc_length() -> None:
    p = P((0, 0), (3, 0), (3, 4))
    assert tail(p, 0.0).tolist() == p.tolist()
    assert tail(p, 1.0).tolist() == [[1, 0], [3, 0], [3, 4]]
    assert tail(p, 5.0).tolist() == [[3, 2], [3, 4]]
    assert tail(p, 7.0).tolist() == [[3, 4]]
    assert tail(p, 99.0).tolist() == [[3, 4]]


def test_flags_carry_both_release_points() -> None:
    # 1 crosses 0 at (5, 0): 0 is clear of 1's path from x = 5.4 (its arc 5.4), 1 from
    # y = 0.4 (its arc 3.4)
    f = pair_flags([P((0, 0), (10, 0)), P((5, -3), (5, 3))], C)
    assert f.a.tolist() == [0] and f.b.tolist() == [1]
    assert f.rel_ab[0] == pytest.approx(5.4) and f.rel_ba[0] == pytest.approx(3.4)


paths_st = st.lists(
    st.tuples(st.floats(0, 6), st.floats(0, 6), st.floats(0, 6), st.floats(0, 6), st.booleans()),
    min_size=2,
    max_size=7,
)


@settings(max_examples=60, deadline=None)
@given(raw=paths_st)
def test_property_release_points_are_the_earliest_safe_ones(
    raw: list[tuple[float, float, float, float, bool]],
) -> None:
    paths = []
    for x0, y0, x1, y1, bent in raw:
        mid = ((x0 + x1) / 2 + 0.7, (y0 + y1) / 2 - 0.5)
        paths.append(P((x0, y0), mid, (x1, y1)) if bent else P((x0, y0), (x1, y1)))
    f = pair_flags(paths, C)
    lens = path_lengths(paths)
    for k in range(f.a.size):
        if f.same_ok[k]:
            continue
        a, b, req = int(f.a[k]), int(f.b[k]), float(f.required[k])
        for first, second, ok, rel in ((a, b, f.ab_ok, f.rel_ab), (b, a, f.ba_ok, f.rel_ba)):
            if not ok[k]:
                continue
            s = float(rel[k])
            assert 0 < s <= lens[first] + 1e-12
            # from there on the first robot's path clears the second's whole path (up to
            # rounding: hypothesis found paths 1e-12 m long, where req was 6e-13) ...
            assert _dist(tail(paths[first], s), paths[second]) >= req - 1e-9
            # ... and a centimetre earlier it does not (the earliest, up to the slack)
            if s > 0.01:
                assert _dist(tail(paths[first], s - 0.01), paths[second]) < C
    try:
        start, after, waves, at = pack(f, lens, 0, np.arange(len(paths)))
    except ValueError:
        return  # a pair with no order or a cycle: the scheduler's job first
    rows, rel_rows = [list(x) for x in after], [list(x) for x in at]
    assert check_dependencies(paths, rows, waves, R, after_at=rel_rows) == []
    assert check_dependencies(paths, rows, waves, R) == []  # waiting until they hold
    ms = dependency_makespan(lens, after, waves, at)
    assert ms == pytest.approx(float(np.max(start + lens)))
    assert ms <= dependency_makespan(lens, after, waves) + 1e-9


@pytest.mark.parametrize(
    ("bad", "match"),
    [
        ([[], [0.0]], r"arc length 0\.0, not in \(0, 10\.0\]"),  # robot 1 waits for 0
        ([[], [11.0]], r"arc length 11\.0, not in"),  # beyond robot 0's 10 m
        ([[], [math.nan]], r"arc length nan"),
        ([[], []], r"robot 1 waits for 1 robots, 0 release points"),
        ([[]], r"2 dependency lists but 1 release lists"),
    ],
)
def test_release_points_are_checked(bad: list[list[float]], match: str) -> None:
    paths = [P((0, 0), (10, 0)), P((5, -3), (5, 3))]
    waves = [0, 1]
    with pytest.raises(ValueError, match=match):
        check_dependencies(paths, [[], [0]], waves, R, after_at=bad)
    with pytest.raises(ValueError, match=match):
        dependency_makespan(path_lengths(paths), [[], [0]], waves, bad)
