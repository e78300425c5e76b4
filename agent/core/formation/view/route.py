"""The march route: where the whole pyramid goes after it holds (AUV paper I–II: the
formation marches in a pattern, followers tracking the robot in front; docs/design.md §1 step 7).

A route is a distance along the pyramid's axis or a point of the common frame. The
pyramid *translates* by V (:func:`route_vector`): its axis keeps its direction, and every
child keeps its parent at the planned offset (:func:`station_offset`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from agent.core.formation.plan import Plan

MAX_ROUTE = 50.0  # m: the longest march accepted (the longest walk command the world takes)


@dataclass(frozen=True)
class Route:
    """The march after ``hold``: the leader walks ``distance`` m along the
    pyramid's axis, or to the point ``to`` (x, y) of the common frame. Exactly one is
    given. The pyramid translates: its axis keeps its direction (see agent/phases/march.py)."""

    distance: float | None = None
    to: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if (self.distance is None) == (self.to is None):
            raise ValueError("a route is a distance along the axis or a point, exactly one")
        if self.distance is not None and not (
            math.isfinite(self.distance) and 0.0 < self.distance <= MAX_ROUTE
        ):
            raise ValueError(f"march distance must be in (0, {MAX_ROUTE:g}] m, got {self.distance}")
        if self.to is not None and not (
            len(self.to) == 2 and all(math.isfinite(v) and abs(v) <= 1000.0 for v in self.to)
        ):
            raise ValueError(f"march point must be two finite coordinates (m), got {self.to}")

    def key(self) -> tuple[str, float] | tuple[str, float, float]:
        """What the agreed-parameters digest covers."""
        if self.to is not None:
            return ("to", float(self.to[0]), float(self.to[1]))
        assert self.distance is not None
        return ("axis", float(self.distance))


def route_vector(plan: Plan, route: Route, axis: float) -> np.ndarray:
    """V, the pyramid's displacement in the common frame (see the module docstring)."""
    if route.to is not None:
        lead = np.asarray(plan.robot(plan.leader).target, dtype=np.float64).reshape(2)
        return np.asarray(route.to, dtype=np.float64) - lead
    assert route.distance is not None
    return route.distance * np.array([math.cos(axis), math.sin(axis)])


def station_offset(plan: Plan, me: int) -> np.ndarray:
    """Where a child keeps its parent: parent target − own target (common frame)."""
    rp = plan.robot(me)
    parent = np.asarray(plan.robot(int(rp.parent)).target, dtype=np.float64).reshape(2)
    return parent - np.asarray(rp.target, dtype=np.float64).reshape(2)
