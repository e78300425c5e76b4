"""Row lanes: robots whose slots lie beyond the fleet along a wide shape's row walk in
nested lanes beside the row and step onto their slots from the side (our addition to NAO
paper 4.2's straight paths, for the ``width`` shapes of docs/formation.md "Shapes" and the
``column``, whose row lies along the fleet too (:mod:`agent.core.formation.waves.choice`
turns its frame so that the row is x); kept to the safety rule of
:mod:`agent.core.formation.waves.safety` by the scheduler as every via point is).

Why: a ``line`` of N robots is N·d_e long, far wider than the fleet it is laid on. The
robots bound for its ends walk along the row, and a straight path to a far slot runs over
every nearer slot of its end at a shallow angle (within the clearance of it). Under the
speed-independent rule a robot may then only stand on its slot once every robot bound
farther out has passed it: each waits until the one ahead has walked nearly its whole
path (a chain of long walks, one after another).

The rule, in the shape frame (x along the row): the robots whose slot lies more than
``ROW_LANE_GAP`` clearances beyond the outermost start, at end e (±1 along x), form the
bundle of that end and of their side of the row (their start above or below their slot).
In a bundle of m robots the r-th farthest slot (r = 0, 1, ...) gets the lane

    y = base + side·g·(m − r),  g = ROW_LANE_GAP·clearance,

``base`` the bundle's outermost slot row on that side: the farther the slot, the farther
its lane from the row. A robot walks

    start -> (x_edge + e·g, y) -> (x_slot, y) -> slot,

x_edge the outermost start along e: diagonally out of the fleet to its lane's entry, along
the lane, and onto its slot across the row. A lane passes every nearer slot's approach at
>= g (the nearer lanes are lower), so the long legs of one bundle keep their clearance;
paths only meet on the diagonal legs inside the fleet, near the start of the one that goes
first, and a robot waiting for another only waits until that one has left the fleet.

Pairing: ``repair=False`` keeps the given robot for each slot; ``repair=True`` re-pairs a
bundle so that its diagonal legs nest as its lanes do: the robot farthest from the row
(side·y) takes the farthest slot. Ties: rows ascending. The plan is one candidate of
:mod:`agent.core.formation.waves.choice`, kept only when its makespan is the smallest.
"""

from __future__ import annotations

import numpy as np

from agent.core.formation.paths.lanes import checked_rows

#: Lanes are this many clearances apart (and the lowest this far beyond the bundle's
#: outermost slot row); a slot is in a bundle when it lies this far beyond every start.
ROW_LANE_GAP = 1.2


def row_lanes(
    starts_p: np.ndarray,
    slots_p: np.ndarray,
    order: np.ndarray,
    clearance: float,
    repair: bool = False,
) -> tuple[np.ndarray, list[tuple[np.ndarray, ...]]] | None:
    """The row-lane plan of the module doc, in the shape frame: (slot per robot row, via
    points per row), or None when no slot lies beyond the fleet. ``order``: each row's
    slot (a permutation of the rows of ``slots_p``)."""
    p, s, perm = checked_rows(starts_p, slots_p, order, clearance)
    n = p.shape[0]
    g = ROW_LANE_GAP * clearance
    out = perm.astype(np.int64).copy()
    vias: list[tuple[np.ndarray, ...]] = [() for _ in range(n)]
    target = s[out]
    above = np.where(p[:, 1] >= target[:, 1], 1.0, -1.0)
    changed = False
    for e in (-1.0, 1.0):
        edge = float(np.max(e * p[:, 0]))
        for side in (-1.0, 1.0):
            bundle = [i for i in range(n) if e * target[i, 0] > edge + g and above[i] == side]
            if not bundle:
                continue
            ks = sorted((int(out[i]) for i in bundle), key=lambda k: (-e * s[k, 0], k))
            if repair:
                robots = sorted(bundle, key=lambda i: (-side * p[i, 1], i))
            else:
                row_of = {int(out[i]): i for i in bundle}
                robots = [row_of[k] for k in ks]
            base = max(side * float(s[k, 1]) for k in ks)
            m = len(ks)
            for r, (i, k) in enumerate(zip(robots, ks, strict=True)):
                lane = side * (base + g * (m - r))
                out[i] = k
                vias[i] = (np.array([e * (edge + g), lane]), np.array([s[k, 0], lane]))
                changed = True
    if not changed:
        return None
    return out, vias
