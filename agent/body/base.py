"""The Body protocol: one NAO's camera and legs as the agent drives them (docs/design.md §8
"Bodies").

Implemented by :class:`agent.body.zenoh_world.ZenohBody` (the world's queryables over
zenoh), :class:`agent.body.naoqi.NaoqiBody` (a real or virtual NAO over the qi protocol)
and :class:`agent.body.in_process.WorldBody` (an in-process world, for tests). Results
and errors are dataclasses: a body raises :class:`BodyError` when the robot or its world
refuses or fails an action, and ``ValueError`` for a request that is wrong before
anything is sent (a head yaw outside ±119.5°, a non-finite distance).

Motion request ids (so that a resume that survives a second crash never walks twice;
docs/faults.md): the agent journals each walk or turn with its request id *before* sending it
(:meth:`Body.new_request_id`), so that after a crash it can send the command in flight again with
the same id. A body with ids (the zenoh world) has each id executed once and answers a repeat with
the first result: the robot never moves twice. A body without them (NAOqi, the in-process world)
hands out 0 and ignores the id; a command in flight at a crash then counts as executed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np


@dataclass(frozen=True)
class Frame:
    """One camera image (BGR uint8, (H, W, 3)), the head yaw actually applied (rad) and
    the robot's time when it was taken (sim time in the simulation)."""

    image: np.ndarray
    yaw: float
    t_sim: float


@dataclass(frozen=True)
class MotionResult:
    """How a walk or turn ended: ``done``, or ``contact`` (stopped by a contact or, on a
    NAO, by its own move-failure protection), at the robot's time ``t_sim``."""

    status: Literal["done", "contact"]
    t_sim: float
    detail: str = ""


@dataclass(eq=False)
class BodyError(RuntimeError):
    """The robot (or its world) refused or failed ``action``; ``reason`` says why."""

    action: str
    reason: str

    def __post_init__(self) -> None:
        super().__init__(str(self))

    def __str__(self) -> str:
        return f"{self.action}: {self.reason}"


class Body(Protocol):
    """One NAO's body as the agent drives it. Actions block until they are over."""

    @property
    def robot_id(self) -> int: ...

    @property
    def t_sim(self) -> float:
        """The latest robot time seen (s)."""
        ...

    @property
    def clock_error(self) -> float:
        """How far this robot's time may be from its fleet's (s): 0 for a simulated body
        (the world's one clock); on a NAO, the bound of its clock synchronisation."""
        ...

    def camera(self, yaw: float) -> Frame:
        """The forehead image with the head turned to ``yaw`` (rad, + left, ±119.5°)."""
        ...

    def new_request_id(self) -> int:
        """A fresh id for the next walk or turn (to journal before sending it); 0 when
        this body cannot tell a repeated motion from a new one."""
        ...

    def walk(self, distance: float, request_id: int = 0) -> MotionResult:
        """Walk ``distance`` m straight ahead (< 0: backwards). ``request_id``: from
        :meth:`new_request_id` or journaled before a crash (0: a fresh one); a body with
        ids answers a repeat of an id with its first result, without moving again."""
        ...

    def side(self, distance: float, request_id: int = 0) -> MotionResult:
        """Step ``distance`` m sideways (+ to the left, at most ``MAX_SIDE_STEP``; NAOqi's
        ``moveTo(0, y, 0)``); ``request_id`` as for :meth:`walk`."""
        ...

    def turn(self, angle: float, request_id: int = 0) -> MotionResult:
        """Turn on the spot by ``angle`` rad (+ CCW); ``request_id`` as for :meth:`walk`."""
        ...

    def stop(self) -> None:
        """Stop walking (idempotent; harmless when idle)."""
        ...

    def close(self) -> None:
        """Release the connection (idempotent)."""
        ...
