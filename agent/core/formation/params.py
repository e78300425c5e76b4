"""The planner's parameters: ``PlanParams`` (the pyramid's d_e and phi_e of AUV eqs.
5-7, the robot radius of the safety rule, the eq. 9 threshold epsilon of NAO paper
4.1.2, the shape: the pyramid or another, :mod:`agent.core.formation.shape.spec`) and
the choices a plan may name: assignment strategy (NAO paper 4.2 and
Lemma 1, AUV III.C), pyramid orientation (NAO eqs. 12-13, north, or the circle pattern
walked first, AUV III.B.2.a), common-frame method
(eq. 10 or least squares), placement, and obstacle method (NAO paper 5.1.2).

The ``default`` strategy is a policy over fleet size, set by the thresholds below and
:meth:`PlanParams.attempts`; :mod:`plan` and :mod:`obstacles` both read it from here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from agent.core.formation.frame.common_frame import METHODS
from agent.core.formation.frame.neighbour_check import DEFAULT_EPSILON
from agent.core.formation.paths.assignment import STRATEGIES
from agent.core.formation.shape.layout import PLACEMENTS, closest_slots
from agent.core.formation.shape.pyramid import AXES, check_geometry
from agent.core.formation.shape.spec import PYRAMID, Shape

#: The orientations a plan may name: an axis of :data:`pyramid.AXES` (``pca``, NAO eq. 12;
#: ``north``), or ``cp``: the circle pattern of AUV III.B.2.a, walked first, whose
#: formation then faces north (:mod:`agent.core.formation.shape.circle_pattern`).
ORIENTATIONS = (*AXES, "cp")

#: ``default`` strategy: exact min-sum (``optimal``, O(n³)) up to this many robots; the
#: paper's O(n log n) strategy above. Whatever it starts with, ``default`` falls back to
#: the next attempt of :func:`attempts` when a plan cannot be scheduled safely.
OPTIMAL_MAX_N = 1500

#: ``default`` strategy: up to this many robots, several assignments are scheduled and
#: compared by makespan, and the critical chain gets detours (see :func:`choice.choose`).
CANDIDATES_MAX_N = 200

#: ``default`` strategy: above this many robots, the banded plan of :mod:`fallback`
#: (O(n log n), safe by construction) instead of the scheduled ones (whose pair search
#: grows with the total path length, ~n^1.5 for the centred pyramid: > 20 s at 2·10^4).
SCHEDULE_MAX_N = 12_000

#: The ``front`` fallback placement is only tried up to this many robots.
FRONT_MAX_N = 2000


#: How a plan meets obstacles: ``near`` (the obstacle-free pattern moved by the smallest
#: clear translation, paths bent by the scheduler; :func:`obstacles.plan_near_obstacles`),
#: ``paper`` (5.1.2: obstacles as robots, sideways shift, layer correction;
#: :func:`obstacles.plan_around_obstacles`), ``default`` (near, else paper).
OBSTACLE_METHODS = ("near", "paper", "default")

#: Every strategy a plan may name: an assignment of :mod:`assignment`, ``banded`` (the
#: plan of :mod:`fallback`, which always exists) or ``default``.
PLAN_STRATEGIES = (*STRATEGIES, "banded", "default")


#: The formation's edge length d_e (m): a child's distance to its parent in the pyramid,
#: the 0.8 m of the real NAOs (NAO paper 5.2; the paper's simulations of 5.1 use 2 m).
#: Every default of d_e (the agent's, the planner's, the tools') is this one.
D_E = 0.8
#: φ_e (degrees): a child's angle off its parent's backward axis (NAO paper 5.1-5.2: 30°).
PHI_E_DEG = 30.0


@dataclass(frozen=True)
class PlanParams:
    """The planner's settings, checked on construction (``ValueError`` when invalid)."""

    d_e: float = D_E
    phi_e: float = math.radians(PHI_E_DEG)
    radius: float = 0.2
    strategy: str = "default"  # "paper" | "optimal" | "capt" | "banded" | "default"
    orientation: str = "pca"  # one of ORIENTATIONS
    #: "bfs" (paper eq. 10) | "lsq" (least squares), both on the papers' aligned frames;
    #: "default": start poses (fleet_frame, docs/design.md §9), = lsq when starts are aligned
    frame_method: str = "default"
    epsilon: float = DEFAULT_EPSILON  # eq. 9 threshold, metres (see neighbour_check)
    # "centroid" (slots centred on the starts) | "front" (pyramid ahead of the fleet) |
    # "default": centroid, or front when the centroid placement cannot be scheduled safely
    placement: str = "default"
    obstacle_method: str = "default"  # see OBSTACLE_METHODS
    #: the formation's shape (the papers' pyramid by default; docs/formation.md "Shapes")
    shape: Shape = PYRAMID

    def __post_init__(self) -> None:
        check_geometry(self.d_e, self.phi_e)
        if not isinstance(self.shape, Shape):
            raise ValueError(f"shape must be a Shape, got {self.shape!r}")
        if not (
            isinstance(self.radius, int | float) and math.isfinite(self.radius) and self.radius > 0
        ):
            raise ValueError(f"radius must be a finite distance > 0, got {self.radius!r}")
        if self.strategy not in PLAN_STRATEGIES:
            raise ValueError(f"strategy must be one of {PLAN_STRATEGIES}, got {self.strategy!r}")
        if self.orientation not in ORIENTATIONS:
            raise ValueError(f"orientation must be one of {ORIENTATIONS}, got {self.orientation!r}")
        if self.frame_method not in (*METHODS, "default"):
            raise ValueError(
                f"frame_method must be one of {(*METHODS, 'default')}, got {self.frame_method!r}"
            )
        if self.placement not in (*PLACEMENTS, "default"):
            raise ValueError(
                f"placement must be one of {(*PLACEMENTS, 'default')}, got {self.placement!r}"
            )
        if self.obstacle_method not in OBSTACLE_METHODS:
            raise ValueError(
                f"obstacle_method must be one of {OBSTACLE_METHODS}, got {self.obstacle_method!r}"
            )
        if not (
            isinstance(self.epsilon, int | float)
            and math.isfinite(self.epsilon)
            and self.epsilon > 0
        ):
            raise ValueError(f"epsilon must be a finite distance > 0, got {self.epsilon!r}")
        if self.shape.capacity is not None:  # a formation file: its slots must be clear
            a, b, d = closest_slots(self.shape, self.d_e, self.phi_e)
            if d < 2.0 * self.radius:
                raise ValueError(
                    f"shape {self.shape.name!r}: slots {a} and {b} are {d:.3f} m apart, "
                    f"closer than two robots may stand (2·radius = {2.0 * self.radius:.3f} m)"
                )

    @property
    def axis(self) -> str:
        """How the shape's frame finds its axis (:data:`pyramid.AXES`): the orientation's,
        north for the circle pattern."""
        return "north" if self.orientation == "cp" else self.orientation

    def resolved_strategy(self, n: int) -> str:
        """The assignment strategy for n robots: ``default`` resolved by fleet size."""
        if self.strategy != "default":
            return self.strategy
        return "optimal" if n <= OPTIMAL_MAX_N else "paper"

    def attempts(self, n: int) -> list[tuple[str, str]]:
        """(strategy, placement) pairs tried in turn until one schedules safely.

        An explicit strategy keeps its strategy; the ``default`` placement falls back
        from ``centroid`` to ``front``. The ``default`` strategy tries optimal (small N)
        then paper (whose top-to-bottom ranking schedules well in dense fleets).
        """
        if self.strategy == "banded" or (self.strategy == "default" and n > SCHEDULE_MAX_N):
            return []  # straight to the plan that always exists
        strategies = [self.resolved_strategy(n)]
        if self.strategy == "default" and "paper" not in strategies:
            strategies.append("paper")
        placements = ["centroid", "front"] if self.placement == "default" else [self.placement]
        if self.placement == "default" and n > FRONT_MAX_N:
            placements = ["centroid"]  # "front" makes O(n^1.5) long paths: hours at 10^4
        return [(s, p) for p in placements for s in strategies]
