"""The circle pattern's circle (AUV paper III.B.2.a, Fig. 3 and Fig. 12b): the robot that
holds the common frame stands at the centre and the others walk to evenly spaced places
on a circle round it, before the formation is built from the circle.

As a shape (the tree conventions of :mod:`tree`): slot 0 is the centre robot, the root;
slot k = 1 … n−1 is its child at distance R and angle 2π(k−1)/(n−1) from its facing, so
slot 1 stands straight ahead of it: at 90° of the common frame when the shape's frame
faces north (``PlanParams.axis``), the place of the formation's leader in the paper
("the robot located at the 90 degree in common frame is defaulted as the leader").
Every robot on the circle is the centre's child: the fine tuning of the paper (each
robot "fine tune[s] their positions based on the center robot") is the hold's
correction on the parent (agent/phases/hold.py).

Radius (the paper gives none): R = max(d_e, d_e / (2 sin(π/(n−1)))), the smallest circle
whose neighbours stand at least d_e apart (a chord of the (n−1)-gon) and whose robots
stand at least d_e from the centre, so that the circle keeps the formation's own spacing
(docs/formation.md "The circle pattern"). Two robots: the other one d_e ahead.
"""

from __future__ import annotations

import math

from agent.core.formation.shape.spec import TREE, Shape

#: The circle's name (the shape of the circle pattern's first plan).
CIRCLE_NAME = "cp-circle"


def ring_radius(n: int, d_e: float) -> float:
    """R for a fleet of ``n`` robots, the centre among them (module doc); ``ValueError``
    for n < 2 or d_e not a finite distance > 0."""
    if isinstance(n, bool) or not isinstance(n, int) or n < 2:
        raise ValueError(f"the circle pattern needs at least 2 robots, got {n!r}")
    if not (isinstance(d_e, int | float) and math.isfinite(d_e) and d_e > 0):
        raise ValueError(f"d_e must be a finite distance > 0, got {d_e!r}")
    on_circle = n - 1
    if on_circle < 2:
        return float(d_e)
    return max(float(d_e), float(d_e) / (2.0 * math.sin(math.pi / on_circle)))


def circle(n: int, d_e: float) -> Shape:
    """The circle of a fleet of ``n`` robots as a tree shape (module doc): the centre at
    slot 0, slot k >= 1 at R and 2π(k−1)/(n−1) from it."""
    r = ring_radius(n, d_e)
    step = 2.0 * math.pi / (n - 1)
    edges = tuple((0, r, math.remainder((k - 1) * step, 2.0 * math.pi)) for k in range(1, n))
    return Shape(name=CIRCLE_NAME, rule=TREE, edges=edges, orient="depth", source="")
