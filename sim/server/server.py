"""The world on the bus: zenoh queryables and publications of docs/design.md §3.

Queryables (payloads are :mod:`agent.wire` messages; what a query may carry and how it
is authenticated and checked: :mod:`sim.server.requests`):

- ``world/register``: ``RegisterRequest(want)`` -> ``RegisterReply(robot_id)``: the lowest
  free robot id of the scenario (or ``want`` if it is free); who may claim or drive which
  robot, and how long: :mod:`sim.server.bindings`.
- ``world/robot/{id}/camera``: ``CameraRequest(yaw)`` -> ``CameraReply`` (raw pixels or
  PNG: ``--camera-encoding``). Declared not complete: where render workers serve a
  robot's camera (:mod:`sim.server.render_worker`, complete queryables), a best-matching
  query goes to one of them, and to the world only when none is left.
- ``world/scenario``: ``ScenarioRequest`` -> ``ScenarioReply`` (the scenario as JSON, for
  render workers building their copy of the room; secure: to the ``render`` key only).
- ``world/robot/{id}/walk`` / ``turn``: ``WalkRequest`` (a walk, or a sidestep with
  ``lateral``) / ``TurnRequest`` -> a ``CommandReply(done|contact)`` sent when the motion has finished in sim time. A
  request with a ``request_id`` (> 0) is executed once per (robot, id), so a client may
  retry a motion whose reply it lost (:mod:`sim.server.motions`; the last ``MOTION_CACHE``
  results per robot are kept).

Anything malformed or impossible (unknown robot, NaN, yaw out of range, wrong schema
version, busy robot) gets an ``ErrorReply`` with the reason; the world keeps serving.

**Hardening against hostile input.** The zenoh callbacks check each request cheaply where it
arrives (payload length before the copy, at most ``MAX_REQUEST_BYTES``; robot id; schema;
yaw) and queue it in one of two bounded lanes: well-formed requests, served first, and
malformed ones, answered with their reason when nothing else waits. A full lane drops
its oldest request (counted in ``dropped``; zenoh then ends that query with no reply;
the malformed lane also holds at most ``MALFORMED_MAX_BYTES`` of payloads),
so a flood of garbage can neither grow memory nor delay a valid request by more than
one queue's worth. Every callback survives every exception; rejected input is counted
in ``rejected`` and logged with a reason cut to 200 characters, rate limited. At most
one camera request per robot waits for render workers (:mod:`sim.server.pending_pictures`:
a repeat at the same yaw is answered by the picture in the works, and no robot of the
world is refused for want of room); liveliness tokens of ids that are not robots of this
world are ignored.

Publications: ``world/clock`` (``ClockMsg``) and ``world/truth/poses`` (``TruthPosesMsg``)
at ``truth_rate`` Hz of wall time and after every finished command; ``world/truth/contacts``
(``ContactMsg``) when a contact happens.

**Threads and the clock.** zenoh callbacks only put queries on a queue; one loop owns
PyBullet and the world, and the loop's own state (:class:`sim.server.bindings.RobotBindings`,
:class:`sim.server.motions.Motions`, :class:`sim.server.camera_desk.CameraDesk`): nothing else calls
them. The sim clock advances (in fixed steps of 0.02 s) only while at least one
walk/turn or look is active, as fast as possible by default or paced at ``speed`` x real
time. A camera request is a look: it costs its robot the time a NAO takes to turn its
head there, settle and capture (:mod:`sim.server.glances`), and is answered when that time
has passed on the clock (``free_looks``: at once, costing nothing); drawing the picture
itself costs no sim time. Queued requests are served between steps. With ``reply_delay`` > 0 (a slow world, :mod:`sim.server.delays`)
camera and motion replies are held for a seeded random delay and sent by the same loop
when due, so the world keeps serving meanwhile. With ``render_workers`` > 0 a camera request's state (poses,
head yaws, sim time) is taken when its look ends and the picture drawn by a
:class:`~sim.server.render_pool.RenderPool` worker; its result comes back through the same queue.
"""

from __future__ import annotations

import contextlib
import json
import math
import queue
import sys
import threading
import time
from collections import Counter, defaultdict
from collections.abc import Callable
from typing import Any

import zenoh

from agent.wire import (
    KEY_ALIVE_ALL,
    KEY_WORLD_CLOCK,
    KEY_WORLD_REGISTER,
    KEY_WORLD_SCENARIO,
    KEY_WORLD_TRUTH_CONTACTS,
    KEY_WORLD_TRUTH_POSES,
    CameraRequest,
    ClockMsg,
    ContactMsg,
    ErrorReply,
    Guard,
    Inbox,
    Message,
    NetworkSpec,
    RegisterReply,
    RegisterRequest,
    ScenarioReply,
    ScenarioRequest,
    TruthPosesMsg,
    TurnRequest,
    WalkRequest,
    encode,
    id_from_key,
    picture,
    reason,
    trust,
)
from sim import scenarios
from sim.physics.locomotion import Contact, Done
from sim.physics.world import World
from sim.server.bindings import RobotBindings, Unauthorised
from sim.server.camera_desk import CameraDesk
from sim.server.delays import DelayedReplies
from sim.server.motions import Motions
from sim.server.render_pool import RenderPool
from sim.server.requests import CheckedRequest, Query, Request, check, payload_size

#: How the world joins the bus: the shared :class:`agent.wire.NetworkSpec`.
NetConfig = NetworkSpec


def zenoh_config(spec: NetworkSpec) -> zenoh.Config:
    """The zenoh config of ``spec`` (the world may not import ``agent.net.bus``)."""
    cfg = zenoh.Config()
    for key, value in spec.json5_items():
        cfg.insert_json5(key, value)
    return cfg


#: Lanes of the world's inbox, in the order they are served, and their capacities.
#: ``rendered``: results of render workers (at most the pending pictures' capacity are
#: ever outstanding, and the lane holds at least that many, so it never overflows);
#: ``alive``: liveliness changes;
#: ``valid``: requests that passed the callback's checks; ``malformed``: requests
#: waiting only for an ErrorReply.
INBOX_CAPS = {"rendered": 256, "alive": 1024, "valid": 256, "malformed": 1024}
#: A malformed query keeps its payload (in zenoh's memory) until it is answered: the
#: lane holds at most this many payload bytes; a bigger request is dropped unanswered.
MALFORMED_MAX_BYTES = 16 * 1024 * 1024
#: Results of motions with a request id kept per robot, for repeats (oldest dropped).
MOTION_CACHE = 32


class WorldServer:
    """Serves one :class:`World` over a zenoh session until :meth:`stop`."""

    def __init__(
        self,
        world: World,
        net: NetConfig | None = None,
        *,
        speed: float = 0.0,
        truth_rate: float = 10.0,
        render_workers: int = 0,
        reply_delay: float = 0.0,
        reply_delay_seed: int = 0,
        free_looks: bool = False,
        camera_encoding: str = picture.DEFAULT_ENCODING,
        log: Any = None,
    ) -> None:
        if not (math.isfinite(speed) and speed >= 0):
            raise ValueError(f"speed {speed} must be >= 0 (0: as fast as possible)")
        if not (math.isfinite(truth_rate) and truth_rate > 0):
            raise ValueError(f"truth rate {truth_rate} must be > 0")
        if camera_encoding not in picture.ENCODINGS:
            raise ValueError(f"camera encoding {camera_encoding!r} not one of {picture.ENCODINGS}")
        self.world = world
        self.net = net or NetConfig()
        self.speed = speed
        self.truth_period = 1.0 / truth_rate
        self.log = log if log is not None else sys.stderr
        self.robot_ids = frozenset(world.robot_ids)  # read by the zenoh callbacks
        self.cameras = CameraDesk(
            world,
            self._answer,
            self._reply,
            self._log,
            free_looks=free_looks,
            encoding=camera_encoding,
        )
        cap = self.cameras.pending.capacity
        caps = {**INBOX_CAPS, "rendered": max(INBOX_CAPS["rendered"], cap)}
        self.inbox: Inbox[Any] = Inbox(
            caps, priority=True, max_weight={"malformed": MALFORMED_MAX_BYTES}
        )
        self.guard = Guard(self._log)
        self._drop_log = Guard(self._log, burst=3, per_second=0.2)  # its count: dropped
        self.bindings = RobotBindings(tuple(world.robot_ids))
        self._errors = 0  # with the camera desk's: errors
        self.served = 0
        self.counts: Counter[str] = Counter()  # requests handled, by kind
        self.busy_s: dict[str, float] = defaultdict(float)  # wall seconds on them, by kind
        self.motions = Motions(MOTION_CACHE)
        if isinstance(render_workers, bool) or not 0 <= render_workers <= 16:
            raise ValueError(f"render workers {render_workers!r} must be in [0, 16]")
        self.render_workers = render_workers
        # a slow world: camera and motion replies held back (sim.server.delays); None: at once
        self.delays: DelayedReplies[Request, Message] | None = (
            DelayedReplies(reply_delay, reply_delay_seed) if reply_delay != 0.0 else None
        )
        self._stop = threading.Event()
        self._keep: list[Any] = []
        self.session: Any = None
        self.verifier: trust.Verifier | None = None
        self.signer: trust.Signer | None = None
        self.untrusted = 0  # requests refused by authentication
        if self.net.secure:
            creds = trust.Credentials(self.net.credentials)
            self.signer = creds.signer(trust.Identity("world"))
            self.verifier = creds.verifier()

    # ------------------------------------------------------------------ setup

    def open(self) -> None:
        if self.render_workers > 0:
            self.cameras.pool = RenderPool(
                self.world.scenario,
                self.render_workers,
                self.guard.wrap(lambda r: self._queue("rendered", r), "render result"),
                renderer=self.world.renderer,
                encoding=self.cameras.encoding,
            )
        self.session = zenoh.open(zenoh_config(self.net))
        s = self.session

        def handler(kind: str) -> Callable[[zenoh.Query], None]:
            def on_query(q: zenoh.Query) -> None:
                self.admit(kind, q)

            return on_query

        self._keep.append(s.declare_queryable(KEY_WORLD_REGISTER, handler("register")))
        self._keep.append(s.declare_queryable(KEY_WORLD_SCENARIO, handler("scenario")))
        for kind in ("camera", "walk", "turn"):
            # not complete: a render worker's complete camera queryable is preferred
            q = s.declare_queryable(f"world/robot/*/{kind}", handler(kind), complete=False)
            self._keep.append(q)

        def on_alive(sample: Any) -> None:
            self.admit_alive(sample)

        self._keep.append(s.liveliness().declare_subscriber(KEY_ALIVE_ALL, on_alive, history=True))
        self._pub = {
            k: s.declare_publisher(k, reliability=zenoh.Reliability.RELIABLE)
            for k in (KEY_WORLD_CLOCK, KEY_WORLD_TRUTH_POSES, KEY_WORLD_TRUTH_CONTACTS)
        }

    def summary(self) -> str:
        """One line: requests by kind (mean handling time), errors, contacts, sim time."""
        parts = [
            f"{k}={self.counts[k]} ({1000 * self.busy_s[k] / self.counts[k]:.0f} ms)"
            for k in ("camera", "walk", "turn", "register")
            if self.counts[k]
        ]
        slow = f" delayed={self.delays.held}" if self.delays is not None else ""
        g = self.cameras.glances
        looked = f" looking={g.charged:.2f} s" if g is not None else " free-looks"
        return (
            f"served {' '.join(parts) or 'nothing'}; errors={self.errors} "
            f"rejected={self.rejected} dropped={self.dropped}{slow} "
            f"contacts={self.world.locomotion.contacts} t_sim={self.world.t_sim:.2f} s{looked}"
        )

    @property
    def errors(self) -> int:
        """Requests answered with an ErrorReply (the camera desk's among them)."""
        return self._errors + self.cameras.errors

    @property
    def rejected(self) -> int:
        """Inputs refused: malformed requests and tokens, requests the world could not
        serve, exceptions in callbacks and handlers."""
        return self.guard.rejected

    @property
    def dropped(self) -> int:
        """Queued items dropped unread because their lane was full (oldest first)."""
        return sum(self.inbox.dropped.values())

    # ------------------------------------------------------------------ callbacks
    # Called by zenoh's threads: they check and queue, never touch the world or zenoh,
    # and never raise.

    def _queue(self, lane: str, item: Any, size: int = 0) -> None:
        dropped = self.inbox.put(lane, item, size)  # counted in inbox.dropped
        if dropped:
            self._drop_log.reject(f"{lane} queue full", f"{dropped} oldest item(s) dropped")

    def admit(self, kind: str, q: Query) -> None:
        """A query arrived: check it cheaply and queue it as valid or malformed."""
        self._admit(kind, q, self.verifier, self.signer)

    def admit_local(self, kind: str, q: Query) -> None:
        """A request of an in-process gateway (the virtual NAOs of ``sim.naoqi_gateway``):
        trusted as a NAO trusts its own qi port, checked like any other and served by the
        same loop; replies are not sealed."""
        self._admit(kind, q, None, None)

    def _admit(
        self, kind: str, q: Query, verifier: trust.Verifier | None, signer: trust.Signer | None
    ) -> None:
        try:
            try:
                target = Request(q, verifier, signer)
            except trust.TrustError as exc:  # unsigned, forged, replayed: no answer at all
                self.guard.reject(f"{kind} request", exc)
                self._queue("malformed", (kind, q, None), payload_size(q))
                return
            except Exception as exc:  # too big for a request: answered when insecure
                self.guard.reject(f"{kind} request", exc)
                self._queue("malformed", (kind, q, reason(exc)), payload_size(q))
                return
            try:
                req = check(kind, target, self.robot_ids)
            except Exception as exc:  # ValueError/ProtocolError, or anything unforeseen
                why = reason(exc) if isinstance(exc, ValueError) else f"internal: {reason(exc)}"
                self.guard.reject(f"{kind} request", exc)
                self._queue("malformed", (kind, target, why), payload_size(q))
                return
            self._queue("valid", req)
        except Exception as exc:
            self.guard.reject(f"{kind} request", exc)

    def admit_alive(self, sample: Any) -> None:
        """A liveliness change: queued only for ids that are robots of this world."""
        try:
            rid = id_from_key(str(sample.key_expr))
            if rid not in self.robot_ids:
                return  # not a robot of this world: no state kept for it
            self._queue("alive", (rid, sample.kind == zenoh.SampleKind.DELETE))
        except Exception as exc:
            self.guard.reject("liveliness token", exc)

    def close(self) -> None:
        if self.session is not None:
            self._log(self.summary())
        if self.delays is not None:  # held replies go out now
            for q, msg in self.delays.take_all():
                self._reply(q, msg)
        for q in self.motions.abandon():
            self._reply(q, ErrorReply(reason="world shutting down"))
        self.cameras.close("world shutting down")
        for obj in reversed(self._keep):
            with contextlib.suppress(Exception):
                obj.undeclare()
        self._keep.clear()
        if self.session is not None:
            with contextlib.suppress(Exception):
                self.session.close()
            self.session = None

    def stop(self) -> None:
        self._stop.set()

    # ------------------------------------------------------------------ loop

    def serve(self) -> None:
        """Run until :meth:`stop` (call :meth:`open` first)."""
        loco = self.world.locomotion
        next_truth = 0.0
        pace_wall = time.monotonic()
        pace_sim = self.world.t_sim
        while not self._stop.is_set():
            now = time.monotonic()
            self._send_due(now)
            if now >= next_truth:
                self._publish_truth()
                next_truth = now + self.truth_period
            if loco.active or self.cameras.looking:
                # Serving requests costs no sim time: when pacing, the wall time spent on
                # them (a render) moves the pacing origin instead of causing a catch-up.
                pace_wall += self._drain(block=False)
                if self.speed > 0:
                    target = pace_wall + (self.world.t_sim + loco.dt - pace_sim) / self.speed
                    delay = target - time.monotonic()
                    if delay > 0:
                        pace_wall += self._drain(block=True, timeout=delay)
                done, contacts = loco.step(clock=True)  # looks take time too
                if done or contacts:
                    self._finish(done, contacts)
                pace_wall += self._capture_due()
            else:
                wait = min(0.05, max(0.0, next_truth - now))
                due = self.delays.next_due() if self.delays is not None else None
                if due is not None:
                    wait = min(wait, max(0.0, due - now))
                self._drain(block=True, timeout=wait)
                pace_wall = time.monotonic()
                pace_sim = self.world.t_sim

    def _capture_due(self) -> float:
        """Draw the pictures of the looks that have ended; the wall time it took (counted
        as camera handling, like a request's)."""
        t0 = time.monotonic()
        self.cameras.capture_due()
        spent = time.monotonic() - t0
        self.busy_s["camera"] += spent
        return spent

    def _drain(self, block: bool, timeout: float = 0.0) -> float:
        """Handle queued requests (waiting up to ``timeout`` for the first if ``block``);
        returns the wall time spent handling them (not waiting)."""
        deadline = time.monotonic() + timeout
        spent = 0.0
        while True:
            try:
                if block:
                    left = deadline - time.monotonic()
                    if left <= 0:
                        return spent
                    lane, item = self.inbox.get(timeout=left)
                else:
                    lane, item = self.inbox.get_nowait()
            except queue.Empty:
                return spent
            t0 = time.monotonic()
            kind = item.kind if lane == "valid" else lane
            try:
                self._handle(lane, item)
            except Exception as exc:  # never let one request take the world down
                self.guard.reject(f"handling {kind}", exc)
            dt = time.monotonic() - t0
            spent += dt
            self.counts[kind] += 1
            self.busy_s[kind] += dt
            block = False

    # ------------------------------------------------------------------ requests

    def _handle(self, lane: str, item: Any) -> None:
        if lane == "alive":
            rid, gone = item
            if self.bindings.token(rid, gone):
                self._log(f"robot {rid} released (agent gone)")
            return
        if lane == "rendered":
            self.cameras.rendered(item)
            return
        if lane == "malformed":
            _, target, why = item
            self._errors += 1
            if isinstance(target, Request):
                self._reply(target, ErrorReply(reason=why[:500]))
            elif why is None or self.verifier is not None:
                self.untrusted += why is None
                with contextlib.suppress(Exception):
                    target.drop()  # secure: no answer to what is not authenticated
            else:
                try:
                    target.reply(target.key_expr, encode(ErrorReply(reason=why[:500])))
                    target.drop()
                    self.served += 1
                except Exception as exc:  # the querier may have gone
                    self._log(f"reply failed: {reason(exc)}")
            return
        req: CheckedRequest = item
        q, rid, msg = req.query, req.robot_id, req.msg
        try:
            if req.kind not in ("register", "scenario") and q.who is not None:
                self._authorise(q, rid)
            if isinstance(msg, RegisterRequest):
                self._reply(q, self._register(q, msg))
            elif isinstance(msg, ScenarioRequest):
                self._reply(q, self._scenario(q))
            elif isinstance(msg, CameraRequest):
                self.cameras.request(q, rid, msg.yaw)
            elif isinstance(msg, WalkRequest):
                d, side, legs = msg.distance, msg.lateral, self.world.locomotion
                go = (lambda: legs.side(rid, side)) if side else (lambda: legs.walk(rid, d))
                self._motion(q, rid, "walk", msg.request_id, go)
            elif isinstance(msg, TurnRequest):
                a, legs = msg.angle, self.world.locomotion
                self._motion(q, rid, "turn", msg.request_id, lambda: legs.turn(rid, a))
        except ValueError as exc:  # ProtocolError is a ValueError
            self._errors += 1
            self.guard.reject(f"{req.kind} {q.key}", exc)
            self._answer(q, ErrorReply(reason=reason(exc, 500)), req.kind != "register")

    def _authorise(self, q: Request, rid: int) -> None:
        """Secure: only robot ``rid``'s key, in the session bound to ``rid``, drives it
        (:meth:`sim.server.bindings.RobotBindings.authorise`); refusals count as untrusted."""
        try:
            self.bindings.authorise(q.who, q.epoch, rid)
        except Unauthorised:
            self.untrusted += 1
            raise

    def _register(self, q: Request, req: RegisterRequest) -> Message:
        rid = self.bindings.register(q.who, q.epoch, req.want)
        self._log(f"robot {rid} claimed")
        return RegisterReply(robot_id=rid)

    def _scenario(self, q: Request) -> Message:
        """The scenario, for a render worker (secure: the ``render`` key only)."""
        if q.who is not None and q.who != trust.Identity("render"):
            self.untrusted += 1
            raise ValueError(f"{q.who.cn} may not ask for the scenario")
        text = json.dumps(scenarios.to_dict(self.world.scenario), sort_keys=True)
        return ScenarioReply(scenario=text.encode())

    def _motion(
        self, q: Request, rid: int, kind: str, request_id: int, start: Callable[[], None]
    ) -> None:
        """Start a motion, or answer a repeat of ``request_id`` without executing it."""
        busy = self.world.locomotion.busy(rid)
        rep = self.motions.request(q, rid, kind, request_id, busy, start)
        if rep is not None:
            self._answer(q, rep)

    def _finish(self, done: list[Done], contacts: list[Contact]) -> None:
        for c in contacts:
            self._put(KEY_WORLD_TRUTH_CONTACTS, ContactMsg(t_sim=c.t_sim, a=c.a, b=c.b))
            self._log(f"contact t={c.t_sim:.2f} between {c.a} and {c.b}")
        # The poses first: a render worker has them before the robot asks for a picture.
        self._publish_truth()
        for d in done:
            ended = self.motions.finish(d)
            if ended is not None:
                queries, rep = ended
                for q in queries:
                    self._answer(q, rep)

    # ------------------------------------------------------------------ output

    def _answer(self, q: Request, msg: Message, slow: bool = True) -> None:
        """A camera or motion reply: at once, or held for its delay in a slow world."""
        if slow and self.delays is not None:
            self.delays.hold(q, msg, time.monotonic())
        else:
            self._reply(q, msg)

    def _send_due(self, now: float) -> None:
        """Send the held replies that are due (a slow world)."""
        if self.delays is not None:
            for q, msg in self.delays.due(now):
                self._reply(q, msg)

    def _reply(self, q: Request, msg: Message) -> None:
        try:
            q.reply(msg)
            self.served += 1
        except Exception as exc:  # the querier may have gone (timeout)
            self._log(f"reply failed: {reason(exc)}")

    def _put(self, key: str, msg: Message) -> None:
        try:
            data = encode(msg)
            if self.signer is not None:
                data = self.signer.seal(key, data)
            self._pub[key].put(data)
        except Exception as exc:
            self._log(f"publish on {key} failed: {reason(exc)}")

    def _publish_truth(self) -> None:
        t = self.world.t_sim
        poses = tuple((rid, *self.world.pose(rid)) for rid in self.world.robot_ids)
        self._put(KEY_WORLD_CLOCK, ClockMsg(t_sim=t))
        self._put(
            KEY_WORLD_TRUTH_POSES,
            TruthPosesMsg(t_sim=t, poses=poses, contacts=self.world.locomotion.contacts),
        )

    def _log(self, text: str) -> None:
        print(f"[sim t={self.world.t_sim:8.2f}] {text}", file=self.log, flush=True)
