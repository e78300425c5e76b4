"""Rotation control (NAO paper 4.2, and 5.2.2 (1), rotation control).

A PD(-I) loop on the rotation still to do, with the visual compass as feedback:
the robot must turn by ``theta``; after each commanded step the compass reports the
rotation actually completed, ``theta_hat`` (eq. 2 summed over steps), the error is
``e = theta - theta_hat`` and the next step is

    u_k = kP * e_k + kI * sum(e) + kD * (e_k - e_{k-1}),   |u_k| <= 15°

(paper: ``theta_stp = min{15°, theta - theta_hat}``, kP = 1.0, kI = 0, kD = 0.2) until
``|e| <= tolerance``. On the first step ``e_{k-1} = e_k`` (no derivative kick). The
distance control uses the same loop with kD = 0.

The controller is pure: it never turns anything. The caller commands ``next_step()``,
measures the completed rotation and reports it with ``record(completed)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

MAX_STEP = math.radians(15.0)
DEFAULT_TOLERANCE = math.radians(2.0)


def wrap_pi(angle: float) -> float:
    """``angle`` wrapped to [-pi, pi) (radians)."""
    a = float(angle)
    if not math.isfinite(a):
        raise ValueError(f"angle {a} is not finite")
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@dataclass(frozen=True)
class PidGains:
    """Gains of the rotation loop; the paper's are kP 1.0, kI 0, kD 0.2."""

    kp: float = 1.0
    ki: float = 0.0
    kd: float = 0.2

    def __post_init__(self) -> None:
        for name in ("kp", "ki", "kd"):
            v = getattr(self, name)
            if not math.isfinite(v) or v < 0.0:
                raise ValueError(f"gain {name} must be finite and >= 0, got {v}")
        if self.kp == 0.0:
            raise ValueError("gain kp must be > 0 (the loop would never move)")


PAPER_GAINS = PidGains(1.0, 0.0, 0.2)
STEP_GAINS = PidGains(1.0, 0.0, 0.0)  # heading correction in the distance control


@dataclass
class RotationControl:
    """One closed-loop rotation by ``target`` radians (+ = CCW).

    ``max_step``: largest single turn command (15°, limited by the visual compass);
    ``tolerance``: the loop ends when ``|target - completed| <= tolerance``;
    ``max_steps``: the loop gives up (``exhausted``) after that many steps.
    """

    target: float
    gains: PidGains = PAPER_GAINS
    max_step: float = MAX_STEP
    tolerance: float = DEFAULT_TOLERANCE
    max_steps: int = 40
    completed: float = 0.0
    steps: int = 0
    _prev_error: float | None = field(default=None, repr=False)
    _integral: float = field(default=0.0, repr=False)

    def __post_init__(self) -> None:
        if not math.isfinite(self.target):
            raise ValueError(f"rotation target {self.target} is not finite")
        if abs(self.target) > 2.0 * math.pi:
            raise ValueError(f"rotation target {self.target} rad exceeds one full turn")
        if not (math.isfinite(self.max_step) and 0.0 < self.max_step <= math.radians(40.0)):
            raise ValueError(
                f"max_step {self.max_step} rad must be in (0, 40°]: the compass fails beyond"
            )
        if not (math.isfinite(self.tolerance) and 0.0 < self.tolerance < self.max_step):
            raise ValueError(f"tolerance {self.tolerance} rad must be in (0, max_step)")
        if self.max_steps < 1:
            raise ValueError(f"max_steps must be >= 1, got {self.max_steps}")

    @property
    def error(self) -> float:
        """Rotation still to do (rad)."""
        return self.target - self.completed

    @property
    def done(self) -> bool:
        return abs(self.error) <= self.tolerance

    @property
    def exhausted(self) -> bool:
        return not self.done and self.steps >= self.max_steps

    def next_step(self) -> float:
        """The next turn command (rad, clipped to ±max_step); 0.0 once done or exhausted."""
        if self.done or self.exhausted:
            return 0.0
        e = self.error
        prev = e if self._prev_error is None else self._prev_error
        integral = self._integral + e
        u = self.gains.kp * e + self.gains.ki * integral + self.gains.kd * (e - prev)
        # The derivative term may overshoot the error's sign on a large change; never
        # command a turn away from the target.
        if u * e < 0.0:
            u = 0.0
        if u == 0.0:
            u = math.copysign(min(abs(e), self.max_step), e)
        return max(-self.max_step, min(self.max_step, u))

    def record(self, measured: float) -> None:
        """Report the rotation measured for the last step (rad, + = CCW)."""
        if not math.isfinite(measured):
            raise ValueError(f"measured rotation {measured} is not finite")
        if abs(measured) > math.radians(90.0):
            raise ValueError(
                f"measured rotation {math.degrees(measured):.1f}° for one step is implausible"
            )
        e = self.error
        self._integral += e
        self._prev_error = e
        self.completed += measured
        self.steps += 1
