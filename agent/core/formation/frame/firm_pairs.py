"""The pairs a dense fleet's first fit can trust (NAO paper 4.1.2, Algorithm 2, eq. 9;
4.1.3, eq. 10; docs/design.md §9).

Eq. 9 accepts a detection pair when ``v_ij ≈ −v_ji`` within ε. In a dense fleet that is
met by chance: robot i's one-way sighting of k and robot j's one-way sighting of l,
2-3.5 m long, agree within ε = 0.35 m about once in thirty candidates, and where neither
detection has its true partner (the other robot missed it) the global greedy of
:func:`neighbour_check.identify_neighbours` accepts the chance pair. At 100 NAOs
(median spacing 0.68 m, 5-39 sightings a robot): 148 of 1 147 eq. 9 pairs were wrong,
the least-squares common frame built on all of them was ~1 m off everywhere, and
identifying the sightings again from it (:mod:`reidentify`) could not recover.

A right pair is recognised by its *support* (the neighbour check's triangles: i's other
sightings, shifted by ``−v_ij``, that are among j's, from both sides), counted here
within :data:`SUPPORT_TOL_SHARE`·ε, half the pairing's tolerance (the absolute part of
:mod:`pose_pairing`'s loop tolerance too): at ε a chance pair of that fleet finds up to 17
chance triangles (a right one 3-27); at ε/2 the wrong pairs had 0-8 (median 3), the right
ones 0-24 (median 12).

:func:`firm_graph` keeps the pairs with support ≥ :data:`FIRM_SUPPORT`, and joins
what they leave apart by a maximum-support spanning forest (Kruskal: pairs by support,
descending; ties: smaller ε_d, then lower (i, j)); the graph it returns connects exactly
the robots the full graph connects. Its least-squares frame is only a start: every
sighting is then identified where it lands (:func:`reidentify.refine_poses`), which
brings the dropped right pairs back. On the recorded record sets of dense fleets (five of
50 NAOs, one of 100) that start gave consistent frames within 0.09 m of the truth for
every threshold from 6 up to a bare spanning tree; 4 failed at 100 NAOs. 12 keeps the
redundancy of the well-seen pairs and sits above the support of every wrong pair
accepted there (at most 8).

Deterministic: integer supports, ties broken by ε_d and ids; the same graph in any
record order gives the same firm graph.
"""

from __future__ import annotations

import numpy as np

from agent.core.formation.frame.neighbour_check import NeighbourGraph, mutual_support
from agent.core.formation.joined import Joined

#: The support's tolerance as a share of ε (module docstring).
SUPPORT_TOL_SHARE = 0.5
#: Pairs with at least this support (both sides, at SUPPORT_TOL_SHARE·ε) are firm.
FIRM_SUPPORT = 12
#: A fleet is dense enough for a firm start when its firm pairs reach this share of its
#: robots (:func:`firm_enough`).
FIRM_COVER = 0.9


def pair_supports(graph: NeighbourGraph, tolerance: float) -> np.ndarray:
    """The support of each of ``graph.pairs`` (both sides summed), within ``tolerance`` m.

    Raises
    ------
    ValueError
        When ``tolerance`` is not a finite number > 0.
    """
    if not (isinstance(tolerance, int | float) and np.isfinite(tolerance) and tolerance > 0):
        raise ValueError(f"tolerance must be a finite number > 0, got {tolerance!r}")
    owner: list[int] = []
    vecs: list[np.ndarray] = []
    row: dict[tuple[int, int], int] = {}
    for ri, rec in enumerate(graph.records):
        for det in range(rec.count):
            row[(rec.robot_id, det)] = len(owner)
            owner.append(ri)
            vecs.append(rec.neighbours[det])
    if not graph.pairs:
        return np.zeros(0, dtype=np.int64)
    own = np.asarray(owner, dtype=np.int64)
    sight = np.asarray(vecs, dtype=np.float64).reshape(-1, 2)
    side_i = np.array([row[(p.i, p.a)] for p in graph.pairs], dtype=np.int64)
    side_j = np.array([row[(p.j, p.b)] for p in graph.pairs], dtype=np.int64)
    total = mutual_support(side_i, side_j, own, sight, tolerance)
    total += mutual_support(side_j, side_i, own, sight, tolerance)
    return total


def firm_start(graph: NeighbourGraph) -> NeighbourGraph | None:
    """:func:`firm_graph` of a dense fleet, or None when its firm pairs (support ≥
    :data:`FIRM_SUPPORT`) reach fewer than :data:`FIRM_COVER` of its robots.

    A sparse fleet's firm graph is a bare spanning tree, a weaker start than all its
    pairs: on synthetic fleets of 6 and 15 NAOs set down within ±20° of north, two of 40
    frames started from the tree were fitted consistent but 0.3-0.8 m and 18-24° off.
    """
    support = pair_supports(graph, SUPPORT_TOL_SHARE * graph.epsilon)
    firm = support >= FIRM_SUPPORT
    reached = {r for p, f in zip(graph.pairs, firm, strict=True) if f for r in (p.i, p.j)}
    if len(reached) < FIRM_COVER * len(graph.ids):
        return None
    return _forest(graph, support, FIRM_SUPPORT)


def firm_graph(graph: NeighbourGraph, min_support: int = FIRM_SUPPORT) -> NeighbourGraph:
    """The pairs of ``graph`` with support ≥ ``min_support`` plus a maximum-support
    forest (module docstring).

    Parameters
    ----------
    graph : NeighbourGraph
        Eq. 9 pairs (:func:`neighbour_check.identify_neighbours`).
    min_support : int
        Pairs with at least this support are kept whether or not the forest needs them.

    Raises
    ------
    ValueError
        When ``min_support`` is not an int ≥ 0.
    """
    if isinstance(min_support, bool) or not isinstance(min_support, int) or min_support < 0:
        raise ValueError(f"min_support must be an int >= 0, got {min_support!r}")
    return _forest(graph, pair_supports(graph, SUPPORT_TOL_SHARE * graph.epsilon), min_support)


def _forest(graph: NeighbourGraph, support: np.ndarray, min_support: int) -> NeighbourGraph:
    pairs = graph.pairs
    order = sorted(
        range(len(pairs)), key=lambda k: (-int(support[k]), pairs[k].eps_d, pairs[k].i, pairs[k].j)
    )
    joined = Joined(graph.ids)
    keep = []
    for k in order:
        # merge() is True when the pair joins two parts of the forest (Kruskal)
        if joined.merge(pairs[k].i, pairs[k].j) or support[k] >= min_support:
            keep.append(pairs[k])
    keep.sort(key=lambda p: (p.i, p.j))
    return NeighbourGraph(
        ids=graph.ids, pairs=tuple(keep), records=graph.records, epsilon=graph.epsilon
    )
