"""The plan seen from one robot: the common frame turned to that robot's fixed frame.

NAO paper 4.1.1 assumes every robot's fixed frame is parallel to the others (all start
facing the same way), so a plan in the common frame (the frame robot's fixed frame,
4.1.3) is used by every robot as it is: a point p is p − start in its own fixed frame.
Without that assumption (docs/design.md §9) robot i's fixed frame is the common frame turned
by ψ_i, its start heading estimated by the pose fit. :func:`in_own_frame` turns the whole
plan by −ψ_i about the common origin: every relative vector of the result (a goal minus
the start, a parent's offset, a route) is then exactly what robot i measures in its own
fixed frame, and every heading (legs, the pyramid axis) is one it can turn to with its
compass. Nothing else changes: the plan digest stays that of the common plan, which
every agent compares. ψ_i = 0 gives the plan back unchanged (the same object).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from agent.core.formation.plan import Plan, RobotPlan


def _turn(points: np.ndarray, c: float, s: float) -> np.ndarray:
    p = np.asarray(points, dtype=np.float64)
    rot = np.array([[c, -s], [s, c]])  # row vectors @ R(−ψ)ᵀ: rotation by −ψ
    return np.asarray(p @ rot)


def in_own_frame(plan: Plan, psi: float) -> Plan:
    """``plan`` turned by −``psi`` (rad) about the common origin (module docstring).

    Raises ``ValueError`` for a non-finite ``psi``.
    """
    if not math.isfinite(psi):
        raise ValueError(f"psi must be finite, got {psi}")
    if psi == 0.0:
        return plan
    c, s = math.cos(psi), math.sin(psi)

    def robot(r: RobotPlan) -> RobotPlan:
        return replace(
            r,
            start=_turn(r.start, c, s),
            target=_turn(r.target, c, s),
            via=tuple(_turn(v, c, s) for v in r.via),
            heading=math.remainder(r.heading - psi, 2.0 * math.pi),
        )

    obstacles = np.asarray(plan.obstacles, dtype=np.float64).reshape(-1, 2)
    return replace(
        plan,
        axis=math.remainder(float(plan.axis) - psi, 2.0 * math.pi),
        origin=_turn(plan.origin, c, s),
        robots=tuple(robot(r) for r in plan.robots),
        obstacles=_turn(obstacles, c, s) if len(obstacles) else obstacles,
    )
