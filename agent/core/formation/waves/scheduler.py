"""The wave scheduler: waves (and via points where needed) that pass the safety rule
(NAO paper 4.2 and 5.2.2 (iii) step 7: "the leader goes to its destination firstly, and then the
followers"; the rule itself, our strengthening of Lemma 1, is :mod:`safety`).

Scheduling (:func:`schedule`): wave 0 = the leader alone. Pairs that may not share a
wave but can go in either order must be in different waves; pairs that can only go in
one order give a precedence edge. Robots are taken in a topological order of the
precedence edges, ready robots by ascending pyramid order (then id); each gets the first
wave >= 1 after all its predecessors that no conflicting robot already holds. Pairs
that can go in no order, precedence cycles, and a leader whose path is blocked are
resolved by a detour: one via point on the side of the blocked path (:mod:`via_points`),
the candidate with the fewest remaining conflicts (then the shortest) wins; this
repeats until nothing is left to resolve. Robots are still taken one by one (a detour
changes the score of the next ones), each scored only against the robots that can
matter (found for the whole round at once). The waves found here certify that a safe
order exists; :mod:`plan` then re-times the robots from the same pair flags
(:mod:`packing`), so each starts as soon as its own conflicts are clear.
"""

from __future__ import annotations

import heapq
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from agent.core.formation.paths.close_pairs import path_segments
from agent.core.formation.waves.safety import PairFlags, pair_flags, update_flags
from agent.core.formation.waves.via_points import detour_candidates, near_sets, score_paths


class ScheduleError(ValueError):
    """No safe schedule; ``pairs`` are robot-row pairs that can go in no order (or, if
    there are none, pairs on precedence cycles) - candidates for a slot swap."""

    def __init__(
        self,
        message: str,
        robots: list[int],
        pairs: list[tuple[int, int]],
        vias: tuple[tuple[np.ndarray, ...], ...] = (),
        state: tuple[list[np.ndarray], PairFlags] | None = None,
    ) -> None:
        super().__init__(message)
        self.robots = robots
        self.pairs = pairs
        self.vias = vias  # the detours found so far, per robot row (may be kept)
        self.state = state  # the paths and their pair flags (see schedule(prior=...))


@dataclass(frozen=True)
class Schedule:
    """A safe schedule: the wave of each robot row and its via points."""

    waves: np.ndarray  # (N,) wave of each robot row
    vias: tuple[tuple[np.ndarray, ...], ...]  # per robot row
    flags: PairFlags | None = None  # pair flags of the final paths (robots, then obstacles)


def _adjacency(u: np.ndarray, v: np.ndarray, n: int) -> list[list[int]]:
    """Adjacency lists of the edges u -> v (in the order of the edge arrays)."""
    order = np.argsort(u, kind="stable")
    vl = v[order].tolist()
    ptr = np.searchsorted(u[order], np.arange(n + 1)).tolist()
    return [vl[ptr[i] : ptr[i + 1]] for i in range(n)]


def _assign_waves(
    n: int, leader: int, priority: np.ndarray, flags: PairFlags
) -> tuple[np.ndarray, list[int]]:
    """Topological wave assignment. Returns (waves, robots left in cycles / blocked).

    The leader goes first (wave 0, alone) unless some robot *must* move before it (its
    slot lies within the clearance of that robot's start): those ancestors of the leader
    in the precedence graph go first, then the leader alone, then everyone else.
    Rows >= n are static obstacles: standing in every wave, never scheduled.
    """
    ns = np.flatnonzero(~flags.same_ok)
    fa, fb, fab, fba = flags.a[ns], flags.b[ns], flags.ab_ok[ns], flags.ba_ok[ns]
    obst = fb >= n  # a robot path too close to an obstacle (a < b always)
    problems: set[int] = set(fa[obst & (fa < n)].tolist())
    fa, fb, fab, fba = fa[~obst], fb[~obst], fab[~obst], fba[~obst]
    both, only_ab, only_ba = fab & fba, fab & ~fba, fba & ~fab
    neither = ~fab & ~fba
    problems.update(fa[neither].tolist())
    problems.update(fb[neither].tolist())
    src = np.concatenate([fa[only_ab], fb[only_ba]])
    dst = np.concatenate([fb[only_ab], fa[only_ba]])
    succ = _adjacency(src, dst, n)
    pred = _adjacency(dst, src, n)
    conflict = _adjacency(
        np.concatenate([fa[both], fb[both]]), np.concatenate([fb[both], fa[both]]), n
    )
    # ancestors of the leader
    anc: set[int] = set()
    stack = list(pred[leader])
    while stack:
        u = stack.pop()
        if u not in anc:
            anc.add(u)
            stack.extend(pred[u])
    waves = [-1] * n
    earliest = [0] * n
    indeg = [len(p) for p in pred]
    prio = [int(p) for p in priority.tolist()]

    def run(members: set[int] | None, floor: int) -> None:
        heap = [
            (prio[i], i)
            for i in range(n)
            if waves[i] < 0 and indeg[i] == 0 and (members is None or i in members)
        ]
        heapq.heapify(heap)
        while heap:
            _, i = heapq.heappop(heap)
            w = max(earliest[i], floor)
            if conflict[i]:
                taken = {waves[j] for j in conflict[i]}
                while w in taken:
                    w += 1
            waves[i] = w
            for j in succ[i]:
                if earliest[j] < w + 1:
                    earliest[j] = w + 1
                indeg[j] -= 1
                if indeg[j] == 0 and (members is None or j in members):
                    heapq.heappush(heap, (prio[j], j))

    if leader in anc:
        problems.add(leader)  # the leader is on a precedence cycle
    else:
        if anc:
            run(anc, 0)
        if all(waves[i] >= 0 for i in anc):
            lw = max((waves[i] for i in anc), default=-1) + 1
            waves[leader] = lw
            for j in succ[leader]:
                earliest[j] = max(earliest[j], lw + 1)
                indeg[j] -= 1
            run(None, lw + 1)
    wv = np.array(waves, dtype=np.int64)
    left = np.flatnonzero(wv < 0)
    if left.size:
        # robots on precedence cycles (strongly connected components of size > 1)
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        graph = coo_matrix((np.ones(src.size), (src, dst)), shape=(n, n))
        _, label = connected_components(graph, directed=True, connection="strong")
        sizes = np.bincount(label)
        problems.update(int(i) for i in left if sizes[label[i]] > 1)
        if leader in left:
            problems.add(leader)
        if not problems:  # pragma: no cover - left nodes always descend from a cycle
            problems.update(int(i) for i in left)
    return wv, sorted(problems)


def schedule(
    starts: np.ndarray,
    targets: np.ndarray,
    leader: int,
    priority: np.ndarray,
    radius: float,
    max_rounds: int = 30,
    fixed_vias: Sequence[tuple[np.ndarray, ...]] | None = None,
    obstacles: np.ndarray | None = None,
    prior: ScheduleError | None = None,
) -> Schedule:
    """Waves (+ via points where needed) that pass :func:`safety.check_safety`.

    ``fixed_vias`` are via points the caller wants (e.g. the obstacle procedure); a robot
    whose path cannot be scheduled may have them replaced by a detour. ``obstacles``
    (M, 2) stand still in every wave and are held to the same clearance. ``prior``, the
    error of a previous call on (mostly) the same paths, only saves time: the pair
    flags of the paths that did not change are taken from it.
    """
    n = starts.shape[0]
    c = 2.0 * radius
    vias: list[tuple[np.ndarray, ...]] = (
        [() for _ in range(n)] if fixed_vias is None else [tuple(v) for v in fixed_vias]
    )
    obs = np.zeros((0, 2)) if obstacles is None else np.asarray(obstacles, dtype=np.float64)
    detoured: set[int] = set()

    def path(i: int) -> np.ndarray:
        if not vias[i]:
            return np.array([starts[i], targets[i]], dtype=np.float64)
        return np.vstack([starts[i], *vias[i], targets[i]])

    paths = [path(i) for i in range(n)] + [np.array([o, o]) for o in obs]
    all_s = np.concatenate([starts, obs]).reshape(-1, 2)
    all_t = np.concatenate([targets, obs]).reshape(-1, 2)
    if prior is not None and prior.state is not None and len(prior.state[0]) == len(paths):
        old_paths, old_flags = prior.state
        changed0 = [
            i
            for i, (p, q) in enumerate(zip(paths, old_paths, strict=True))
            if p.shape != q.shape or not np.array_equal(p, q)
        ]
        flags = (
            update_flags(old_flags, paths, changed0, c, (all_s, all_t)) if changed0 else old_flags
        )
    else:
        flags = pair_flags(paths, c)
    for _ in range(max_rounds):
        waves, problems = _assign_waves(n, leader, priority, flags)
        if not problems:
            return Schedule(waves=waves[:n], vias=tuple(vias), flags=flags)
        # Try a detour for every problem robot (the leader first, then by priority),
        # each scored against the current paths of the robots near it.
        ordered = sorted(problems, key=lambda r: (r != leader, int(priority[r])))
        todo: list[tuple[int, np.ndarray]] = []
        for r in ordered:
            if r in detoured:
                continue
            cands = detour_candidates(starts[r], targets[r], c)
            if cands:
                todo.append((r, np.array([[starts[r], v, targets[r]] for v in cands])))
        if not todo:
            break
        pa, pb, po = path_segments(paths)
        near_of = near_sets([r for r, _ in todo], starts, targets, paths, c, (pa, pb, po))
        ptr = np.searchsorted(po, np.arange(len(paths) + 1))
        changed: list[int] = []
        for (r, stack), near in zip(todo, near_of, strict=True):
            # segments of the near robots (robots that changed this round: their new path)
            fresh = np.isin(near, changed)
            if fresh.any():
                na, nb, no = path_segments([paths[k] for k in near])
                nfirst = np.searchsorted(no, np.arange(near.size + 1))
            else:
                cnt = ptr[near + 1] - ptr[near]
                idx = np.repeat(ptr[near], cnt) + (
                    np.arange(int(cnt.sum())) - np.repeat(np.cumsum(cnt) - cnt, cnt)
                )
                na, nb = pa[idx], pb[idx]
                nfirst = np.r_[0, np.cumsum(cnt)]
            args = (na, nb, nfirst, all_s[near], all_t[near], c)
            base = paths[r]
            if base.shape[0] == 2:  # the straight path as [s, s, t]: the same distances
                both_d, both_c = score_paths(
                    np.concatenate([np.array([[base[0], base[0], base[1]]]), stack]), *args
                )
                base_d, base_c = both_d[:1], both_c[:1]
                deficit, conflicts = both_d[1:], both_c[1:]
            else:
                base_d, base_c = score_paths(base[None], *args)
                deficit, conflicts = score_paths(stack, *args)
            lengths = np.sum(np.hypot(*np.diff(stack, axis=1).transpose(2, 0, 1)), axis=1)
            pick = int(np.lexsort((np.arange(len(stack)), lengths, conflicts, deficit))[0])
            if deficit[pick] < base_d[0] - 1e-12 or (
                deficit[pick] <= base_d[0] + 1e-12 and conflicts[pick] < base_c[0]
            ):
                vias[r] = (stack[pick, 1].copy(),)
                paths[r] = path(r)
                detoured.add(r)
                changed.append(r)
        if not changed:
            break
        flags = update_flags(flags, paths, changed, c, (all_s, all_t))
    blocked = [
        (int(flags.a[k]), int(flags.b[k]))
        for k in np.flatnonzero(~flags.same_ok & ~flags.ab_ok & ~flags.ba_ok)
        if flags.b[k] < n
    ]
    if not blocked:
        # precedence cycles: offer the one-order pairs among the stuck robots for swapping
        stuck = set(problems)
        one_order = ~flags.same_ok & (flags.ab_ok ^ flags.ba_ok)
        blocked = [
            (int(flags.a[k]), int(flags.b[k]))
            for k in np.flatnonzero(one_order)
            if int(flags.a[k]) in stuck and int(flags.b[k]) in stuck
        ]
    raise ScheduleError(
        f"no safe schedule found: robots {problems[:10]} stay blocked after detours",
        problems,
        blocked,
        vias=tuple(vias),
        state=(list(paths), flags),
    )
