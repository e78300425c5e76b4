"""Wave packing, critical-chain detours and the bottleneck assignments."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from agent.core.formation.paths.assignment import (
    assign,
    bottleneck_assignment,
    bounded_assignment,
    min_bottleneck,
)
from agent.core.formation.waves.detours import shorten
from agent.core.formation.waves.execution import (
    check_dependencies,
    dependency_makespan,
    path_lengths,
)
from agent.core.formation.waves.packing import pack
from agent.core.formation.waves.safety import PairFlags, check_safety, pair_flags

R = 0.2


def P(*pts: tuple[float, float]) -> np.ndarray:
    return np.array(pts, dtype=np.float64)


def _pack(paths: list[np.ndarray], leader: int = 0):  # type: ignore[no-untyped-def]
    f = pair_flags(paths, 2 * R)
    lens = path_lengths(paths)
    return f, lens, pack(f, lens, leader, np.arange(len(paths)))


def _deps_ok(paths, after, at, waves) -> bool:  # type: ignore[no-untyped-def]
    rows = [list(a) for a in after]
    rel = [list(x) for x in at]
    return check_dependencies(paths, rows, waves, R, after_at=rel) == []


def test_either_order_pair_waits_for_the_release_point_and_far_robots_start_at_once() -> None:
    # 0 and 1 cross at (2, 2) (either order is fine: the ends are far from the other
    # path); 2 is far. Robot 0's point at arc s is s/sqrt(2) (1, 1), |s - 2 sqrt(2)| from
    # robot 1's line x + y = 4: 1 may start once 0 is past 2 sqrt(2) + 2r
    paths = [P((0, 0), (4, 4)), P((0, 4), (4, 0)), P((50, 0), (51, 0))]
    _, _, (start, after, waves, at) = _pack(paths)
    release = 2 * math.sqrt(2) + 2 * R
    assert start[0] == 0.0 and start[2] == 0.0  # the leader first, the far robot at once
    assert start[1] == pytest.approx(release)
    assert after == ((), (0,), ()) and waves.tolist() == [0, 1, 0]
    assert at[1] == (pytest.approx(release),) and at[0] == () and at[2] == ()
    assert check_safety(paths, waves, R) == []
    assert _deps_ok(paths, after, at, waves)
    # one metre less and the rest of 0's path still comes within 2r of 1's
    early = [[], [release - 1.0], []]
    bad = check_dependencies(paths, [list(a) for a in after], waves, R, after_at=early)
    assert [v.kind for v in bad] == ["released-early"]


def test_precedence_pair_keeps_its_order_and_longest_goes_first() -> None:
    # robot 1 stands 0.1 m beside robot 0's path: it must leave first; 0 starts once 1
    # is 0.3 m up its path (0.1 + 0.3 = 2r from 0's path)
    paths = [P((0, 0), (4, 0)), P((2, 0.1), (2, 3)), P((20, 0), (30, 0)), P((20, 1), (21, 1))]
    _, _, (start, after, waves, at) = _pack(paths, leader=2)
    assert after[0] == (1,) and start[0] == pytest.approx(0.3) and at[0] == (pytest.approx(0.3),)
    # 2 and 3 run side by side 1 m apart: both may walk at once
    assert start[2] == 0.0 and start[3] == 0.0
    assert _deps_ok(paths, after, at, waves)
    # the rule before release points (wait until 1 holds) is safe too
    assert check_dependencies(paths, [list(a) for a in after], waves, R) == []


def test_a_short_walk_slips_into_a_gap() -> None:
    # 1 crosses 0 and 2 (either order); 0 (the leader) goes first, 1 once 0 is 5.4 m
    # along (0.4 past x = 5); 2, placed last, goes before 1: 1 waits until 2 is 1.4 m
    # along (0.4 past x = 5), which 2 is at 1.4 < 5.4. Worked by hand: makespan 5.4 + 6
    paths = [P((0, 0), (10, 0)), P((5, -3), (5, 3)), P((4, 2), (6, 2))]
    _, lens, (start, after, waves, at) = _pack(paths)
    assert start.tolist() == pytest.approx([0.0, 5.4, 0.0])
    assert after == ((), (0, 2), ()) and at[1] == pytest.approx((5.4, 1.4))
    assert dependency_makespan(lens, after, waves, at) == pytest.approx(11.4)
    assert dependency_makespan(lens, after, waves) == pytest.approx(16.0)  # hold rule
    assert _deps_ok(paths, after, at, waves)


def test_pack_rejects_bad_input() -> None:
    paths = [P((0, 0), (4, 0)), P((2, 0.1), (2, -3))]
    f = pair_flags(paths, 2 * R)
    lens = path_lengths(paths)
    with pytest.raises(ValueError, match="priorities"):
        pack(f, lens, 0, np.arange(3))
    with pytest.raises(ValueError, match="leader"):
        pack(f, lens, 5, np.arange(2))
    neither = PairFlags(
        f.a, f.b, np.zeros(1, bool), np.zeros(1, bool), np.zeros(1, bool), *(f.d_path,) * 6
    )
    with pytest.raises(ValueError, match="no order"):
        pack(neither, lens, 0, np.arange(2))
    # a precedence cycle: 0 before 1 and 1 before 0 through a third robot
    a, b = np.array([0, 0, 1]), np.array([1, 2, 2])
    no = np.zeros(3, bool)
    cyc = PairFlags(
        a, b, no, np.array([True, False, True]), np.array([False, True, False]), *(np.ones(3),) * 6
    )
    with pytest.raises(ValueError, match="cycle"):
        pack(cyc, np.ones(3), 0, np.arange(3))


def test_detour_cuts_the_critical_chain() -> None:
    # robot 1 walks along robot 0's path, passing 0.325 m from 0's slot (20, 0): 1 goes
    # first and 0 starts once 1's path is 2r from that slot again (x = 20.26, arc 10.26;
    # makespan 10.26 + 20); a via point keeps 1 clear of 0's path: both start at once
    paths = [P((0, 0), (20, 0)), P((10, 0.45), (30, 0.2)), P((40, 0), (41, 0))]
    starts = np.array([p[0] for p in paths])
    targets = np.array([p[-1] for p in paths])
    f, lens, (start, _, _, _) = _pack(paths)
    before = float(np.max(start + lens))
    assert 30.0 < before < 30.5
    t2, o2, vias, f2 = shorten(starts, targets, [(), (), ()], f, np.arange(3), R, bound=1e9)
    new_paths = [np.vstack([starts[k], *vias[k], t2[k]]) for k in range(3)]
    lens2 = path_lengths(new_paths)
    s2, after2, waves2, at2 = pack(f2, lens2, int(np.flatnonzero(o2 == 0)[0]), o2)
    assert float(np.max(s2 + lens2)) < before - 1.0
    assert sorted(o2.tolist()) == [0, 1, 2]
    assert check_safety(new_paths, waves2, R) == []
    assert _deps_ok(new_paths, after2, at2, waves2)
    # the path budget holds (here: no longer than the straight paths)
    t3, _, vias3, _ = shorten(starts, targets, [(), (), ()], f, np.arange(3), R, bound=lens.sum())
    paths3 = [np.vstack([starts[k], *vias3[k], t3[k]]) for k in range(3)]
    assert path_lengths(paths3).sum() <= lens.sum() + 1e-9


def test_bottleneck_assignment_is_the_min_bottleneck_by_brute_force() -> None:
    rng = np.random.default_rng(5)
    for _ in range(5):
        s, t = rng.uniform(0, 5, (6, 2)), rng.uniform(0, 5, (6, 2))
        best = min(
            max(np.hypot(*(s[i] - t[p[i]])) for i in range(6))
            for p in itertools.permutations(range(6))
        )
        perm = bottleneck_assignment(s, t)
        assert sorted(perm.tolist()) == list(range(6))
        assert float(np.max(np.hypot(*(s - t[perm]).T))) == pytest.approx(best)
        assert min_bottleneck(s, t) == pytest.approx(best)
        # no bound: the min-sum assignment
        opt = assign(s, t, "optimal", 1.0, 0.5)
        loose = bounded_assignment(s, t, 1e9)
        total = float(np.sum(np.hypot(*(s - t[loose]).T)))
        assert total == pytest.approx(float(np.sum(np.hypot(*(s - t[opt]).T))))
        assert assign(s, t, "bottleneck", 1.0, 0.5).tolist() == perm.tolist()


def test_regroup_waves_keeps_the_order_and_never_lengthens() -> None:
    from agent.core.formation.waves.execution import wave_makespan
    from agent.core.formation.waves.packing import regroup_waves

    # 1 waits for 0; 2 (long, free) joins 0's wave... it already is; 3 (short, free)
    # joins the wave of the longest path it can
    lens = np.array([5.0, 4.0, 6.0, 1.0, 2.0])
    after = ((), (0,), (), (), (1,))
    waves = np.array([0, 1, 0, 0, 2])
    new = regroup_waves(lens, after, waves, pinned=0)
    for v, deps in enumerate(after):
        assert all(new[u] < new[v] for u in deps)
    assert wave_makespan(lens, new) <= wave_makespan(lens, waves)
    assert new[0] == 0
    rng = np.random.default_rng(2)
    for _ in range(20):
        n = 12
        lens = rng.uniform(0.5, 5.0, n)
        after = tuple(
            tuple(sorted({int(j) for j in rng.integers(0, i, 2)})) if i else () for i in range(n)
        )
        waves = np.zeros(n, dtype=np.int64)
        for i in range(n):
            waves[i] = max((waves[j] + 1 for j in after[i]), default=0)
        new = regroup_waves(lens, after, waves, pinned=0)
        assert all(new[u] < new[v] for v in range(n) for u in after[v])
        assert wave_makespan(lens, new) <= wave_makespan(lens, waves) + 1e-9
