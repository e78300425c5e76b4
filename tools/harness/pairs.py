"""The planned formation's child-parent pairs judged by the robots' own formula (NAO paper
5.1.1's r_d and r_φ; :func:`agent.core.formation.shape.verdict.check_edge` for any shape's
tree, :func:`~agent.core.formation.shape.verdict.check_pair` for a bare pyramid pair): what
the march is judged with at every truth sample (:func:`tools.harness.judge.judge_march`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from agent.core.formation.shape.spec import Shape
from agent.core.formation.shape.verdict import check_edge, check_pair


def plan_pairs(
    plan: Any, ids: list[int], shape: Shape, d_e: float, phi_e: float
) -> list[tuple[int, int, float, float]]:
    """(child, parent, distance, angle) of the planned formation: parents by
    ``RobotPlan.parent`` (the pyramid's: AUV eq. 6), distance and angle of the child's slot
    in the shape's tree."""
    slots = shape.slots(len(plan.robots), d_e, phi_e)
    out = []
    for i in ids:
        rp = plan.robot(i)
        if int(rp.parent) >= 0:
            _, dist, ang = slots.edge(int(rp.order))
            out.append((i, int(rp.parent), dist, ang))
    return sorted(out)


def evaluate(
    final: dict[int, tuple[float, float, float]],
    pairs: Sequence[tuple[int, int] | tuple[int, int, float, float]],
    axis: float,
    d_e: float,
    phi_e: float,
) -> list[dict[str, float]]:
    """Per pair: distance, angle, r_d, r_φ (NAO paper 5.1.1), by the formula the robots'
    own check uses: a pair with its slot's distance and angle (:func:`plan_pairs`) by
    :func:`agent.core.formation.shape.verdict.check_edge` (``angle_deg``: the direction
    parent → child, CCW from the facing), a bare (child, parent) pair of the pyramid by
    :func:`~agent.core.formation.shape.verdict.check_pair` (``angle_deg``: off the backward
    axis, either side)."""
    rows = []
    for pair in pairs:
        child, parent = pair[0], pair[1]
        offset = np.array(final[parent][:2]) - np.array(final[child][:2])
        if len(pair) == 4:
            c = check_edge(child, parent, offset, axis, pair[2], pair[3], phi_e)
        else:
            c = check_pair(child, parent, offset, axis, d_e, phi_e)
        rows.append(
            {
                "child": child,
                "parent": parent,
                "distance": c.distance,
                "angle_deg": math.degrees(c.angle),
                "r_d": c.r_d,
                "r_phi": c.r_phi,
            }
        )
    return rows
