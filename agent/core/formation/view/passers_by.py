"""Who may still pass a robot's final alignment (an addition to NAO paper 5.2.2: the
final alignment to the parent, ``agent/phases/hold.py``; the paths of 4.2).

Once it has arrived, a child looks at its parent and steps by the measured error
(at most ``max_correction``). Before, every robot waited for the whole fleet to
arrive first, so the alignment, which runs down the pyramid one level at a time, began
only after the last walk: a minute of 50 NAOs' wall time. What the alignment needs is
narrower: no robot may still walk near the child's slot (which the correction step
leaves by up to ``max_correction``), near its parent's slot (a passing NAO would be
taken for the parent), or between the two (it would hide the parent). Those are the
robots whose planned path comes within ``margin`` of the segment from the child's slot
to its parent's; every agent computes them from the same plan, so they are the same
on every agent.
"""

from __future__ import annotations

import math

import numpy as np

from agent.core.formation.paths.geometry import seg_seg_dist
from agent.core.formation.plan import Plan


def passers_by(plan: Plan, robot_id: int, margin: float) -> tuple[int, ...]:
    """Ids (ascending) of the other robots that move and whose planned path (start,
    vias, target) comes within ``margin`` of ``robot_id``'s sight line: the segment from its target to
    its parent's target (the point of its target for the leader).

    Raises ``ValueError`` for a robot not in the plan or a ``margin`` that is not a
    finite distance >= 0.
    """
    if not (math.isfinite(margin) and margin >= 0.0):
        raise ValueError(f"margin must be a finite distance >= 0, got {margin!r}")
    me = plan.robot(robot_id)
    a = np.asarray(me.target, dtype=np.float64)
    b = a if me.parent < 0 else np.asarray(plan.robot(me.parent).target, dtype=np.float64)
    out: list[int] = []
    for other in sorted(plan.robots, key=lambda r: r.robot_id):
        if other.robot_id == robot_id:
            continue
        path = np.asarray(other.path(), dtype=np.float64)
        if other.length() == 0.0:  # it stays where it stands: it passes nobody
            continue
        d = seg_seg_dist(a[None, :], b[None, :], path[:-1], path[1:])
        if float(np.min(d)) <= margin:
            out.append(other.robot_id)
    return tuple(out)
