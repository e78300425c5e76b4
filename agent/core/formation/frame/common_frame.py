"""Common frame: every robot's start position in one frame (NAO paper 4.1.3, eq. 10; AUV III.A eq. 4).

The frame robot is the one with the most identified neighbours (tie: lowest id); its
fixed frame is the common frame, so its own start is (0, 0). Two ways to place the
others:

* ``bfs`` - the paper's: breadth-first from the frame robot, ``p_j = p_i + v_ij`` with
  v_ij robot i's own measurement of j (eq. 10). Neighbours of a node are visited in
  ascending id (tie-break), so the spanning tree is unique.
* ``lsq`` - our variant: weighted least squares over *every* measurement of every
  identified pair (both directions: ``p_j - p_i ≈ v_ij`` and ``p_i - p_j ≈ v_ji``,
  weight = confidence λ of the detection, 1 if unknown), anchored at the frame robot.
  Detections that were seen by one side only are attached afterwards when, placed from
  their owner's estimate, they fall within ε of exactly one robot's estimate; they add
  one more equation and the system is solved once more.

The default (``DEFAULT_METHOD``) is the one the Monte Carlo (``python -m
tools.montecarlo``) shows to be more accurate: ``lsq``.

A fleet whose identified-neighbour graph is not connected gives a ``ValueError`` that
names the robots the frame robot cannot reach (the paper's answer is to search again).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve
from scipy.spatial import cKDTree

from agent.core.formation.frame.neighbour_check import NeighbourGraph

METHODS = ("bfs", "lsq")
DEFAULT_METHOD = "lsq"


@dataclass(frozen=True)
class CommonFrame:
    frame_robot: int
    ids: tuple[int, ...]  # ascending
    positions: np.ndarray  # (N, 2), row k is robot ids[k]; frame robot at (0, 0)
    method: str


def choose_frame_robot(graph: NeighbourGraph) -> int:
    """Robot with the most identified neighbours; ties -> lowest id."""
    deg = graph.degree()
    best = max(deg.values())
    return min(i for i, d in deg.items() if d == best)


def _adjacency(graph: NeighbourGraph) -> dict[int, list[tuple[int, np.ndarray]]]:
    adj: dict[int, list[tuple[int, np.ndarray]]] = {i: [] for i in graph.ids}
    for p in graph.pairs:
        adj[p.i].append((p.j, p.v_ij))
        adj[p.j].append((p.i, p.v_ji))
    for lst in adj.values():
        lst.sort(key=lambda t: t[0])
    return adj


def _check_connected(graph: NeighbourGraph, frame: int) -> None:
    adj = _adjacency(graph)
    seen = {frame}
    queue = deque([frame])
    while queue:
        u = queue.popleft()
        for v, _ in adj[u]:
            if v not in seen:
                seen.add(v)
                queue.append(v)
    missing = sorted(set(graph.ids) - seen)
    if missing:
        isolated = [i for i in missing if not adj[i]]
        extra = f" ({len(isolated)} with no identified neighbour: {isolated})" if isolated else ""
        raise ValueError(
            f"fleet not connected: robots {missing} cannot be reached from frame robot "
            f"{frame} through identified neighbours{extra}; they must search again"
        )


def bfs_positions(graph: NeighbourGraph, frame: int) -> np.ndarray:
    """Eq. 10 by breadth-first translation from the frame robot."""
    adj = _adjacency(graph)
    pos: dict[int, np.ndarray] = {frame: np.zeros(2)}
    queue = deque([frame])
    while queue:
        u = queue.popleft()
        for v, vec in adj[u]:
            if v not in pos:
                pos[v] = pos[u] + vec
                queue.append(v)
    return np.array([pos[i] for i in graph.ids], dtype=np.float64)


def _solve_lsq(n: int, anchor: int, edges: list[tuple[int, int, np.ndarray, float]]) -> np.ndarray:
    """min Σ w |p_b - p_a - v|² with p_anchor = 0 (normal equations, sparse)."""
    a_idx = np.array([e[0] for e in edges], dtype=np.int64)
    b_idx = np.array([e[1] for e in edges], dtype=np.int64)
    vec = np.array([e[2] for e in edges], dtype=np.float64).reshape(-1, 2)
    w = np.array([max(e[3], 1e-6) for e in edges], dtype=np.float64)
    rows = np.concatenate([a_idx, b_idx, a_idx, b_idx])
    cols = np.concatenate([a_idx, b_idx, b_idx, a_idx])
    vals = np.concatenate([w, w, -w, -w])
    lap = sp.coo_matrix((vals, (rows, cols)), shape=(n, n)).tocsr()
    rhs = np.zeros((n, 2))
    np.add.at(rhs, b_idx, w[:, None] * vec)
    np.add.at(rhs, a_idx, -w[:, None] * vec)
    keep = np.array([k for k in range(n) if k != anchor], dtype=np.int64)
    out = np.zeros((n, 2))
    if keep.size:
        sub = lap[keep][:, keep].tocsc()
        sol = spsolve(sub, rhs[keep])
        out[keep] = np.asarray(sol).reshape(-1, 2)
    return out


def lsq_positions(graph: NeighbourGraph, frame: int) -> np.ndarray:
    """Least squares over every pair measurement, plus one-sided detections."""
    index = {rid: k for k, rid in enumerate(graph.ids)}
    n = len(graph.ids)
    edges: list[tuple[int, int, np.ndarray, float]] = []
    for p in graph.pairs:
        edges.append((index[p.i], index[p.j], p.v_ij, p.w_ij))
        edges.append((index[p.j], index[p.i], p.v_ji, p.w_ji))
    anchor = index[frame]
    pos = _solve_lsq(n, anchor, edges) if edges else np.zeros((n, 2))
    # One-sided detections: attach to the unique robot estimate within ε, if any.
    linked = {(p.i, p.j) for p in graph.pairs} | {(p.j, p.i) for p in graph.pairs}
    extra: list[tuple[int, int, np.ndarray, float]] = []
    loose = graph.unidentified()
    if loose and n > 1:
        tree = cKDTree(pos)
        recs = {r.robot_id: r for r in graph.records}
        for rid, a in loose:
            rec = recs[rid]
            guess = pos[index[rid]] + rec.neighbours[a]
            hits = sorted(tree.query_ball_point(guess, graph.epsilon))
            hits = [h for h in hits if graph.ids[h] != rid]
            if len(hits) != 1 or (rid, graph.ids[hits[0]]) in linked:
                continue
            w = 1.0 if rec.confidences is None else float(rec.confidences[a])
            extra.append((index[rid], hits[0], rec.neighbours[a], w))
            linked.add((rid, graph.ids[hits[0]]))
    if extra:
        pos = _solve_lsq(n, anchor, edges + extra)
    pos[anchor] = 0.0
    return pos


def build_common_frame(graph: NeighbourGraph, method: str = DEFAULT_METHOD) -> CommonFrame:
    """Frame robot + start positions of every robot in its fixed frame."""
    if method == "default":
        method = DEFAULT_METHOD
    if method not in METHODS:
        raise ValueError(f"frame method must be one of {(*METHODS, 'default')}, got {method!r}")
    frame = choose_frame_robot(graph)
    _check_connected(graph, frame)
    pos = bfs_positions(graph, frame) if method == "bfs" else lsq_positions(graph, frame)
    return CommonFrame(frame_robot=frame, ids=graph.ids, positions=pos, method=method)


def positions_from_pairs(
    ids: Sequence[int], graph: NeighbourGraph, method: str = DEFAULT_METHOD
) -> np.ndarray:
    """Convenience: positions of ``ids`` (a subset of the graph's) in the common frame."""
    cf = build_common_frame(graph, method)
    index = {rid: k for k, rid in enumerate(cf.ids)}
    try:
        return np.array([cf.positions[index[i]] for i in ids])
    except KeyError as exc:
        raise ValueError(f"robot {exc.args[0]} has no record") from None
