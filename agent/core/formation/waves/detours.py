"""Via points instead of waiting: shorten the critical chain of a packed plan (shorter schedules,
same safety rule).

After :mod:`packing`, the makespan is the end of a chain of robots each waiting for the
one before it to pass its release point (a close pair that may not walk together, see
:mod:`safety` and :mod:`release`). A cheap
detour can cut such a link: one via point that keeps one robot of the pair clear of the
other, so that both may walk together. Local search, deterministic:

1. pack; take the critical chain (the robot that ends last, then the robot it waits for
   that passed its release point last, ... ties by row);
2. for each link (v waits for u) and each of the two robots, the detour candidates of
   :func:`via_points.detour_candidates` (one via point beside the straight path) and the
   end candidates below (a step aside at the start, or an approach from the side) that
   keep the pair clear (both paths >= the pair's clearance apart)
   are tried, shortest first, at most ``TRIES`` per robot: the pair flags are updated
   for that robot only and the plan is packed again;
   Each link also tries the 2-opt move of Lemma 1: the two robots swap slots (straight
   paths, both robots' pair flags updated);
3. the candidate with the smallest makespan (then the shorter total, then the order
   tried) is kept if it shortens the makespan by more than 1e-9 and keeps the total
   path within ``bound``; a candidate that leaves a pair with no safe order (or a
   precedence cycle) is discarded. Repeat until no link improves, ``rounds`` is met or
   MAX_EVALS plans were packed.

The search runs twice (:mod:`scheduled`): the *narrow* neighbourhood above, then, from
its result, the *wide* one (to bring the planner's worst makespan to at most 2× CAPT's), which adds
what a chain of long parallel walks needs (a robot passing the start of the one ahead of it, both
long: the worst cases of the line and two-blob fleets): sidesteps at a fixed distance from
either end (``SIDESTEP_ALONG`` × ``SIDESTEP_OFFSETS`` clearances, a lane taken early
whatever the path's length), both robots of a link bent at once (a lane each, the pairs
of candidates >= the pair's clearance apart, shortest first), and slot swaps of each
chain robot with the ``SWAPS`` robots whose slots are nearest its own. The wide search
starts from the narrow one's plan and only accepts improvements, so no plan gets a
longer makespan than the narrow search alone gives. Ties: every list above is in a
fixed order (rows, candidate order), so identical inputs give identical plans.

Safety is never traded: every accepted plan is packed from exact pair flags, so it
keeps the same guarantees as the plan it started from.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import Any

import numpy as np

from agent.core.formation.paths.close_pairs import path_segments, replace_paths
from agent.core.formation.paths.geometry import seg_seg_dist
from agent.core.formation.waves.packing import pack
from agent.core.formation.waves.safety import PairFlags, update_flags
from agent.core.formation.waves.via_points import detour_candidates

#: Detour candidates tried per robot of a link (shortest first).
TRIES = 6

#: Plans packed per :func:`shorten` call at most (each costs a pair-flag update and a
#: packing): bounds the time on long chains (a line of 200 robots: ~6 000 without it).
MAX_EVALS = 2000

#: Slot swaps tried per robot of the critical chain: with the robots whose slots are the
#: nearest to its own (then by row).
SWAPS = 8

#: Combinations of two bent paths measured first (:func:`_pair_detours`, shortest first),
#: then twice as many each time: the search stops at the chunk that completes ``TRIES``
#: clear ones.
PAIR_CHUNK = 32

#: The wide neighbourhood's sidesteps: via points ``along`` clearances from either end
#: of the path and ``off`` clearances beside it (a lane taken at a fixed distance, not a
#: fraction of a long path: 7-56 degrees off the straight line).
SIDESTEP_ALONG = (2.0, 4.0, 8.0)
SIDESTEP_OFFSETS = (1.0, 2.0, 3.0)


#: Extra via points near the ends of the path (fractions of the path, offsets in
#: clearances): a step aside first, or an approach from the side, clears a robot standing
#: next to the start or the target, which the middle detours of :mod:`via_points` miss.
END_FRACTIONS = (0.0, 0.1, 0.9, 1.0)
END_OFFSETS = (1.0, 1.5, 2.0, 3.0)


def _candidates(p: np.ndarray, q: np.ndarray, c: float, wide: bool = False) -> list[np.ndarray]:
    """:func:`via_points.detour_candidates`, then the end candidates (left before right)."""
    out = detour_candidates(p, q, c)
    if not out:
        return out
    d = q - p
    u = d / float(np.hypot(*d))
    nrm = np.array([-u[1], u[0]])
    for frac in END_FRACTIONS:
        for off in END_OFFSETS:
            for sign in (1.0, -1.0):
                out.append(p + frac * d + sign * off * c * nrm)
    if not wide:
        return out
    length = float(np.hypot(*d))
    for along in SIDESTEP_ALONG:
        if along * c >= 0.5 * length:
            break
        for off in SIDESTEP_OFFSETS:
            for sign in (1.0, -1.0):
                out.append(p + along * c * u + sign * off * c * nrm)
                out.append(q - along * c * u + sign * off * c * nrm)
    return out


def _stack(p: np.ndarray, q: np.ndarray, current: np.ndarray, c: float) -> np.ndarray:
    """(K, 3, 2): the current path (as 3 points) and one-via candidates p -> w -> q."""
    cur = current if current.shape[0] == 3 else np.array([current[0], current[0], current[-1]])
    cands = _candidates(p, q, c, wide=True)
    out = np.empty((len(cands) + 1, 3, 2))
    out[0] = cur
    if cands:
        out[1:, 0], out[1:, 1], out[1:, 2] = p, np.array(cands), q
    return out


def _pair_detours(
    starts: np.ndarray,
    targets: np.ndarray,
    paths: Sequence[np.ndarray],
    u: int,
    v: int,
    c: float,
    req: float,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Both robots of a link bent at once (a lane each): the combinations of their current
    path and one-via candidates that keep the two paths >= ``req`` apart, shortest
    summed length first (then listed order), at most ``TRIES``; both paths change (one
    alone is tried by the single detours)."""
    su = _stack(starts[u], targets[u], paths[u], c)
    sv = _stack(starts[v], targets[v], paths[v], c)
    ku, kv = su.shape[0], sv.shape[0]
    lu = np.sum(np.hypot(*np.diff(su, axis=1).transpose(2, 0, 1)), axis=1)
    lv = np.sum(np.hypot(*np.diff(sv, axis=1).transpose(2, 0, 1)), axis=1)
    tot = (lu[:, None] + lv[None, :]).reshape(-1)
    # the combinations without either current path, shortest first (then listed); their
    # distances are measured in that order, in growing chunks, until TRIES are clear
    flat = (np.arange(1, ku)[:, None] * kv + np.arange(1, kv)[None, :]).reshape(-1)
    flat = flat[np.lexsort((flat, tot[flat]))]
    pick: list[int] = []
    lo, size = 0, PAIR_CHUNK
    while lo < flat.size:
        f = flat[lo : lo + size]
        lo, size = lo + size, 2 * size
        a, b = su[f // kv], sv[f % kv]
        d = (
            seg_seg_dist(
                a[:, :-1, None, :], a[:, 1:, None, :], b[:, None, :-1, :], b[:, None, 1:, :]
            )
            .reshape(f.size, -1)
            .min(axis=1)
        )
        pick.extend(f[d >= req].tolist())
        if len(pick) >= TRIES:
            break
    pick = pick[:TRIES]
    return [(su[f // kv], sv[f % kv]) for f in pick]


def _path(start: np.ndarray, via: Sequence[np.ndarray], target: np.ndarray) -> np.ndarray:
    return np.vstack([start, *via, target])


def _length(p: np.ndarray) -> float:
    return float(np.sum(np.hypot(*np.diff(p, axis=0).T)))


def _chain(
    start: np.ndarray,
    finish: np.ndarray,
    after: Sequence[Sequence[int]],
    release: Sequence[Sequence[float]],
) -> list[int]:
    i = int(np.argmax(finish))  # first row among equal ends
    chain = [i]
    while after[i]:
        deps = list(after[i])
        free = start[deps] + np.asarray(release[i])  # when each let i go
        k = int(np.argmax(free))
        j = deps[k]
        if free[k] < start[i] - 1e-9:  # i did not wait for anyone: chain starts here
            break
        chain.append(j)
        i = j
    return chain[::-1]


def shorten(
    starts: np.ndarray,
    targets: np.ndarray,
    vias: Sequence[tuple[np.ndarray, ...]],
    flags: PairFlags,
    order: np.ndarray,
    radius: float,
    bound: float,
    rounds: int = 20,
    wide: bool = False,
) -> tuple[np.ndarray, np.ndarray, tuple[tuple[np.ndarray, ...], ...], PairFlags]:
    """Local search of the module doc. ``order``: the slot order of every robot (the
    leader holds 0; also the packing priority). Returns (targets, order, vias, flags) of
    the best plan found."""
    n = starts.shape[0]
    c = 2.0 * radius
    targets = np.array(targets, dtype=np.float64, copy=True)
    order = np.array(order, dtype=np.int64, copy=True)
    vias_l = [tuple(v) for v in vias]
    paths = [_path(starts[k], vias_l[k], targets[k]) for k in range(n)]
    lengths = np.array([_length(p) for p in paths])

    def leader_of(o: np.ndarray) -> int:
        return int(np.flatnonzero(o == 0)[0])

    st, after, _, rel = pack(flags, lengths, leader_of(order), order)
    best = float(np.max(st + lengths))
    evals = 0
    for _ in range(rounds):
        pair_req = {
            (int(a), int(b)): float(q)
            for a, b, q in zip(flags.a, flags.b, flags.required, strict=True)
        }
        chain = _chain(st, st + lengths, after, rel)
        segments = path_segments(paths)  # a candidate replaces the segments of its rows
        # (makespan, total, tried, changed rows, paths, targets, order, flags, lengths)
        trial: tuple[Any, ...] | None = None
        tried = 0

        def consider(
            rows: list[int],
            new_paths: list[np.ndarray],
            new_t: np.ndarray,
            new_o: np.ndarray,
            lengths: np.ndarray = lengths,
            flags: PairFlags = flags,
            best: float = best,
            segments: tuple[np.ndarray, np.ndarray, np.ndarray] = segments,
        ) -> None:
            nonlocal trial, tried, evals
            if evals >= MAX_EVALS:
                return
            evals += 1
            new_len = lengths.copy()
            for r in rows:
                new_len[r] = _length(new_paths[r])
            if float(new_len.sum()) > bound:
                return
            f2 = update_flags(
                flags, new_paths, rows, c, (starts, new_t), replace_paths(segments, rows, new_paths)
            )
            try:
                s2, _, _, _ = pack(f2, new_len, leader_of(new_o), new_o, times_only=True)
            except ValueError:
                return
            ms = float(np.max(s2 + new_len))
            key = (ms, float(new_len.sum()), tried)
            if ms < best - 1e-9 and (trial is None or key < trial[:3]):
                trial = (*key, rows, new_paths, new_t, new_o, f2, new_len)
            tried += 1

        def swap(
            u: int,
            v: int,
            targets: np.ndarray = targets,
            order: np.ndarray = order,
            paths: list[np.ndarray] = paths,
        ) -> None:
            # 2-opt: the two robots swap slots (straight paths)
            new_t = targets.copy()
            new_t[[u, v]] = new_t[[v, u]]
            new_o = order.copy()
            new_o[[u, v]] = new_o[[v, u]]
            swapped = list(paths)
            swapped[u] = _path(starts[u], (), new_t[u])
            swapped[v] = _path(starts[v], (), new_t[v])
            consider([u, v], swapped, new_t, new_o)

        swapped_pairs: set[tuple[int, int]] = set()
        for r in chain if wide else []:
            dist = np.hypot(*(targets - targets[r]).T)
            near = np.lexsort((np.arange(n), dist))[1 : SWAPS + 1]
            for o in near.tolist():
                if o == r:
                    continue
                key2 = (min(r, o), max(r, o))
                if key2 not in swapped_pairs:
                    swapped_pairs.add(key2)
                    swap(r, o)
        seen: set[tuple[int, int]] = set()
        for u, v in itertools.pairwise(chain):
            key2 = (min(u, v), max(u, v))
            if key2 not in swapped_pairs:
                swapped_pairs.add(key2)
                swap(u, v)
            req = pair_req.get((min(u, v), max(u, v)), c)
            for r, other in ((v, u), (u, v)):
                if (r, other) in seen:
                    continue
                seen.add((r, other))
                cands = _candidates(starts[r], targets[r], c, wide)
                if not cands:
                    continue
                k_c = len(cands)
                stack = np.empty((k_c, 3, 2))
                stack[:, 0], stack[:, 1], stack[:, 2] = starts[r], np.array(cands), targets[r]
                lens_c = np.sum(np.hypot(*np.diff(stack, axis=1).transpose(2, 0, 1)), axis=1)
                q = paths[other]
                d = seg_seg_dist(
                    stack[:, :-1, None, :],
                    stack[:, 1:, None, :],
                    q[None, None, :-1],
                    q[None, None, 1:],
                ).reshape(k_c, -1)
                ok = np.flatnonzero(d.min(axis=1) >= req)
                ok = ok[np.lexsort((ok, lens_c[ok]))][:TRIES]  # shortest first, then listed
                for j in ok.tolist():
                    new_paths = list(paths)
                    new_paths[r] = stack[j]
                    consider([r], new_paths, targets, order)
            for pu, pv in _pair_detours(starts, targets, paths, u, v, c, req) if wide else []:
                new_paths = list(paths)
                new_paths[u], new_paths[v] = pu, pv
                consider([u, v], new_paths, targets, order)
        if trial is None:
            break
        best = trial[0]
        rows, paths, targets, order, flags, lengths = trial[3:]
        for r in rows:
            vias_l[r] = tuple(p.copy() for p in paths[r][1:-1])
        st, after, _, rel = pack(flags, lengths, leader_of(order), order)
    return targets, order, tuple(vias_l), flags
