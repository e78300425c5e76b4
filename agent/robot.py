"""The body an agent drives (DESIGN.md §2): forehead camera at a head yaw, walk, turn.

Each action is a query to the world's queryables (``world/robot/{id}/camera|walk|turn``,
DESIGN.md §3); walk and turn replies arrive when the motion has finished in sim time.
The body reports no pose: the agent knows only what it commanded and what it sees.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

import cv2
import numpy as np

from agent.bus import Bus, BusError, NoRoute
from agent.protocol import (
    HEAD_YAW_LIMIT,
    KEY_WORLD_REGISTER,
    CameraReply,
    CameraRequest,
    CommandReply,
    RegisterReply,
    RegisterRequest,
    TurnRequest,
    WalkRequest,
    key_camera,
    key_turn,
    key_walk,
)


class RobotError(RuntimeError):
    """The world refused or failed a request for this robot; the text says why."""


T = TypeVar("T")


def retry_no_route(call: Callable[[], T], deadline_s: float, first_wait: float = 0.05) -> T:
    """``call()``, repeated with backoff while it raises :class:`NoRoute`, until ``deadline_s``.

    A query that met no queryable executed nothing, so repeating it is safe; the papers
    assume lossless WiFi, but on a lossy link zenoh rebuilds routes and queries made
    meanwhile end at once with no reply. Any other error is raised at once.
    """
    end = time.monotonic() + deadline_s
    wait = first_wait
    while True:
        try:
            return call()
        except NoRoute:
            if time.monotonic() + wait > end:
                raise
            time.sleep(wait)  # back off before asking the network again
            wait = min(wait * 2.0, 1.0)


@dataclass(frozen=True)
class Frame:
    """One camera image (BGR uint8, (H, W, 3)) with the head yaw and sim time it was taken."""

    image: np.ndarray
    yaw: float
    t_sim: float


def register(bus: Bus, want: int = -1, timeout: float = 10.0) -> int:
    """Claim a free robot of the scenario from the world (``--id auto``)."""
    try:
        reply = retry_no_route(
            lambda: bus.query(
                KEY_WORLD_REGISTER, RegisterRequest(want=want), RegisterReply, timeout
            ),
            timeout,
        )
    except BusError as exc:
        raise RobotError(f"cannot register with the world: {exc}") from None
    return reply.robot_id


class Robot:
    """Camera, walk and turn of robot ``robot_id`` through the world process."""

    def __init__(
        self,
        bus: Bus,
        robot_id: int,
        camera_timeout: float = 30.0,
        motion_timeout: float = 300.0,
    ) -> None:
        self.bus = bus
        self.robot_id = robot_id
        self.camera_timeout = camera_timeout
        self.motion_timeout = motion_timeout
        self.t_sim = 0.0
        self.contacts = 0

    def camera(self, yaw: float) -> Frame:
        """The forehead image with the head at ``yaw`` (rad, + left, |yaw| <= 119.5°)."""
        if not math.isfinite(yaw) or abs(yaw) > HEAD_YAW_LIMIT + 1e-9:
            raise ValueError(f"head yaw {yaw} rad outside ±119.5°")
        try:
            rep = retry_no_route(
                lambda: self.bus.query(
                    key_camera(self.robot_id),
                    CameraRequest(yaw=yaw),
                    CameraReply,
                    self.camera_timeout,
                ),
                self.camera_timeout,
            )
        except BusError as exc:
            raise RobotError(f"camera at yaw {math.degrees(yaw):.1f}°: {exc}") from None
        buf = np.frombuffer(rep.data, dtype=np.uint8)
        img = cv2.imdecode(buf, cv2.IMREAD_COLOR)
        if img is None or img.shape != (rep.height, rep.width, 3):
            raise RobotError(f"camera at yaw {math.degrees(yaw):.1f}°: undecodable image")
        self.t_sim = max(self.t_sim, rep.t_sim)
        return Frame(img, rep.yaw, rep.t_sim)

    def walk(self, distance: float) -> CommandReply:
        """Walk ``distance`` m straight ahead; returns when done (status done|contact)."""
        return self._motion(key_walk(self.robot_id), WalkRequest(distance=distance), "walk")

    def turn(self, angle: float) -> CommandReply:
        """Turn on the spot by ``angle`` rad (+ CCW); returns when done."""
        return self._motion(key_turn(self.robot_id), TurnRequest(angle=angle), "turn")

    def _motion(self, key: str, req: WalkRequest | TurnRequest, what: str) -> CommandReply:
        try:
            # Safe to repeat: NoRoute means the command reached no queryable (it ended
            # within bus.NO_ROUTE_WINDOW with no reply), so the world never started it.
            rep = retry_no_route(
                lambda: self.bus.query(key, req, CommandReply, self.motion_timeout), 30.0
            )
        except BusError as exc:
            raise RobotError(f"{what}: {exc}") from None
        if rep.status == "error":
            raise RobotError(f"{what}: world reports error: {rep.detail}")
        if rep.status == "contact":
            self.contacts += 1
        self.t_sim = max(self.t_sim, rep.t_sim)
        return rep
