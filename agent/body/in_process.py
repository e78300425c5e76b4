"""The in-process body: a :class:`~agent.body.base.Body` on an in-process world (the runner's phases
tested without a network).

For tests of the runner's phases without a network (docs/design.md §8 "Bodies"): the same
renders and the same locomotion (noise, contacts) as the world process, called
directly. A motion steps the world's clock until this robot's command has finished;
other robots of the world stand still meanwhile (one agent drives one body).

The world is named by the structural types below (``sim.physics.world.World`` fits them), so
this lowest floor never imports the world: ``sim/`` depends on ``agent.wire``, not the
other way round.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Protocol

import numpy as np

from agent.body.base import BodyError, Frame, MotionResult
from agent.core.nao import HEAD_YAW_LIMIT
from agent.wire import MAX_SIDE_STEP, MAX_STEP


class Finished(Protocol):
    """A motion that ended during one locomotion step (``sim.physics.locomotion.Done``)."""

    @property
    def robot_id(self) -> int: ...
    @property
    def status(self) -> str: ...
    @property
    def t_sim(self) -> float: ...
    @property
    def detail(self) -> str: ...


class Legs(Protocol):
    """The world's locomotion: commands and one step of the clock."""

    def walk(self, robot_id: int, distance: float) -> object: ...
    def side(self, robot_id: int, distance: float) -> object: ...
    def turn(self, robot_id: int, angle: float) -> object: ...
    def step(self) -> tuple[Sequence[Finished], Sequence[object]]: ...


class World(Protocol):
    """What the in-process body needs of the world (``sim.physics.world.World`` has it)."""

    @property
    def t_sim(self) -> float: ...
    @property
    def robot_ids(self) -> Sequence[int]: ...
    @property
    def locomotion(self) -> Legs: ...
    def render(self, robot_id: int, yaw: float) -> np.ndarray: ...
    def head_yaw(self, robot_id: int) -> float: ...


class WorldBody:
    """Robot ``robot_id`` of an in-process ``world``; the caller owns the world."""

    def __init__(self, world: World, robot_id: int, max_motion_s: float = 600.0) -> None:
        self.world = world
        self._robot_id = robot_id
        self.max_motion_s = max_motion_s
        self.contacts = 0

    @property
    def robot_id(self) -> int:
        return self._robot_id

    @property
    def t_sim(self) -> float:
        return self.world.t_sim

    @property
    def clock_error(self) -> float:
        return 0.0  # the world's one clock

    def _check_robot(self, action: str) -> None:
        if self._robot_id not in self.world.robot_ids:
            raise BodyError(action, f"unknown robot {self._robot_id}")

    def camera(self, yaw: float) -> Frame:
        """The rendered forehead image at head ``yaw`` (a ``ValueError`` outside ±119.5°)."""
        if not math.isfinite(yaw) or abs(yaw) > HEAD_YAW_LIMIT + 1e-9:
            raise ValueError(f"head yaw {yaw} rad outside ±{math.degrees(HEAD_YAW_LIMIT):.1f}°")
        what = f"camera at yaw {math.degrees(yaw):.1f}°"
        self._check_robot(what)
        img = self.world.render(self._robot_id, yaw)
        return Frame(img, self.world.head_yaw(self._robot_id), self.world.t_sim)

    def new_request_id(self) -> int:
        """0: the in-process world keeps no request ids (a motion always runs to its end
        within the call)."""
        return 0

    def walk(self, distance: float, request_id: int = 0) -> MotionResult:
        """Walk ``distance`` m straight ahead (the request id is ignored)."""
        if not math.isfinite(distance) or abs(distance) > MAX_STEP:
            raise ValueError(f"walk distance {distance} m outside ±{MAX_STEP:g} m")
        return self._motion("walk", distance)

    def side(self, distance: float, request_id: int = 0) -> MotionResult:
        """Step ``distance`` m sideways (+ left; the request id is ignored)."""
        if not math.isfinite(distance) or abs(distance) > MAX_SIDE_STEP:
            raise ValueError(f"sidestep {distance} m outside ±{MAX_SIDE_STEP:g} m")
        return self._motion("side", distance)

    def turn(self, angle: float, request_id: int = 0) -> MotionResult:
        """Turn on the spot by ``angle`` rad (the request id is ignored)."""
        if not math.isfinite(angle):
            raise ValueError(f"turn angle {angle} is not finite")
        return self._motion("turn", angle)

    def stop(self) -> None:
        """Nothing runs between calls: every motion has finished when it returns."""

    def close(self) -> None:
        """The world is the caller's."""

    def _motion(self, what: str, amount: float) -> MotionResult:
        self._check_robot(what)
        loco = self.world.locomotion
        try:
            if what == "walk":
                loco.walk(self._robot_id, amount)
            elif what == "side":
                loco.side(self._robot_id, amount)
            else:
                loco.turn(self._robot_id, amount)
        except ValueError as exc:  # the world refuses (busy, too far)
            raise BodyError(what, str(exc)) from None
        end = self.world.t_sim + self.max_motion_s
        while self.world.t_sim < end:
            done, _ = loco.step()
            for d in done:
                if d.robot_id == self._robot_id:
                    if d.status == "contact":
                        self.contacts += 1
                        return MotionResult("contact", d.t_sim, d.detail)
                    return MotionResult("done", d.t_sim, d.detail)
        raise BodyError(what, f"not finished after {self.max_motion_s:g} s of sim time")
