"""Wave packing: start every robot as soon as its own conflicts are clear (shorter schedules, same
safety rule; the execution rules are those of :mod:`execution`, the release points those of
:mod:`release`).

Input: the pair flags of :mod:`safety` for paths that can be scheduled (no pair that can
go in no order, no precedence cycle). Robots walk at unit speed in this model, so a
robot that starts at t is at arc length s of its path at t + s. Pairs that may not walk
together become:

* *precedence* pairs (only u before v allowed): v starts once u is past the pair's
  release point r(u, v), i.e. at or after start_u + r(u, v);
* *either-order* pairs: u before v (start_v >= start_u + r(u, v)) or v before u
  (start_u >= start_v + r(v, u)), whichever fits.

List scheduling: robots are taken in a topological order of the precedence pairs, ready
robots by priority - the leader first, then the longest path first (a long walk started
late ends late), then pyramid order, then row. Each robot gets the earliest start t >=
the release times of its precedence predecessors at which every either-order
neighbour already placed is on one side of it: t + r(i, j) <= start_j (it slips in
before j) or t >= start_j + r(j, i) (after j); the forbidden windows are visited by
their lower end (ties by row) and t only moves forward, so the result does not depend
on the order of the input. Then every close pair is ordered by its starts: v waits for
u (its ``after`` list, with the release point r(u, v)) when start_v >= start_u +
r(u, v), else u waits for v. Release points of close pairs are > 0, so every ``after``
edge goes from an earlier start to a later one and the graph is acyclic; waves are its
levels (wave = 1 + the largest wave it waits for), so the wave rule (every robot of an
earlier wave holds) stays safe as well. The dependency makespan is the largest
start + length.
"""

from __future__ import annotations

import heapq
import math

import numpy as np

from agent.core.formation.waves.safety import PairFlags


def pack(
    flags: PairFlags,
    lengths: np.ndarray,
    leader: int,
    priority: np.ndarray,
    times_only: bool = False,
) -> tuple[np.ndarray, tuple[tuple[int, ...], ...], np.ndarray, tuple[tuple[float, ...], ...]]:
    """(start time, after lists, waves, release points) per robot row: robot i starts
    once every robot ``after[i][k]`` has walked ``release[i][k]`` of its path. Rows >=
    len(lengths) in ``flags`` (static obstacles) are ignored (the scheduler already kept
    paths clear of them). ``times_only``: the start times alone (the rest empty)."""
    lens = np.asarray(lengths, dtype=np.float64)
    n = lens.size
    if np.asarray(priority).shape != (n,):
        raise ValueError(f"{n} lengths but {np.asarray(priority).size} priorities")
    if not 0 <= leader < n:
        raise ValueError(f"leader row {leader} not in [0, {n})")
    sel = ~flags.same_ok & (flags.b < n)
    a, b = flags.a[sel], flags.b[sel]
    ab, ba = flags.ab_ok[sel], flags.ba_ok[sel]
    r_ab, r_ba = flags.rel_ab[sel].tolist(), flags.rel_ba[sel].tolist()
    if np.any(~ab & ~ba):
        raise ValueError("a pair can go in no order: schedule the paths first (safety)")
    either = ab & ba
    # rel[(u, v)]: u before v, v may start once u has walked this far (release)
    rel: dict[tuple[int, int], float] = {}
    for u, v, x, y in zip(a.tolist(), b.tolist(), r_ab, r_ba, strict=True):
        rel[(u, v)] = x
        rel[(v, u)] = y
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
    placed = 0
    while heap:
        i = heapq.heappop(heap)[3]
        t = max((start[j] + rel[(j, i)] for j in pred[i]), default=0.0)
        # either-order neighbours placed: i goes before j (t + rel(i, j) <= start j) or
        # after it (t >= start j + rel(j, i)); earliest such t, intervals by lower end
        busy = sorted(
            (start[j] - rel[(i, j)], j, rel[(i, j)], rel[(j, i)]) for j in nbr[i] if start[j] >= 0
        )
        moved = True
        while moved:  # one pass, plus one more only if rounding moved t past a gap
            moved = False
            for _, j, r_ij, r_ji in busy:
                if t + r_ij <= start[j] or t >= start[j] + r_ji:
                    continue
                t = start[j] + r_ji
                moved = True
        start[i] = t
        placed += 1
        for j in succ[i]:
            indeg[j] -= 1
            if indeg[j] == 0:
                heapq.heappush(heap, key(j))
    if placed < n:
        raise ValueError("precedence cycle: schedule the paths first (safety)")
    if times_only:
        return np.array(start), (), np.zeros(0, dtype=np.int64), ()
    # order every close pair by its starts: v waits for u when it starts once u is past
    # the pair's release point
    after: list[dict[int, float]] = [{} for _ in range(n)]
    for u, v in zip(src, dst, strict=True):
        after[v][u] = rel[(u, v)]
    for u, v in zip(a[either].tolist(), b[either].tolist(), strict=True):
        if start[u] + rel[(u, v)] <= start[v]:
            after[v][u] = rel[(u, v)]
        elif start[v] + rel[(v, u)] <= start[u]:
            after[u][v] = rel[(v, u)]
        else:  # pragma: no cover - the placement above keeps one of the two
            raise ValueError("internal error: a close pair walks together")
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
        tuple(tuple(x[j] for j in sorted(x)) for x in after),
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
