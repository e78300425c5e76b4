"""What looking costs a NAO on the world clock: head turn, settling and capture
(docs/world.md "Clock"; docs/design.md §4; the NAO paper 3.2 sweeps the head to search).

A real NAO asked for a picture at a head yaw turns its head there, waits for the joint to
settle and takes the camera's next frame; the simulated world charges the same time
(:class:`LookTiming`, from NAO datasheet values):

- **head turn**: ``|yaw - current yaw| / (fraction x HeadYaw's maximum speed)``.
  HeadYaw's maximum joint speed is 8.27 rad/s (Aldebaran's NAO H25 joint table,
  ``ALMotion.getLimits("HeadYaw")``: 8.26797 rad/s, no load). Motion commands do not run
  at it: ``ALMotion.setAngles`` moves a joint at the fraction of that speed it is given,
  and the agent gives :data:`agent.core.nao.HEAD_SPEED_FRACTION` = 0.3 (a steady head
  and little wear; :mod:`agent.body.naoqi`), so the head turns at 2.48 rad/s (a 30°
  sweep step takes 0.21 s, the full ±119.5° 1.7 s). The speed is held constant over the
  move: setAngles' interpolation ramps in and out, which the settling time covers.
- **settling**: :data:`SETTLE_S` = 0.1 s once the head moved at all: the joint's
  position loop closing to within the 1° the agent waits for (the NAO's DCM runs a
  10 ms cycle and ALMotion a 20 ms one: five motion cycles). Not a datasheet value: a
  chosen one, stated here as such.
- **capture**: :data:`CAPTURE_S` = 0.05 s: the top camera streams at 30 fps in VGA (the
  NAO's camera datasheet, MT9M114: 30 fps at 640x480), so a frame starts on average
  half a frame period after the head has settled and is read out one frame period
  later: 1.5 / 30 s. Also charged when the head does not move (a second picture at
  the same yaw).

**One clock, many robots.** The world has one clock for every robot; each robot's
actions take their own time on it and run concurrently with the other robots', as on
a real fleet. A look is one such action, like a walk: when the world receives a camera
request it starts a *glance* ending at ``now + cost`` (the cost depends only on the
robot's head yaw and the asked one); the clock advances in the locomotion's fixed
steps while any walk, turn or glance is in flight; the picture is drawn at the first
step at or after the glance's end, from the world as it is then, and answered with that
time (``CameraReply.t_sim``). Glances due at the same step are taken in (end time,
robot id) order. A glance occupies its robot's head: a repeat of the request at the
same yaw takes over the glance (the older query is told it was superseded), another
yaw is told the world is busy. Walking and looking may overlap (legs and head are
different joints). Nothing here reads wall time, so the clock stays deterministic: the
same requests in the same order give the same times and pictures.

``python -m sim --free-looks`` turns the charge off (pictures at once, at the current
time: recordings made before it); the in-process :meth:`sim.physics.world.World.render` never
charges time, and neither do the separate render workers of :mod:`sim.server.render_worker`,
which answer camera queries without the world's clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Generic, TypeVar

from agent.wire import nao
from sim.server.pending_pictures import Admission

#: HeadYaw's maximum joint speed (rad/s; NAO H25 joint table, ``ALMotion.getLimits``).
HEAD_YAW_MAX_SPEED = 8.26797
#: Settling time (s) after a head move (module docstring: a chosen value).
SETTLE_S = 0.1
#: Frame rate (fps) of the top camera in VGA (NAO camera datasheet).
CAMERA_FPS = 30.0
#: Capture time (s): half a frame period to the next frame, one to read it out.
CAPTURE_S = 1.5 / CAMERA_FPS

Q = TypeVar("Q")


@dataclass(frozen=True)
class LookTiming:
    """The time a look costs (module docstring); ``speed`` in rad/s, times in s."""

    speed: float = nao.HEAD_SPEED_FRACTION * HEAD_YAW_MAX_SPEED
    settle: float = SETTLE_S
    capture: float = CAPTURE_S

    def __post_init__(self) -> None:
        if not (math.isfinite(self.speed) and self.speed > 0):
            raise ValueError(f"head speed {self.speed} must be > 0")
        for name in ("settle", "capture"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} time {v} must be >= 0")

    def cost(self, from_yaw: float, to_yaw: float) -> float:
        """Seconds from the request to the picture: turn, settle (if it turned), capture."""
        turn = abs(float(to_yaw) - float(from_yaw))
        if not math.isfinite(turn):
            raise ValueError(f"head yaw {from_yaw} -> {to_yaw} is not finite")
        moving = turn / self.speed + self.settle if turn > 0.0 else 0.0
        return moving + self.capture


@dataclass
class Glance(Generic[Q]):
    """A look in flight: robot ``robot_id`` turning to ``yaw`` from ``t_start``; its
    picture is due at ``t_end``, for ``query``."""

    query: Q
    robot_id: int
    yaw: float
    t_start: float
    t_end: float


class Glances(Generic[Q]):
    """The looks in flight, at most one per robot (module docstring)."""

    def __init__(self, timing: LookTiming | None = None) -> None:
        self.timing = timing if timing is not None else LookTiming()
        self._by_robot: dict[int, Glance[Q]] = {}
        self.charged = 0.0  # seconds of looking charged, all robots together

    def __len__(self) -> int:
        return len(self._by_robot)

    def start(
        self, query: Q, robot_id: int, yaw: float, from_yaw: float, now: float
    ) -> tuple[Admission, Q | None]:
        """Start robot ``robot_id``'s look at ``yaw`` (its head at ``from_yaw``) at time
        ``now``: ``NEW``; a repeat at the yaw in flight: ``REBOUND`` and the query it
        supersedes; another yaw while one is in flight: ``BUSY``."""
        g = self._by_robot.get(robot_id)
        if g is not None:
            if g.yaw == yaw:
                old, g.query = g.query, query
                return Admission.REBOUND, old
            return Admission.BUSY, None
        cost = self.timing.cost(from_yaw, yaw)
        self.charged += cost
        self._by_robot[robot_id] = Glance(query, robot_id, yaw, now, now + cost)
        return Admission.NEW, None

    def due(self, now: float) -> list[Glance[Q]]:
        """The glances that end at or before ``now`` (removed), by (end time, robot id).

        ``now`` is a multiple of the clock's step, summed in floating point: an end
        within 1e-9 s of it counts as reached."""
        ready = sorted(
            (g for g in self._by_robot.values() if g.t_end <= now + 1e-9),
            key=lambda g: (g.t_end, g.robot_id),
        )
        for g in ready:
            del self._by_robot[g.robot_id]
        return ready

    def drain(self) -> list[Glance[Q]]:
        """Every glance in flight (removed), by robot id: the world is stopping."""
        out = [self._by_robot[r] for r in sorted(self._by_robot)]
        self._by_robot.clear()
        return out
