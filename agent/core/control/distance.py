"""Distance control (NAO paper 4.2, and 5.2.2 (2), distance control).

The planned trajectory ``(eta_i, d_i)`` is walked open-loop in steps of at most
``d_stp = 20 cm`` (paper Table 2: longer segments do not stay straight); after each
step the heading is corrected with the rotation control (kD = 0).

The agent keeps a dead-reckoned belief of its own position in its fixed frame: each
step moves it by the commanded distance along the believed heading (the mean of the
compass-measured heading before and after the step). The correction after a step
re-aims at the goal from that belief, so a heading drift measured by the compass is
also corrected in position, not only in direction. Pure: no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from agent.core.control.rotation import wrap_pi

STEP_LENGTH = 0.20  # metres, the paper's d_stp
ARRIVE_TOLERANCE = 0.02  # metres: closer than this to the goal counts as arrived


def split_distance(distance: float, step: float = STEP_LENGTH) -> list[float]:
    """``distance`` (m, >= 0) cut into equal open-loop steps no longer than ``step``.

    Equal steps rather than ``step, step, ..., rest``: a tiny last step walks badly.
    """
    if not math.isfinite(distance) or distance < 0.0:
        raise ValueError(f"distance {distance} m must be finite and >= 0")
    if not math.isfinite(step) or step <= 0.0:
        raise ValueError(f"step {step} m must be finite and > 0")
    if distance == 0.0:
        return []
    n = math.ceil(distance / step - 1e-9)
    return [distance / n] * n


@dataclass(frozen=True)
class Leg:
    """What to do next towards a goal: turn by ``turn`` (rad, + CCW), then walk ``walk`` m."""

    turn: float
    walk: float
    heading: float  # the heading (fixed frame, rad) to hold while walking
    remaining: float  # distance to the goal before this leg (m)


def _xy(p: np.ndarray | tuple[float, float], name: str) -> np.ndarray:
    a = np.asarray(p, dtype=np.float64)
    if a.shape != (2,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be a finite (2,) position in metres, got {a!r}")
    return a


def next_leg(
    position: np.ndarray | tuple[float, float],
    heading: float,
    goal: np.ndarray | tuple[float, float],
    step: float = STEP_LENGTH,
    tolerance: float = ARRIVE_TOLERANCE,
    backward_within: float = 0.0,
) -> Leg | None:
    """The next leg from ``position`` with ``heading`` (fixed frame) towards ``goal``.

    ``None`` when within ``tolerance`` of the goal. The walk is the next equal step
    of :func:`split_distance` for the remaining distance. A goal behind the robot and
    closer than ``backward_within`` is reached by stepping backwards (negative walk)
    instead of turning round: small corrections need no half turn.
    """
    p = _xy(position, "position")
    g = _xy(goal, "goal")
    if not math.isfinite(heading):
        raise ValueError(f"heading {heading} is not finite")
    if not math.isfinite(tolerance) or tolerance <= 0.0:
        raise ValueError(f"tolerance {tolerance} m must be finite and > 0")
    delta = g - p
    remaining = float(np.hypot(delta[0], delta[1]))
    if remaining <= tolerance:
        return None
    want = math.atan2(float(delta[1]), float(delta[0]))
    steps = split_distance(remaining, step)
    turn = wrap_pi(want - heading)
    if abs(turn) > math.pi / 2 and remaining < backward_within:
        back = wrap_pi(want + math.pi)
        return Leg(turn=wrap_pi(back - heading), walk=-steps[0], heading=back, remaining=remaining)
    return Leg(turn=turn, walk=steps[0], heading=want, remaining=remaining)


def advance(
    position: np.ndarray | tuple[float, float],
    heading_before: float,
    heading_after: float,
    walked: float,
) -> np.ndarray:
    """Dead reckoning for one straight step of ``walked`` metres.

    The body is assumed to have drifted uniformly from ``heading_before`` to
    ``heading_after`` during the step, so it moved along their circular mean.
    """
    p = _xy(position, "position")
    for name, v in (("heading_before", heading_before), ("heading_after", heading_after)):
        if not math.isfinite(v):
            raise ValueError(f"{name} {v} is not finite")
    if not math.isfinite(walked):
        raise ValueError(f"walked distance {walked} is not finite")
    mean = heading_before + 0.5 * wrap_pi(heading_after - heading_before)
    return p + walked * np.array([math.cos(mean), math.sin(mean)])
