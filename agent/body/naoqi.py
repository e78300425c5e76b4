"""The NAOqi body: a :class:`~agent.seams.Body` on a NAO over the qi protocol (a real NAO).

The only agent module that imports ``qi`` (the libqi Python bindings). It drives a real
NAO (``tcp://nao.local:9559``) or a virtual one served by ``python -m sim --naoqi``
(:mod:`sim.naoqi_gateway`) through the NAOqi API:

- start: ``ALMotion.wakeUp``, ``ALRobotPosture.goToPosture("StandInit")``,
  ``ALMotion.moveInit``; ``ALVideoDevice.subscribeCamera`` on the top (forehead)
  camera at kVGA (640×480) in kBGRColorSpace;
- camera at a head yaw: ``ALMotion.setAngles("HeadYaw", yaw, 0.3)``, wait until the
  joint sensor reads the target (``getAngles(..., True)``), then
  ``ALVideoDevice.getImageRemote``; the frame carries the yaw the sensor read;
- walk and turn: ``ALMotion.moveTo(x, 0, 0)`` and ``moveTo(0, 0, theta)`` (blocking).
  ``moveTo`` returning ``False`` (NAOqi ≥ 2.5: the move was interrupted, e.g. by the
  robot's collision protection) is a ``contact``;
- stop: ``ALMotion.stopMove``; close: unsubscribe the camera, close the session.

Limits are checked before anything moves: head yaw within ±119.5° (``ValueError``), one
walk at most 50 m (the protocol's bound). Every qi error (connection lost, a service
missing, a method refusing) becomes a :class:`~agent.seams.BodyError`. The session is
closed explicitly, also at interpreter exit (``atexit``): a bare qi session left to
Python's finalisation can end the process with "terminate called without an active
exception" (tests/body/test_naoqi.py checks a process that never calls ``close``).
"""

from __future__ import annotations

import atexit
import contextlib
import math
import time
from collections.abc import Callable, Sequence
from typing import TypeVar

import numpy as np
import qi

from agent.body.base import BodyError, Frame, MotionResult
from agent.core import nao
from agent.wire import MAX_SIDE_STEP, MAX_STEP

T = TypeVar("T")

HEAD_TOLERANCE = math.radians(1.0)  # the head has reached its target
HEAD_SETTLE_S = 3.0  # longest wait for the head (a full 239° sweep at 0.3 takes ~1 s)
HEAD_START_S = 0.15  # a head that has not moved this long after setAngles has stopped
CAMERA_FPS = 15  # ALVideoDevice subscription rate


def _call(action: str, fn: Callable[[], T]) -> T:
    """``fn()``, its qi errors (``RuntimeError`` and friends) as :class:`BodyError`."""
    try:
        return fn()
    except BodyError:
        raise
    except Exception as exc:
        raise BodyError(action, f"{type(exc).__name__}: {exc}") from None


class NaoqiBody:
    """Robot ``robot_id`` is the NAO at ``url`` (``tcp://HOST:9559``)."""

    def __init__(
        self,
        url: str,
        robot_id: int,
        timeout: float = 10.0,
        clock_error: float = nao.NTP_CLOCK_ERROR,
    ) -> None:
        if not (math.isfinite(clock_error) and 0.0 <= clock_error <= 10.0):
            raise ValueError(f"clock_error must be in [0, 10] s, got {clock_error!r}")
        self._robot_id = robot_id
        self._clock_error = clock_error
        self.url = url
        self._t_sim = 0.0
        self.contacts = 0
        self._handle = ""
        self._closed = False
        qi.logging.setLevel(qi.logging.WARNING)  # libqi's info lines are not ours
        self.session = qi.Session()
        atexit.register(self.close)
        try:
            fut = self.session.connect(url, _async=True)
            state = fut.wait(int(timeout * 1000))
            if state == qi.FutureState.FinishedWithError:
                raise BodyError("connect", f"no NAOqi at {url}: {fut.error()}")
            if state != qi.FutureState.FinishedWithValue:
                fut.cancel()
                raise BodyError("connect", f"no NAOqi at {url} within {timeout:g} s")
            self.motion = _call("connect", lambda: self.session.service("ALMotion"))
            self.video = _call("connect", lambda: self.session.service("ALVideoDevice"))
            self.posture = _call("connect", lambda: self.session.service("ALRobotPosture"))
            _call("ALMotion.wakeUp", self.motion.wakeUp)
            ok = _call(
                "ALRobotPosture.goToPosture",
                lambda: self.posture.goToPosture(nao.POSTURE_STAND_INIT, 0.5),
            )
            if ok is False:
                raise BodyError("ALRobotPosture.goToPosture", "StandInit not reached")
            _call("ALMotion.moveInit", self.motion.moveInit)
            self._handle = _call(
                "ALVideoDevice.subscribeCamera",
                lambda: self.video.subscribeCamera(
                    f"nao_formation_{robot_id}",
                    nao.TOP_CAMERA,
                    nao.RESOLUTION_VGA,
                    nao.COLORSPACE_BGR,
                    CAMERA_FPS,
                ),
            )
        except BodyError:
            self.close()
            raise
        except Exception as exc:
            self.close()
            raise BodyError("connect", f"{url}: {type(exc).__name__}: {exc}") from None

    @property
    def robot_id(self) -> int:
        return self._robot_id

    @property
    def t_sim(self) -> float:
        return self._t_sim

    @property
    def clock_error(self) -> float:
        """The bound of this NAO's clock against its fleet's (``nao.NTP_CLOCK_ERROR``
        unless given)."""
        return self._clock_error

    # ------------------------------------------------------------------ camera

    def camera(self, yaw: float) -> Frame:
        """The top-camera image with the head at ``yaw`` (rad, + left, within ±119.5°)."""
        if not math.isfinite(yaw) or abs(yaw) > nao.HEAD_YAW_LIMIT + 1e-9:
            raise ValueError(f"head yaw {yaw} rad outside ±{math.degrees(nao.HEAD_YAW_LIMIT):.1f}°")
        what = f"camera at yaw {math.degrees(yaw):.1f}°"
        self._open(what)
        _call(
            "ALMotion.setAngles",
            lambda: self.motion.setAngles(nao.HEAD_YAW_JOINT, float(yaw), nao.HEAD_SPEED_FRACTION),
        )
        applied = self._head_settled(yaw)
        settled_at = self._robot_time()
        # the camera streams: an image stamped before the head settled was taken while
        # it moved (a real NAO's frame can be a frame period old); take the next one
        for _ in range(5):
            raw = _call(
                "ALVideoDevice.getImageRemote", lambda: self.video.getImageRemote(self._handle)
            )
            img, t = self._decode(what, raw)
            if t >= settled_at - 1e-3:  # getTime is a float32 on the wire
                break
            time.sleep(1.0 / CAMERA_FPS)
        self._t_sim = max(self._t_sim, t)
        return Frame(img, applied, t)

    def _head_settled(self, target: float) -> float:
        """The HeadYaw sensor once it reads ``target``, or has stopped short of it (a
        joint at its mechanical stop, backlash) after ``HEAD_START_S``."""
        start = time.monotonic()
        last = math.inf
        while True:
            now = self._read_head()
            waited = time.monotonic() - start
            if abs(now - target) <= HEAD_TOLERANCE:
                return now
            if waited > HEAD_START_S and abs(now - last) < 1e-4:
                return now
            if waited > HEAD_SETTLE_S:
                raise BodyError("HeadYaw", f"at {math.degrees(now):.1f}°, not at the target")
            last = now
            time.sleep(0.02)

    def _robot_time(self) -> float:
        """The robot's clock (``ALMotion.getTime``; sim time on a virtual NAO), or this
        computer's monotonic clock on a NAOqi without it."""
        try:
            return float(self.motion.getTime(0))
        except Exception:
            return time.monotonic()

    def _read_head(self) -> float:
        vals = _call("ALMotion.getAngles", lambda: self.motion.getAngles(nao.HEAD_YAW_JOINT, True))
        # the sensor (a float32 on the wire) may read a hair beyond the joint's range
        lim = nao.HEAD_YAW_LIMIT
        return min(lim, max(-lim, float(vals[0])))

    @staticmethod
    def _decode(what: str, raw: Sequence[object]) -> tuple[np.ndarray, float]:
        """The NAOqi image array → (BGR image, timestamp in s)."""
        if raw is None or len(raw) < 7:
            raise BodyError(what, "no image (ALVideoDevice returned nothing)")
        w, h, layers, space, sec, usec, data = raw[:7]
        if not isinstance(data, bytes | bytearray):
            raise BodyError(what, f"image data of type {type(data).__name__}")
        if (layers, space) != (3, nao.COLORSPACE_BGR) or not isinstance(w, int):
            raise BodyError(what, f"image of {layers} layers in colour space {space}, not BGR")
        if not isinstance(h, int) or len(data) != w * h * 3:
            raise BodyError(what, f"image of {len(data)} bytes for {w}x{h}")
        img = np.frombuffer(bytes(data), dtype=np.uint8).reshape(h, w, 3)
        t = float(sec) + float(usec) * 1e-6  # type: ignore[arg-type]
        return img, t

    # ------------------------------------------------------------------ motion

    def new_request_id(self) -> int:
        """0: NAOqi has no request ids (a motion in flight at a crash counts as executed)."""
        return 0

    def walk(self, distance: float, request_id: int = 0) -> MotionResult:
        """``ALMotion.moveTo(distance, 0, 0)``: straight ahead (< 0: backwards); the
        request id is ignored (NAOqi has none)."""
        if not math.isfinite(distance) or abs(distance) > MAX_STEP:
            raise ValueError(f"walk distance {distance} m outside ±{MAX_STEP:g} m")
        return self._move("walk", distance, 0.0)

    def side(self, distance: float, request_id: int = 0) -> MotionResult:
        """``ALMotion.moveTo(0, distance, 0)``: sideways (+ left); the request id is
        ignored."""
        if not math.isfinite(distance) or abs(distance) > MAX_SIDE_STEP:
            raise ValueError(f"sidestep {distance} m outside ±{MAX_SIDE_STEP:g} m")
        return self._move("side", 0.0, 0.0, distance)

    def turn(self, angle: float, request_id: int = 0) -> MotionResult:
        """``ALMotion.moveTo(0, 0, angle)``: on the spot (+ CCW); the request id is ignored."""
        if not math.isfinite(angle) or abs(angle) > 4 * math.pi:
            raise ValueError(f"turn angle {angle} rad outside ±4π")
        return self._move("turn", 0.0, angle)

    def _move(self, what: str, x: float, theta: float, y: float = 0.0) -> MotionResult:
        self._open(what)
        ok = _call(f"{what} (ALMotion.moveTo)", lambda: self.motion.moveTo(x, y, theta))
        t = self._robot_time()
        self._t_sim = max(self._t_sim, t)
        if ok is False:
            self.contacts += 1
            return MotionResult("contact", t, "ALMotion.moveTo was interrupted")
        return MotionResult("done", t)

    def stop(self) -> None:
        """``ALMotion.stopMove`` (harmless when the robot stands)."""
        if not self._closed:
            _call("ALMotion.stopMove", self.motion.stopMove)

    def _open(self, what: str) -> None:
        if self._closed:
            raise BodyError(what, f"the session to {self.url} is closed")

    def close(self) -> None:
        """Unsubscribe the camera and close the session (idempotent)."""
        if self._closed:
            return
        self._closed = True
        with contextlib.suppress(Exception):
            atexit.unregister(self.close)
        if self._handle:
            with contextlib.suppress(Exception):
                self.video.unsubscribe(self._handle)
        with contextlib.suppress(Exception):
            self.session.close()
