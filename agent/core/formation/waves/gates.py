"""Gates: a robot that waits for others walks on, and holds only where its path meets
theirs (docs/formation.md "Holds where the paths meet"; the release points of
:mod:`release` taken stretch by stretch; our addition to NAO paper 5.2.2 (iii) step 7,
"the leader goes to its destination firstly, and then the followers").

The dependency rule of :mod:`execution` starts robot b once every robot a it waits for
is past its release point: the last arc length of a's path within the pair's room of
b's *whole* path. Before b walks the stretch ``[y, y']`` of its own path, it is enough
that every robot a ordered before it is past the last arc length of a's path within
the room of *that stretch*:

    need_a(y, y') = max { s : d(path_a(s), path_b[y, y']) < room_ab }            (G)

(none: a never comes that near the stretch). From then on a stays on ``path_a[need:]``,
which clears the stretch, whatever the two speeds; a's progress only grows, so every
stretch b has entered stays clear of a. b's start is clear of a's whole path (the order's
own condition, :mod:`safety`'s ``ab_ok``), so b may stand there from the first. Over b's
whole path (G) is the release point; over a stretch it is at most that: b walks on as
soon as the release rule would let it start, or sooner, and holds only on the stretch
that comes near a's way.

**Who gates whom.** Every robot b waits, through (G), for every robot it waits for
directly or through others (``after`` lists, transitively) whose path comes within the
pair's room of its own. The planner orders every close pair directly (measured on the
bench's fleets: no close pair is ordered only through others), so this is the ``after``
list in practice and the rule stays safe when it is not.

**What the waiting robot hears.** A walking robot publishes its progress (``walked``,
:func:`release.walked_along`) at most every few seconds, and at once when it passes a
*milestone* of its path: every :data:`MILESTONE` metres, and its release points. b
waits for a's progress to reach :func:`milestone` of the need: the need rounded up to
a's next milestone, never beyond b's release point on a (nor a's whole length: a holds).
So b learns at once that it may go on, and waits at most one milestone's walk longer
than (G) alone.

``room_ab`` is the pair's clearance of :mod:`safety` (``min(c, d(starts), d(targets))``,
without its rounding slack), as for the release points. :func:`gated_makespan` is the
makespan of a plan executed so at unit speed, the walking in steps of ``step`` metres
(the agents' distance-control step): what the bench reports as the plan's makespan.

Pure: polylines and ``after`` lists (rows) in, arc lengths and times out.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from agent.core.formation.waves.release import NONE, last_within, tail

#: Milestones of a walking robot's path (m): it publishes its progress at once when it
#: passes one, and a robot gated on it waits for the next one past the need.
MILESTONE = 0.5
#: The stretch asked for reaches this far past the step (m): a robot a little behind its
#: planned arc, or a step a little long, stays inside the stretch it was granted.
STEP_SLACK = 0.05


def _polyline(path: np.ndarray) -> np.ndarray:
    p = np.asarray(path, dtype=np.float64).reshape(-1, 2)
    if p.shape[0] == 0 or not np.all(np.isfinite(p)):
        raise ValueError(f"a path must have finite points, got {path!r}")
    return np.vstack([p, p]) if p.shape[0] == 1 else p


def path_length(path: np.ndarray) -> float:
    """Length of a polyline (m)."""
    return float(np.sum(np.hypot(*np.diff(_polyline(path), axis=0).T)))


def stretch(path: np.ndarray, y0: float, y1: float) -> np.ndarray:
    """``path[y0:y1]``: the polyline between two arc lengths (clipped to the path)."""
    p = _polyline(path)
    if not (math.isfinite(y0) and math.isfinite(y1)) or y1 < y0:
        raise ValueError(f"a stretch needs finite arcs y0 <= y1, got {y0!r}, {y1!r}")
    rest = tail(p, max(0.0, y0))
    out = tail(rest[::-1], max(0.0, path_length(rest) - (y1 - max(0.0, y0))))[::-1]
    return _polyline(out)


def room(path_a: np.ndarray, path_b: np.ndarray, clearance: float) -> float:
    """The pair's room: the clearance, or less when the two starts or the two targets are
    already nearer (:mod:`safety`)."""
    if not (math.isfinite(clearance) and clearance > 0):
        raise ValueError(f"clearance must be > 0, got {clearance!r}")
    a, b = _polyline(path_a), _polyline(path_b)
    return float(min(clearance, np.hypot(*(a[0] - b[0])), np.hypot(*(a[-1] - b[-1]))))


def need(path_a: np.ndarray, part_b: np.ndarray, room_ab: float) -> float:
    """(G): the last arc length of ``path_a`` within ``room_ab`` of the polyline
    ``part_b`` (a stretch of b's path); ``-inf`` when a never comes that near."""
    a, b = _polyline(path_a), _polyline(part_b)
    sa, ea = a[:-1], a[1:]
    sb, eb = b[:-1], b[1:]
    seg = np.hypot(*(ea - sa).T)
    arc0 = np.cumsum(seg) - seg
    i = np.repeat(np.arange(sa.shape[0]), sb.shape[0])
    k = np.tile(np.arange(sb.shape[0]), sa.shape[0])
    u = last_within(sa[i], ea[i], sb[k], eb[k], np.full(i.size, room_ab))
    arc = np.where(u > NONE, arc0[i] + np.maximum(u, 0.0) * seg[i], NONE)
    return float(arc.max()) if arc.size else -math.inf


def milestone(value: float, cap: float) -> float:
    """``value`` rounded up to the next :data:`MILESTONE`, at most ``cap`` (``-inf``
    stays ``-inf``: nothing to wait for)."""
    if value == -math.inf:
        return value
    if not (math.isfinite(value) and math.isfinite(cap)):
        raise ValueError(f"need finite arcs, got {value!r} and {cap!r}")
    return min(cap, math.ceil(value / MILESTONE - 1e-9) * MILESTONE)


def milestones(length: float, releases: Sequence[float] = ()) -> list[float]:
    """The arcs at which a robot of path ``length`` publishes its progress at once: every
    :data:`MILESTONE` before its end, and its ``releases`` (ascending, unique)."""
    if not (math.isfinite(length) and length >= 0):
        raise ValueError(f"length must be finite and >= 0, got {length!r}")
    grid = [k * MILESTONE for k in range(1, math.floor(length / MILESTONE - 1e-9) + 1)]
    return sorted({*grid, *(float(x) for x in releases if 0.0 < x <= length)})


def predecessors(after: Sequence[Sequence[int]], b: int) -> list[int]:
    """The rows robot ``b`` waits for, directly or through others (ascending)."""
    seen: set[int] = set()
    stack = [int(j) for j in after[b]]
    while stack:
        j = stack.pop()
        if j in seen or j == b:
            continue
        seen.add(j)
        stack.extend(int(x) for x in after[j])
    return sorted(seen)


class Gates:
    """Robot b's gates in a plan (module docstring): the robots it waits for whose paths
    come within the pair's room of its own, and what each must have walked before b
    walks a stretch."""

    def __init__(
        self,
        paths: Sequence[np.ndarray],
        after: Sequence[Sequence[int]],
        b: int,
        clearance: float,
        after_at: Sequence[Sequence[float]] | None = None,
    ) -> None:
        if not 0 <= b < len(paths) or len(after) != len(paths):
            raise ValueError(f"robot row {b} of {len(paths)} paths, {len(after)} after lists")
        self.path = _polyline(paths[b])
        self.length = path_length(self.path)
        direct = {int(j): float(x) for j, x in zip(after[b], (after_at or [()] * len(paths))[b])}
        #: (row a, a's path, the pair's room, the cap of a need: b's release point on a,
        #: else a's whole length), for each a whose path comes within the room of b's
        self.on: list[tuple[int, np.ndarray, float, float]] = []
        #: the robots b waits for directly whose paths never come near its own: the
        #: plan's word stands (b starts once each is past its release point), so a gate
        #: is never more lenient than the plan's start
        self.at_start: list[tuple[int, float]] = []
        for a in predecessors(after, b):
            pa = _polyline(paths[a])
            r = room(pa, self.path, clearance)
            cap = direct[a] if a in direct else path_length(pa)
            if need(pa, self.path, r) > -math.inf:
                self.on.append((a, pa, r, cap))
            elif a in direct:
                self.at_start.append((a, cap))

    def needs(self, y0: float, y1: float) -> list[tuple[int, float]]:
        """(row a, the milestone of a's path a must have passed) before b walks its
        stretch ``[y0, y1]``, for each a that comes near it, and each a the plan names
        that never does (its release point; ascending rows)."""
        y0 = min(y0, self.length)
        part = stretch(self.path, y0, min(max(y0, y1), self.length))
        out = list(self.at_start)
        for a, pa, r, cap in self.on:
            n = need(pa, part, r)
            if n != -math.inf:
                out.append((a, milestone(n, cap)))
        return sorted(out)


def _reach(times: np.ndarray, arcs: np.ndarray, s: float) -> float:
    """When a robot whose arrival times at ``arcs`` are ``times`` has walked past arc
    ``s`` (it then holds at its end)."""
    k = int(np.searchsorted(arcs, s - 1e-12, side="left"))
    return float(times[min(k, arcs.size - 1)])


def gated_makespan(
    paths: Sequence[np.ndarray],
    after: Sequence[Sequence[int]],
    waves: Sequence[int] | np.ndarray,
    clearance: float,
    step: float,
    after_at: Sequence[Sequence[float]] | None = None,
) -> float:
    """The time the last robot holds its slot when every robot walks at unit speed in
    steps of ``step`` m and holds before a step until its gates are open (module
    docstring; robots in ascending wave order, those of a wave in row order)."""
    if not (math.isfinite(step) and step > 0):
        raise ValueError(f"step must be > 0, got {step!r}")
    n = len(paths)
    order = np.argsort(np.asarray(waves, dtype=np.int64), kind="stable").tolist()
    arcs: list[np.ndarray] = [np.zeros(0)] * n
    times: list[np.ndarray] = [np.zeros(0)] * n
    for b in order:
        g = Gates(paths, after, b, clearance, after_at)
        ys = np.r_[np.arange(0.0, g.length, step), g.length]
        ts = np.zeros(ys.size)
        t = 0.0
        for k in range(1, ys.size):
            y0, y1 = float(ys[k - 1]), float(ys[k])
            for a, s in g.needs(y0, min(g.length, y1 + STEP_SLACK)):
                if not arcs[a].size:
                    raise ValueError(f"robot row {b} waits for row {a} of the same or a later wave")
                t = max(t, _reach(times[a], arcs[a], s))
            t += y1 - y0
            ts[k] = t
        arcs[b], times[b] = ys, ts
    return float(max((ts[-1] for ts in times if ts.size), default=0.0))
