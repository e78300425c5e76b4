"""The banded plan: a safe plan that always exists, built in O(n log n) (our addition to
NAO paper 4.2; a "one conflict class at a time" fallback, so that every valid input gets a safe
plan).

Work in the pyramid frame (x to the right, y = the facing axis). Let ``y_max`` be the
front-most start and ``g = 1.5·c`` (c = 2·radius). The pyramid is placed *ahead* of the
fleet: its last layer at ``Y0 + g`` where ``Y0 = y_max + g`` is the *corridor* line.

Order and slots. Robots are sequenced front to back: y descending, then x ascending,
then row (= id order). Slot columns (eq. 7 puts slots on columns ``sx = d_e sin φ_e``
apart; for another shape the columns are its distinct slot x and ``sx`` the smallest gap
between two) are filled by a 1-D transport in x: robots sorted by x fill the columns left
to right, each column taking as many robots as it has slots; inside a column the robots
in sequence order take its slots front to back. So within a column, start y and slot y
fall together along the sequence; robots of different columns have slots >= sx >= c
apart in x. If ``sx < c``, layer blocks replace the columns: the k-th block of robots
in the sequence takes the k-th row of slots from the front (the pyramid's k-th layer;
a row: the slots of equal y; inside a block the robots sorted by x take the row's slots
left to right), so along the whole sequence the slot y never increases.

Bands. Robot i's path stays inside the x-interval ``[min(x_i, X_i), max(x_i, X_i)]``
(its *band*). Two robots whose bands are >= c apart never come within c of each other,
moving or standing. Robots whose bands come closer go in sequence order (wave of the
later one > wave of the earlier one). (The leader need not go first: its column may
hold robots ahead of it.)

Why this is always safe (the clearance rule of :mod:`safety`, with
``req = min(c, |s_i - s_k|, |t_i - t_k|)``), for robots i before k in the sequence
(y_k <= y_i):

* i moves while k stands at s_k: i's first leg goes straight up from s_i, so its nearest
  point to s_k is s_i itself (distance |s_i - s_k| >= req); the corridor leg and the
  last leg lie >= g > c above every start.
* k moves while i stands at t_i: k's first two legs lie >= g below every slot; k's last
  leg rises at x = X_k to t_k. If i and k share a slot column (or a layer block order),
  Y_i >= Y_k and the nearest point to t_i is t_k; otherwise |X_i - X_k| >= sx >= c.
* moving together: only when their bands are >= c apart (then every point is).

Nothing here depends on the fleet's shape, spacing or size, so every valid input (n >= 1
robots at finite positions) gets this plan; :mod:`plan` uses it whenever the scheduled
plans of :mod:`safety` fail. Cost: one sort, one pass over the bands with a numpy
level array over x cells of side c/2 (a band is widened by c/2 and covers the cells it
meets, so two bands closer than c share a cell). Dependencies per robot: the robots that
last claimed one of its cells (every earlier conflicting robot is one of them or an
ancestor of one). Obstacles are not handled here (a robot can be walled in by
obstacles, where no safe plan exists at all).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from agent.core.formation.shape.layout import centred, column_step, columns
from agent.core.formation.shape.pyramid import PyramidFrame
from agent.core.formation.shape.spec import PYRAMID, Shape

#: Gap between the front-most start and the corridor line, and between the corridor line
#: and the last layer, in clearances.
GAP = 1.5


@dataclass(frozen=True)
class BandedPlan:
    order: np.ndarray  # (N,) slot order per robot row
    targets: np.ndarray  # (N, 2) common frame
    vias: tuple[tuple[np.ndarray, ...], ...]  # per robot row, common frame
    waves: np.ndarray  # (N,) per robot row
    after: tuple[tuple[int, ...], ...]  # per robot row: rows it waits for (ascending)
    origin: np.ndarray  # (2,) the pyramid's o_p after the move ahead (common frame)


def banded_plan(
    starts: np.ndarray,
    frame: PyramidFrame,
    d_e: float,
    phi_e: float,
    radius: float,
    shape: Shape = PYRAMID,
) -> BandedPlan:
    """The banded plan of the module doc for robot rows ``starts`` (N, 2), common frame,
    on the slots of ``shape`` (default the pyramid)."""
    pos = np.asarray(starts, dtype=np.float64)
    if pos.ndim != 2 or pos.shape[1] != 2 or pos.shape[0] < 1:
        raise ValueError(f"starts must be a non-empty (N, 2) array, got shape {pos.shape}")
    if not np.all(np.isfinite(pos)):
        raise ValueError("starts contain non-finite values")
    if not (math.isfinite(radius) and radius > 0):
        raise ValueError(f"radius must be > 0, got {radius!r}")
    n = pos.shape[0]
    c = 2.0 * radius
    g = GAP * c
    sp = frame.to_pyramid(pos)
    y_corr = float(np.max(sp[:, 1])) + g
    slots = centred(shape, n, d_e, phi_e)
    slots = slots + np.array([0.0, y_corr + g - float(np.min(slots[:, 1]))])
    rows = np.arange(n)
    seq = np.lexsort((rows, sp[:, 0], -sp[:, 1]))  # front to back
    rank = np.empty(n, dtype=np.int64)
    rank[seq] = rows  # position in the sequence
    order = np.empty(n, dtype=np.int64)
    col = columns(slots[:, 0])
    sx = column_step(shape, slots[:, 0], d_e, phi_e)  # the pyramid's: sx apart (eq. 7)
    if n > 1 and sx >= c * (1.0 - 1e-10):
        # columns: robots by x (1-D transport, then sequence rank) fill the slot columns
        # left to right; inside a column, sequence order takes the slots front to back
        slot_seq = np.lexsort((-slots[:, 1], col))  # by column, front to back
        by_x = np.lexsort((rank, sp[:, 0]))
        col_of_robot = np.empty(n, dtype=np.int64)
        col_of_robot[by_x] = col[slot_seq]  # the k-th robot by x joins the k-th slot's column
        robots_seq = np.lexsort((rank, col_of_robot))  # by column, then sequence
        order[robots_seq] = slot_seq
    else:
        # layer blocks: the slots of one row (equal y, a pyramid's layer) front to back,
        # each row left to right; the next robots of the sequence take a row, by x
        row = columns(-slots[:, 1])  # rank of the slot's row, front (highest y) first
        slot_seq = np.lexsort((rows, slots[:, 0], row))
        bounds = np.flatnonzero(np.diff(row[slot_seq])) + 1
        start = 0
        for stop in [*bounds.tolist(), n]:
            block = seq[start:stop]
            block = block[np.lexsort((block, sp[block, 0]))]
            order[block] = slot_seq[start:stop]  # eq. 7: a layer left to right
            start = stop
    slot_p = slots[order]
    targets = frame.to_common(slot_p)
    axis = np.array([math.cos(frame.beta), math.sin(frame.beta)])
    v1 = pos + (y_corr - sp[:, 1])[:, None] * axis
    v2 = targets - (slot_p[:, 1] - y_corr)[:, None] * axis
    same_x = np.abs(sp[:, 0] - slot_p[:, 0]) <= 1e-12 * max(1.0, float(np.max(np.abs(sp))))
    vias = tuple((v1[i].copy(),) if same_x[i] else (v1[i].copy(), v2[i].copy()) for i in range(n))
    # bands -> cells of side c/2 (widened by c/2)
    lo = np.minimum(sp[:, 0], slot_p[:, 0]) - 0.5 * c
    hi = np.maximum(sp[:, 0], slot_p[:, 0]) + 0.5 * c
    q = 0.5 * c
    base = math.floor(float(np.min(lo)) / q)
    c0 = np.floor(lo / q).astype(np.int64) - base
    c1 = np.floor(hi / q).astype(np.int64) - base + 1
    level = np.full(int(c1.max()) + 1, -1, dtype=np.int64)
    owner = np.full(level.size, -1, dtype=np.int64)
    waves = np.zeros(n, dtype=np.int64)
    after: list[tuple[int, ...]] = [() for _ in range(n)]
    c0l, c1l = c0.tolist(), c1.tolist()
    for i in seq.tolist():
        a, b = c0l[i], c1l[i]
        w = int(level[a:b].max()) + 1
        prev = set(owner[a:b].tolist())
        prev.discard(-1)
        after[i] = tuple(sorted(prev))
        waves[i] = w
        level[a:b] = w
        owner[a:b] = i
    origin = frame.to_common(np.array([0.0, float(np.mean(slots[:, 1]))]))
    return BandedPlan(
        order=order,
        targets=targets,
        vias=vias,
        waves=waves,
        after=tuple(after),
        origin=origin,
    )
