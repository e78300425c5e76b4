"""Re-search (NAO paper 4.1.3 rule 2): who searches again, and the exploration move first.

4.1.3: "(1) If each NAO finds at least one neighbor, the fixed-n with maximum neighbors
is chosen as the common frame; otherwise, the NAOs run the second step. (2) If at least
one NAO has no neighbor, these NAOs will restart searching neighbors again, and repeat
the first step." The common frame also needs the identified-neighbour graph to be
connected (eq. 10 translates positions along its edges), so we apply rule 2 to every
robot the frame cannot reach, not only to robots with no neighbour at all.

**The decision** (:func:`decide_research`, pure, from the agreed records alone, so every
agent reaches the same one from the same records in any order):

1. identified neighbour pairs (eq. 9, :func:`~agent.core.formation.frame.neighbour_check.
   identify_neighbours`, the same ε as the plan) on the canonical records;
2. the connected components of that graph, each sorted by id;
3. one component: nobody searches again (``connected``). Otherwise the *kept* component
   is the largest one, ties to the one holding the lowest id; every robot outside it
   must search again. A robot with no identified neighbour is a component of one, so it
   always searches again (rule 2) unless every robot is alone, when the lowest id keeps
   its place as the anchor (and the others walk towards their one-sided sightings);
4. no record holds a sighting at all (``blind``): nobody walks, and the fleet stops. The
   exploration is there to join a group, and there is none; either the robots stand out
   of each other's sight, which a person must fix, or the camera does not recognise
   these robots (a calibration made for other caps or light), and then a robot that walks
   cannot see the robots in its way either (docs/design.md §1, Plan).

**The exploration move** (deterministic, documented): the robots of one component that
searches again move as a block, every member by the same vector (its internal geometry
and identified pairs survive):

(a) towards a *one-sided* sighting: the nearest detection of a member that no pair
    explains and that lies more than :data:`MATE_RADIUS` from every member (placed by
    breadth-first translation within the component), when farther than
    ``approach + 0.3`` m: the block walks until that detection is ``approach`` m away
    (the robot it saw may have missed it; closer, both should see each other);
(b) otherwise blind, a square spiral (the classic search pattern): in re-search round
    k (1, 2, ...) a leg of length ``k·step`` at heading
    ``north + c·137.5° + (k−1)·90°`` (fixed frame, CCW from +x), where c is the
    component's lowest id: the golden angle spreads the first legs of different ids.

Robots of the kept component do not walk; they search again from where they stand
(turning on the spot), because eq. 9 needs *both* sides' detections: a robot that walked
into sight can only be identified if the robots it now sees look again too.

:func:`step_blocked` is the camera check before each exploration step: a NAO seen
inside the step's sweep (along ``(0, step + clearance]``, across ``< clearance``) blocks
it.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from agent.core.formation.frame.neighbour_check import (
    DEFAULT_EPSILON,
    NeighbourGraph,
    identify_neighbours,
)
from agent.core.formation.frame.pose_pairing import identify_pairs
from agent.core.formation.frame.records import NeighborRecord
from agent.core.formation.joined import Joined

NORTH = math.pi / 2
GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))  # 137.5°
#: m, the first spiral leg: two thirds of the 3 m perception range, so the discs seen
#: from successive stops overlap, and a robot up to ~5 m from the fleet can come in sight
DEFAULT_STEP = 2.0
DEFAULT_APPROACH = 1.0  # m left to a one-sided sighting after the move (within d_e..1.2 m)
MATE_RADIUS = 0.5  # m: a detection this close to a member of the component is that member


@dataclass(frozen=True)
class Research:
    """What the agreed records say about re-search round ``round`` (see module doc)."""

    round: int  # the re-search round the moves are for (1, 2, ...)
    components: tuple[tuple[int, ...], ...]  # sorted by (size desc, lowest id)
    kept: tuple[int, ...]  # the component that keeps its place
    searchers: tuple[int, ...]  # every other robot, ascending
    isolated: tuple[int, ...]  # robots with no identified neighbour, ascending
    moves: tuple[tuple[int, float, float], ...]  # (searcher, dx, dy) in fixed frames, m
    reason: str

    @property
    def blind(self) -> bool:
        """No robot saw any other: nobody explores (module doc, step 4)."""
        return bool(self.searchers) and not self.kept

    @property
    def connected(self) -> bool:
        """Whether the common frame reaches every robot (nobody searches again)."""
        return not self.searchers

    def move(self, robot_id: int) -> np.ndarray:
        """The exploration vector of ``robot_id`` (fixed frame, m); zero for the kept."""
        for rid, dx, dy in self.moves:
            if rid == robot_id:
                return np.array([dx, dy], dtype=np.float64)
        return np.zeros(2)


BLIND = (
    "no robot saw any other: the robots stand out of each other's sight, or the camera does "
    "not recognise them (a calibration made for other caps or light); nobody walks blind"
)


def components(graph: NeighbourGraph) -> tuple[tuple[int, ...], ...]:
    """Connected components of the identified-neighbour graph, each ascending, ordered
    by size (largest first), ties by lowest id."""
    joined = Joined(graph.ids)
    for p in graph.pairs:
        joined.merge(p.i, p.j)
    comps = [tuple(sorted(g)) for g in joined.subsets()]
    comps.sort(key=lambda c: (-len(c), c[0]))
    return tuple(comps)


def _local_positions(graph: NeighbourGraph, comp: tuple[int, ...]) -> dict[int, np.ndarray]:
    """Members of ``comp`` placed by eq. 10 from its lowest id (neighbours by ascending id)."""
    adj: dict[int, list[tuple[int, np.ndarray]]] = {i: [] for i in comp}
    for p in graph.pairs:
        if p.i in adj:
            adj[p.i].append((p.j, p.v_ij))
            adj[p.j].append((p.i, p.v_ji))
    pos = {comp[0]: np.zeros(2)}
    queue = deque([comp[0]])
    while queue:
        u = queue.popleft()
        for v, vec in sorted(adj[u], key=lambda t: t[0]):
            if v not in pos:
                pos[v] = pos[u] + vec
                queue.append(v)
    return pos


def exploration_move(
    graph: NeighbourGraph,
    comp: tuple[int, ...],
    round_: int,
    step: float = DEFAULT_STEP,
    approach: float = DEFAULT_APPROACH,
) -> np.ndarray:
    """The block move of component ``comp`` in re-search round ``round_`` (module doc)."""
    pos = _local_positions(graph, comp)
    members = np.array([pos[i] for i in comp])
    recs = {r.robot_id: r for r in graph.records}
    best: tuple[float, int, int, np.ndarray] | None = None
    for rid, a in graph.unidentified():
        if rid not in pos:
            continue
        v = recs[rid].neighbours[a]
        d = float(np.hypot(*v))
        where = pos[rid] + v
        if d <= approach + 0.3 or np.min(np.hypot(*(members - where).T)) < MATE_RADIUS:
            continue
        key = (d, rid, a, v)
        if best is None or key[:3] < best[:3]:
            best = key
    if best is not None:
        d, v = best[0], best[3]
        return np.asarray(v * (1.0 - approach / d), dtype=np.float64)
    heading = NORTH + comp[0] * GOLDEN_ANGLE + (round_ - 1) * (math.pi / 2)
    length = round_ * step
    return np.array([length * math.cos(heading), length * math.sin(heading)])


def decide_research(
    records: Sequence[NeighborRecord],
    round_: int,
    epsilon: float = DEFAULT_EPSILON,
    step: float = DEFAULT_STEP,
    approach: float = DEFAULT_APPROACH,
) -> Research:
    """Who searches again in re-search round ``round_`` (>= 1), and their moves."""
    if isinstance(round_, bool) or not isinstance(round_, int) or round_ < 1:
        raise ValueError(f"re-search round must be an int >= 1, got {round_!r}")
    for name, v in (("step", step), ("approach", approach)):
        if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be a finite distance > 0, got {v!r}")
    graph = identify_neighbours(records, epsilon)
    comps = components(graph)
    if len(graph.ids) > 1 and not any(r.count for r in graph.records):
        ids = tuple(graph.ids)
        return Research(round_, comps, (), ids, ids, (), BLIND)
    if len(comps) > 1:
        # frames that are not parallel (docs/design.md §9): the pose fit's pairing may join
        # what eq. 9 cannot; the planner uses it too, so the fewer groups win
        unaligned = identify_pairs(records, epsilon)
        if len(components(unaligned)) < len(comps):
            graph, comps = unaligned, components(unaligned)
    deg = graph.degree()
    isolated = tuple(i for i in graph.ids if deg[i] == 0)
    kept = comps[0]
    if len(comps) == 1:
        return Research(round_, comps, kept, (), isolated, (), "fleet connected")
    searchers = tuple(sorted(i for c in comps[1:] for i in c))
    moves: list[tuple[int, float, float]] = []
    for c in comps[1:]:
        mv = exploration_move(graph, c, round_, step, approach)
        moves += [(i, float(mv[0]), float(mv[1])) for i in c]
    moves.sort()
    alone = f" (no identified neighbour: {list(isolated)})" if isolated else ""
    reason = (
        f"fleet not connected: robots {list(searchers)} outside the group of robots "
        f"{list(kept)}{alone}"
    )
    return Research(round_, comps, kept, searchers, isolated, tuple(moves), reason)


def step_blocked(points: np.ndarray, heading: float, step: float, clearance: float) -> int | None:
    """Index of the nearest NAO (``points``: (k, 2) relative to the robot, fixed-frame
    axes) inside the sweep of a ``step`` m walk along ``heading``; ``None`` if clear."""
    if not (math.isfinite(step) and math.isfinite(clearance) and clearance > 0):
        raise ValueError(f"step {step} and clearance {clearance} must be finite, clearance > 0")
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if pts.shape[0] == 0:
        return None
    u = np.array([math.cos(heading), math.sin(heading)]) * (1.0 if step >= 0 else -1.0)
    along = pts @ u
    across = np.abs(pts @ np.array([-u[1], u[0]]))
    inside = (along > 0.0) & (along <= abs(step) + clearance) & (across < clearance)
    if not np.any(inside):
        return None
    idx = np.flatnonzero(inside)
    return int(idx[np.argmin(along[idx])])
