"""The zenoh body (docs/design.md §2–3, §8): a :class:`~agent.seams.Body` on the world process.

Forehead camera at a head yaw, walk, turn. Each action is a query to the world's
queryables (``world/robot/{id}/camera|walk|turn``, docs/design.md §3); walk and turn replies
arrive when the motion has finished in sim time.

Lost replies (a lossy radio): every walk and turn carries a request id, unique to this body
(a random 40-bit start, then counting up, so that a restarted agent does not reuse its
predecessor's ids); a query that times out is asked again with the same id, and the
world executes each (robot, id) once and answers a repeat with the first result. The
agent takes the id first (:meth:`ZenohBody.new_request_id`) and journals it, so that a
restarted agent sends the command in flight again with the same id (a resume that survives a second
crash). A camera query that times out is asked again as it is (a picture moves nothing but the
head, to the same yaw).
The body reports no pose: the agent knows only what it commanded and what it sees.

Render workers (the world's cameras drawn by other processes, for large fleets; docs/world.md
"Render workers"): a camera query goes to one complete queryable (``best``: zenoh's best-matching
target), a render worker when one serves the robot, else the world. Each reply carries the world
time of the poses it was drawn from (``CameraReply.t_sim``); a worker follows the world's poses a
little behind. The pose-time rule: a frame whose poses precede the end of this robot's last motion
(the ``t_sim`` of its last walk or turn reply) shows the robot where it was, and is never
used: the body asks again, after a short pause, until a fresh frame comes or the camera
timeout is spent (then a :class:`BodyError`). Frames refused so are counted in
``stale_frames``. A world whose render queue is full answers ``busy`` and draws nothing;
the body asks again after a growing pause, within the camera timeout (``busy_replies``).
"""

from __future__ import annotations

import logging
import math
import secrets
import time
from collections.abc import Callable
from typing import TypeVar

from agent.body.base import BodyError, Frame, MotionResult
from agent.core.nao import HEAD_YAW_LIMIT
from agent.net.bus import Bus, BusError, Busy, NoRoute, QueryTimeout
from agent.wire import (
    KEY_WORLD_REGISTER,
    MAX_SIDE_STEP,
    MAX_STEP,
    CameraReply,
    CameraRequest,
    CommandReply,
    Message,
    RegisterReply,
    RegisterRequest,
    TurnRequest,
    WalkRequest,
    key_camera,
    key_turn,
    key_walk,
    picture,
)

#: Former name of :class:`~agent.seams.BodyError` (kept for callers of the old API).
RobotError = BodyError

T = TypeVar("T")
M = TypeVar("M", bound=Message)

log = logging.getLogger("agent.body.zenoh_world")

#: Seconds one attempt of a motion query waits for its reply before asking again with
#: the same request id (a repeat of a running motion waits for that motion in the world).
MOTION_ATTEMPT_S = 60.0
#: ... and of a camera query, and all attempts of one camera query together.
CAMERA_ATTEMPT_S = 15.0
#: Pause before asking again for a frame older than the last motion, doubled up to
#: STALE_WAIT_MAX_S (a render worker's poses lag the world's by a publication or two).
STALE_WAIT_S = 0.02
STALE_WAIT_MAX_S = 0.5
#: A busy world (its bounded render queue full, :class:`~agent.net.bus.Busy`) is asked
#: again after this pause, doubling up to BUSY_WAIT_MAX_S, within the camera timeout
#: (at 100 NAOs 36 agents stopped on "world busy: 64 pictures being drawn").
BUSY_WAIT_S = 0.5
BUSY_WAIT_MAX_S = 4.0
CAMERA_TIMEOUT_S = 30.0
#: Seconds of a camera query's attempt per robot of the fleet (so that large fleets wait their
#: turn). The world draws one picture at a time, so in a fleet that searches at once a query waits
#: behind one query of nearly every other robot: 10 NAOs on the 2-core machine at load 34 took
#: ~0.75 s a picture (261 s of search, ~35 pictures each). An attempt shorter than that
#: queue asks again while the first query still waits: the world then draws pictures
#: nobody waits for, and the queue grows (at 100 NAOs every query would time out).
CAMERA_WAIT_PER_ROBOT_S = 1.0


def camera_waits(fleet_size: int | None) -> tuple[float, float]:
    """(one attempt, all attempts) in seconds of a camera query in a fleet of
    ``fleet_size`` robots: (max(15, 1·N), twice that); (15, 30) up to 15 robots and when
    the size is not known."""
    attempt = max(CAMERA_ATTEMPT_S, CAMERA_WAIT_PER_ROBOT_S * (fleet_size or 0))
    return attempt, attempt * CAMERA_TIMEOUT_S / CAMERA_ATTEMPT_S


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


def retry_timeout(
    call: Callable[[float], T], total_s: float, attempt_s: float, what: str
) -> tuple[T, int]:
    """``call(timeout)`` asked again while it raises :class:`QueryTimeout`, each attempt
    waiting at most ``attempt_s``, all of them ``total_s``; (result, attempts).

    Only for calls that are safe to repeat (idempotent, or carrying a request id). Any
    other error, and a timeout past ``total_s``, is raised."""
    end = time.monotonic() + total_s
    attempts = 0
    while True:
        left = end - time.monotonic()
        attempts += 1
        try:
            return call(max(0.1, min(attempt_s, left))), attempts
        except QueryTimeout as exc:
            if time.monotonic() >= end - 0.05:
                raise
            log.warning("%s: %s; asking again (attempt %d)", what, exc, attempts + 1)


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
        raise BodyError("register", f"cannot register with the world: {exc}") from None
    return reply.robot_id


class ZenohBody:
    """Camera, walk and turn of robot ``robot_id`` through the world process.

    Satisfies :class:`agent.seams.Body`; :meth:`stop` and :meth:`close` do nothing: a
    motion ends in the world, and the bus belongs to the caller.
    """

    def __init__(
        self,
        bus: Bus,
        robot_id: int,
        camera_timeout: float = CAMERA_TIMEOUT_S,
        motion_timeout: float = 300.0,
        camera_attempt: float = CAMERA_ATTEMPT_S,
    ) -> None:
        self.bus = bus
        self._robot_id = robot_id
        self.camera_timeout = camera_timeout
        self.camera_attempt = camera_attempt
        self.motion_timeout = motion_timeout
        self._t_sim = 0.0
        #: World time at which this robot's last motion ended (the pose-time rule).
        self.motion_end = 0.0
        self.stale_frames = 0  # frames refused: drawn from poses older than motion_end
        self.busy_replies = 0  # camera queries a busy world refused (asked again later)
        self.contacts = 0
        self._next_request = secrets.randbits(40) + 1
        self.retries = 0  # queries asked again after a timeout

    @property
    def robot_id(self) -> int:
        return self._robot_id

    @property
    def t_sim(self) -> float:
        return self._t_sim

    @property
    def clock_error(self) -> float:
        return 0.0  # the world's one clock

    def camera(self, yaw: float) -> Frame:
        """The forehead image with the head at ``yaw`` (rad, + left, |yaw| <= 119.5°)."""
        if not math.isfinite(yaw) or abs(yaw) > HEAD_YAW_LIMIT + 1e-9:
            raise ValueError(f"head yaw {yaw} rad outside ±{math.degrees(HEAD_YAW_LIMIT):.1f}°")
        what = f"camera at yaw {math.degrees(yaw):.1f}°"
        rep = self._fresh_frame(CameraRequest(yaw=yaw), what)
        try:
            img = picture.picture_of(rep.encoding, rep.width, rep.height, rep.data)
        except ValueError as exc:  # a ProtocolError
            raise BodyError(what, f"undecodable image: {exc}") from None
        self._t_sim = max(self._t_sim, rep.t_sim)
        return Frame(img, rep.yaw, rep.t_sim)

    def _fresh_frame(self, req: CameraRequest, what: str) -> CameraReply:
        """A camera reply drawn from poses no older than the end of the last motion,
        asked again (after a pause) while it is older, within the camera timeout."""
        end = time.monotonic() + self.camera_timeout
        wait, busy_wait = STALE_WAIT_S, BUSY_WAIT_S
        key = key_camera(self.robot_id)
        while True:
            left = max(0.1, end - time.monotonic())
            try:
                rep = self._ask(key, req, CameraReply, left, self.camera_attempt, best=True)
            except Busy as exc:
                self.busy_replies += 1
                if time.monotonic() + busy_wait > end:
                    raise BodyError(what, f"{exc} until the camera timeout") from None
                time.sleep(busy_wait)  # the world's queue drains; nothing was drawn
                busy_wait = min(2.0 * busy_wait, BUSY_WAIT_MAX_S)
                continue
            except BusError as exc:
                raise BodyError(what, str(exc)) from None
            if rep.t_sim >= self.motion_end:
                return rep
            self.stale_frames += 1
            if time.monotonic() + wait > end:
                raise BodyError(
                    what,
                    f"every frame predates the last motion: poses of t={rep.t_sim:.2f} s, "
                    f"the motion ended at t={self.motion_end:.2f} s",
                )
            log.debug("%s: poses of t=%.2f s < motion end %.2f s", what, rep.t_sim, self.motion_end)
            time.sleep(wait)  # the renderer's poses catch up with the world's
            wait = min(2.0 * wait, STALE_WAIT_MAX_S)

    def new_request_id(self) -> int:
        """The next request id of this body (never 0)."""
        rid = self._next_request
        self._next_request += 1
        return rid

    def walk(self, distance: float, request_id: int = 0) -> MotionResult:
        """Walk ``distance`` m straight ahead; returns when done (status done|contact).
        A repeated ``request_id`` is answered with its first result (0: a fresh id)."""
        if not math.isfinite(distance) or abs(distance) > MAX_STEP:
            raise ValueError(f"walk distance {distance} m outside ±{MAX_STEP:g} m")
        req = WalkRequest(distance=distance, request_id=self._id(request_id))
        return self._motion(key_walk(self.robot_id), req, "walk")

    def side(self, distance: float, request_id: int = 0) -> MotionResult:
        """Step ``distance`` m sideways (+ left): a ``WalkRequest`` with ``lateral``;
        returns when done. ``request_id`` as for :meth:`walk`."""
        if not math.isfinite(distance) or abs(distance) > MAX_SIDE_STEP:
            raise ValueError(f"sidestep {distance} m outside ±{MAX_SIDE_STEP:g} m")
        req = WalkRequest(distance=0.0, lateral=distance, request_id=self._id(request_id))
        return self._motion(key_walk(self.robot_id), req, "walk")

    def turn(self, angle: float, request_id: int = 0) -> MotionResult:
        """Turn on the spot by ``angle`` rad (+ CCW); returns when done. ``request_id``
        as for :meth:`walk`."""
        req = TurnRequest(angle=angle, request_id=self._id(request_id))
        return self._motion(key_turn(self.robot_id), req, "turn")

    def stop(self) -> None:
        """Nothing to stop: the world ends each motion itself (it has no cancel)."""

    def close(self) -> None:
        """Nothing to release (the bus is the caller's); says how many frames the
        pose-time rule refused, if any."""
        if self.busy_replies:
            log.info("camera: the world was busy %d time(s); asked again", self.busy_replies)
            self.busy_replies = 0
        if self.stale_frames:
            log.info(
                "camera: %d frame(s) drawn before the last motion ended were asked again",
                self.stale_frames,
            )
            self.stale_frames = 0

    def _id(self, request_id: int) -> int:
        """``request_id``, or a fresh one for 0 (the wire checks the range)."""
        if isinstance(request_id, bool) or not isinstance(request_id, int) or request_id < 0:
            raise ValueError(f"request id {request_id!r} is not an id")
        return request_id or self.new_request_id()

    def _ask(
        self,
        key: str,
        req: Message,
        expect: type[M],
        total_s: float,
        attempt_s: float,
        best: bool = False,
    ) -> M:
        """The query, asked again after a timeout (same request, so the same request id)
        and while it meets no queryable (NoRoute: nothing was executed); ``best``: to one
        complete queryable (a camera: one render worker), see :meth:`Bus.query`."""

        def once(timeout: float) -> M:
            if best:
                return retry_no_route(
                    lambda: self.bus.query(key, req, expect, timeout, best=True), 30.0
                )
            return retry_no_route(lambda: self.bus.query(key, req, expect, timeout), 30.0)

        rep, attempts = retry_timeout(once, total_s, attempt_s, key)
        self.retries += attempts - 1
        return rep

    def _motion(self, key: str, req: WalkRequest | TurnRequest, what: str) -> MotionResult:
        try:
            rep = self._ask(key, req, CommandReply, self.motion_timeout, MOTION_ATTEMPT_S)
        except BusError as exc:
            raise BodyError(what, str(exc)) from None
        self._t_sim = max(self._t_sim, rep.t_sim)
        self.motion_end = max(self.motion_end, rep.t_sim)
        if rep.status == "contact":
            self.contacts += 1
            return MotionResult("contact", rep.t_sim, rep.detail)
        if rep.status != "done":
            raise BodyError(what, f"world reports {rep.status}: {rep.detail}")
        return MotionResult("done", rep.t_sim, rep.detail)


#: Former name of :class:`ZenohBody`.
Robot = ZenohBody
