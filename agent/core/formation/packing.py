"""Wave packing: start every robot as soon as its own conflicts are clear (issue 12; the
execution rules are those of :mod:`execution`).

Input: the pair flags of :mod:`safety` for paths that can be scheduled (no pair that can
go in no order, no precedence cycle). Robots walk at unit speed in this model, so a
robot's walk is an interval ``[start, start + length]``. Pairs that may not walk
together become:

* *precedence* pairs (only one order allowed): the later one starts after the earlier
  one's interval ends;
* *either-order* pairs: their intervals may not overlap, in any order.

List scheduling: robots are taken in a topological order of the precedence pairs, ready
robots by priority - the leader first, then the longest path first (a long walk started
late ends late), then pyramid order, then row. Each robot gets the earliest start
>= the end of its precedence predecessors at which its interval overlaps no interval
of an either-order neighbour already placed; it may slip *before* such a neighbour when
the gap is long enough. Then every close pair is ordered by its intervals: the one that
ends first is the one the other waits for (its ``after`` list). Intervals of a pair
never overlap, so every ``after`` edge goes from an earlier end to a later start and the
graph is acyclic; waves are its levels (wave = 1 + the largest wave it waits for), so
the wave rule stays safe as well. The dependency makespan is at most the largest end.
"""

from __future__ import annotations

import heapq
import math

import numpy as np

from agent.core.formation.safety import PairFlags


def pack(
    flags: PairFlags,
    lengths: np.ndarray,
    leader: int,
    priority: np.ndarray,
    times_only: bool = False,
) -> tuple[np.ndarray, tuple[tuple[int, ...], ...], np.ndarray]:
    """(start time, after lists, waves) per robot row; rows >= len(lengths) in ``flags``
    (static obstacles) are ignored (the scheduler already kept paths clear of them).
    ``times_only``: the start times alone (empty after lists and waves)."""
    lens = np.asarray(lengths, dtype=np.float64)
    n = lens.size
    if np.asarray(priority).shape != (n,):
        raise ValueError(f"{n} lengths but {np.asarray(priority).size} priorities")
    if not 0 <= leader < n:
        raise ValueError(f"leader row {leader} not in [0, {n})")
    sel = ~flags.same_ok & (flags.b < n)
    a, b = flags.a[sel], flags.b[sel]
    ab, ba = flags.ab_ok[sel], flags.ba_ok[sel]
    if np.any(~ab & ~ba):
        raise ValueError("a pair can go in no order: schedule the paths first (safety)")
    either = ab & ba
    src = np.concatenate([a[ab & ~ba], b[ba & ~ab]]).tolist()
    dst = np.concatenate([b[ab & ~ba], a[ba & ~ab]]).tolist()
    succ: list[list[int]] = [[] for _ in range(n)]
    pred: list[list[int]] = [[] for _ in range(n)]
    for u, v in zip(src, dst, strict=True):
        succ[u].append(v)
        pred[v].append(u)
    nbr: list[list[int]] = [[] for _ in range(n)]
    for u, v in zip(a[either].tolist(), b[either].tolist(), strict=True):
        nbr[u].append(v)
        nbr[v].append(u)
    indeg = [len(p) for p in pred]
    lens_l = lens.tolist()
    prio = [int(p) for p in np.asarray(priority).tolist()]

    def key(i: int) -> tuple[int, float, int, int]:
        return (0 if i == leader else 1, -lens_l[i], prio[i], i)

    heap = [key(i) for i in range(n) if indeg[i] == 0]
    heapq.heapify(heap)
    start = [-1.0] * n
    finish = [-1.0] * n
    rank = [0] * n  # placement index: breaks ties of zero-length walks at one instant
    placed = 0
    while heap:
        i = heapq.heappop(heap)[3]
        t = max((finish[j] for j in pred[i]), default=0.0)
        busy = sorted((start[j], finish[j]) for j in nbr[i] if start[j] >= 0)
        li = lens_l[i]
        for s, f in busy:
            if t + li <= s:
                break  # fits in the gap before this interval
            if f > t:
                t = f
        start[i], finish[i] = t, t + li
        rank[i] = placed
        placed += 1
        for j in succ[i]:
            indeg[j] -= 1
            if indeg[j] == 0:
                heapq.heappush(heap, key(j))
    if placed < n:
        raise ValueError("precedence cycle: schedule the paths first (safety)")
    if times_only:
        return np.array(start), (), np.zeros(0, dtype=np.int64)
    # order every close pair by its intervals: the one ending first is waited for
    after: list[set[int]] = [set() for _ in range(n)]
    for u, v in zip(src, dst, strict=True):
        after[v].add(u)
    for u, v in zip(a[either].tolist(), b[either].tolist(), strict=True):
        if finish[u] <= start[v] and (finish[v] > start[u] or rank[u] < rank[v]):
            after[v].add(u)
        else:
            after[u].add(v)
    # levels of the after graph (Kahn), ties by row
    waiting = [len(x) for x in after]
    users: list[list[int]] = [[] for _ in range(n)]
    for v in range(n):
        for u in after[v]:
            users[u].append(v)
    waves = np.zeros(n, dtype=np.int64)
    ready = [i for i in range(n) if waiting[i] == 0]
    while ready:
        nxt = []
        for u in ready:
            for v in users[u]:
                waves[v] = max(waves[v], waves[u] + 1)
                waiting[v] -= 1
                if waiting[v] == 0:
                    nxt.append(v)
        ready = nxt
    if any(waiting):  # pragma: no cover - intervals of a pair never overlap
        raise ValueError("internal error: the after graph has a cycle")
    return (
        np.array(start),
        tuple(tuple(sorted(x)) for x in after),
        waves,
    )


def regroup_waves(
    lengths: np.ndarray,
    after: tuple[tuple[int, ...], ...],
    waves: np.ndarray,
    pinned: int,
    passes: int = 2,
) -> np.ndarray:
    """Wave numbers for the wave rule, keeping every ``after`` edge (the dependency rule is
    unchanged): the wave rule's makespan is the sum over waves of the longest path, so a
    robot is best placed in a wave whose longest path is already >= its own. Robots are
    moved one by one - longest path first, then row - to the wave within their slack
    (after every robot they wait for, before every robot waiting for them) that adds
    the least to that sum (ties: the earliest); ``pinned`` (the leader) stays put.
    Empty waves are then dropped."""
    lens = np.asarray(lengths, dtype=np.float64)
    n = lens.size
    w = np.asarray(waves, dtype=np.int64).copy()
    if n == 0:
        return w
    users: list[list[int]] = [[] for _ in range(n)]
    for v in range(n):
        for u in after[v]:
            users[u].append(v)
    lens_l = lens.tolist()
    seq = sorted(range(n), key=lambda i: (-lens_l[i], i))
    for _ in range(passes):
        top = int(w.max()) + 1
        members: list[list[int]] = [[] for _ in range(top)]
        for i, k in enumerate(w.tolist()):
            members[k].append(i)
        wl = w.tolist()
        for i in seq:
            if i == pinned:
                continue
            lo = max((wl[j] + 1 for j in after[i]), default=0)
            hi = min((wl[j] - 1 for j in users[i]), default=top - 1)
            members[wl[i]].remove(i)
            best_k, best_cost = wl[i], math.inf
            for k in range(lo, hi + 1):
                m = max((lens_l[j] for j in members[k]), default=0.0)
                cost = max(lens_l[i] - m, 0.0)
                if cost < best_cost - 1e-12:
                    best_k, best_cost = k, cost
            members[best_k].append(i)
            wl[i] = best_k
        w = np.array(wl, dtype=np.int64)
    return np.unique(w, return_inverse=True)[1].reshape(-1).astype(np.int64)
