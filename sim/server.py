"""The world on the bus: zenoh queryables and publications of DESIGN.md §3 (issue 3).

Queryables (payloads are :mod:`agent.wire` messages):

- ``world/register``: ``RegisterRequest(want)`` -> ``RegisterReply(robot_id)``: the lowest
  free robot id of the scenario (or ``want`` if it is free). An id is taken while it is
  claimed or while an agent holds its liveliness token ``nao/alive/{id}`` (agents
  started with a fixed ``--id`` register nothing but hold the token); a claim is
  released when that token goes away.
- ``world/robot/{id}/camera``: ``CameraRequest(yaw)`` -> ``CameraReply`` (PNG). Without a
  payload, the selector parameter ``yaw`` (radians) is read instead.
- ``world/robot/{id}/walk`` / ``turn``: ``WalkRequest`` / ``TurnRequest`` -> a
  ``CommandReply(done|contact)`` sent when the motion has finished in sim time.
  A request with a ``request_id`` (> 0) is executed once per (robot, id): a repeat
  while it runs waits for the same motion, a repeat after it is answered with the first
  result (the last ``MOTION_CACHE`` results per robot are kept), so a client may retry
  a motion whose reply it lost (issue #9).

Anything malformed or impossible (unknown robot, NaN, yaw out of range, wrong schema
version, busy robot) gets an ``ErrorReply`` with the reason; the world keeps serving.

**Hardening (issue #8).** The zenoh callbacks check each request cheaply where it
arrives (payload length before the copy, at most ``MAX_REQUEST_BYTES``; robot id; schema;
yaw) and queue it in one of two bounded lanes: well-formed requests, served first, and
malformed ones, answered with their reason when nothing else waits. A full lane drops
its oldest request (counted in ``dropped``; zenoh then ends that query with no reply;
the malformed lane also holds at most ``MALFORMED_MAX_BYTES`` of payloads),
so a flood of garbage can neither grow memory nor delay a valid request by more than
one queue's worth. Every callback survives every exception; rejected input is counted
in ``rejected`` and logged with a reason cut to 200 characters, rate limited. At most
``MAX_RENDER_PENDING`` camera requests wait for render workers; liveliness tokens of
ids that are not robots of this world are ignored.

Publications: ``world/clock`` (``ClockMsg``) and ``world/truth/poses`` (``TruthPosesMsg``)
at ``truth_rate`` Hz of wall time and after every finished command; ``world/truth/contacts``
(``ContactMsg``) when a contact happens.

**Threads and the clock.** zenoh callbacks only put queries on a queue; one loop owns
PyBullet and the world. The sim clock advances (in fixed steps of 0.02 s) only while at
least one walk/turn is active, as fast as possible by default or paced at ``speed`` x
real time; rendering costs no sim time. Queued requests are served between steps.
With ``render_workers`` > 0 a camera request's state (poses, head yaws, sim time) is
taken at once and the picture drawn by a :class:`~sim.render_pool.RenderPool` worker;
its result comes back through the same queue.
"""

from __future__ import annotations

import contextlib
import math
import queue
import sys
import threading
import time
from collections import Counter, OrderedDict, defaultdict
from dataclasses import dataclass, field
from typing import Any

import cv2
import zenoh

from agent.wire import (
    KEY_ALIVE_ALL,
    KEY_WORLD_CLOCK,
    KEY_WORLD_REGISTER,
    KEY_WORLD_TRUTH_CONTACTS,
    KEY_WORLD_TRUTH_POSES,
    MAX_REQUEST_BYTES,
    CameraReply,
    CameraRequest,
    ClockMsg,
    CommandReply,
    ContactMsg,
    ErrorReply,
    Guard,
    Inbox,
    Message,
    NetworkSpec,
    ProtocolError,
    RegisterReply,
    RegisterRequest,
    TruthPosesMsg,
    TurnRequest,
    WalkRequest,
    decode,
    encode,
    id_from_key,
    reason,
    take_payload,
    trust,
)
from sim import camera
from sim.locomotion import Contact, Done
from sim.render_pool import PNG_PARAMS, Job, RenderPool, Result
from sim.world import World

#: How the world joins the bus: the shared :class:`agent.wire.NetworkSpec`.
NetConfig = NetworkSpec


def zenoh_config(spec: NetworkSpec) -> zenoh.Config:
    """The zenoh config of ``spec`` (the world may not import ``agent.net.bus``)."""
    cfg = zenoh.Config()
    for key, value in spec.json5_items():
        cfg.insert_json5(key, value)
    return cfg


class Request:
    """One query to the world, authenticated when the world runs with credentials.

    Secure: the payload is the :mod:`agent.wire.trust` envelope's, ``signer`` is who sealed
    it, and replies are sealed by the world and bound to the request (``nonce``), so a
    reply can neither be forged nor replayed to another request. Insecure: the query's
    own payload, no signer.
    """

    def __init__(
        self,
        q: Any,
        verifier: trust.Verifier | None,
        signer: trust.Signer | None,
    ) -> None:
        self.q = q
        self.key = str(q.key_expr)
        self.parameters = q.parameters
        self.signer = signer
        self.who: trust.Identity | None = None
        self.epoch = -1
        self.nonce = b""
        raw = q.payload
        data = take_payload(raw, MAX_REQUEST_BYTES) if raw is not None else None
        if verifier is not None:
            if data is None:
                raise trust.TrustError(f"unsigned request on {self.key}")
            opened = verifier.open(self.key, data)
            self.who, self.epoch, self.nonce = opened.who, opened.epoch, opened.nonce
            data = opened.payload
        self.payload: bytes | None = data

    def reply(self, msg: Message) -> None:
        data = encode(msg)
        if self.signer is not None:
            data = self.signer.seal(self.key, data, bind=self.nonce)
        self.q.reply(self.q.key_expr, data)
        self.q.drop()

    def refuse(self) -> None:
        """No answer at all: a stranger learns nothing (zenoh ends its query)."""
        self.q.drop()


#: Lanes of the world's inbox, in the order they are served, and their capacities.
#: ``rendered``: results of render workers (at most MAX_RENDER_PENDING are ever
#: outstanding, so this lane never overflows); ``alive``: liveliness changes;
#: ``valid``: requests that passed the callback's checks; ``malformed``: requests
#: waiting only for an ErrorReply.
INBOX_CAPS = {"rendered": 256, "alive": 1024, "valid": 256, "malformed": 1024}
#: A malformed query keeps its payload (in zenoh's memory) until it is answered: the
#: lane holds at most this many payload bytes; a bigger request is dropped unanswered.
MALFORMED_MAX_BYTES = 16 * 1024 * 1024
#: Camera requests handed to render workers and not yet answered.
MAX_RENDER_PENDING = 64
#: Results of motions with a request id kept per robot, for repeats (oldest dropped).
MOTION_CACHE = 32
#: Longest ``yaw`` selector parameter read (a float needs a few dozen characters).
MAX_PARAM_CHARS = 64


@dataclass
class _Pending:
    query: Request
    kind: str
    robot_id: int
    request_id: int = 0
    waiters: list[Request] = field(default_factory=list)  # repeats of request_id


@dataclass
class _Request:
    """A request that passed the callback's checks: ``msg`` is its decoded payload."""

    kind: str
    query: Request
    robot_id: int
    msg: Any


def _payload_size(q: Any) -> int:
    """Length of a query's payload (0 if none or unreadable), without copying it."""
    try:
        return 0 if q.payload is None else len(q.payload)
    except Exception:
        return 0


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
        log: Any = None,
    ) -> None:
        if not (math.isfinite(speed) and speed >= 0):
            raise ValueError(f"speed {speed} must be >= 0 (0: as fast as possible)")
        if not (math.isfinite(truth_rate) and truth_rate > 0):
            raise ValueError(f"truth rate {truth_rate} must be > 0")
        self.world = world
        self.net = net or NetConfig()
        self.speed = speed
        self.truth_period = 1.0 / truth_rate
        self.log = log if log is not None else sys.stderr
        self.robot_ids = frozenset(world.robot_ids)  # read by the zenoh callbacks
        self.inbox: Inbox[Any] = Inbox(
            INBOX_CAPS, priority=True, max_weight={"malformed": MALFORMED_MAX_BYTES}
        )
        self.guard = Guard(self._log)
        self._drop_log = Guard(self._log, burst=3, per_second=0.2)  # its count: dropped
        self.claims: set[int] = set()
        self.alive: set[int] = set()  # ids with a live agent token (nao/alive/{id})
        self.errors = 0
        self.served = 0
        self.counts: Counter[str] = Counter()  # requests handled, by kind
        self.busy_s: dict[str, float] = defaultdict(float)  # wall seconds on them, by kind
        self._pending: dict[int, _Pending] = {}
        # robot -> request id -> (kind, first result), at most MOTION_CACHE per robot
        self._results: dict[int, OrderedDict[int, tuple[str, CommandReply]]] = {}
        self.repeats = 0  # motion requests answered without executing them again
        if isinstance(render_workers, bool) or not 0 <= render_workers <= 16:
            raise ValueError(f"render workers {render_workers!r} must be in [0, 16]")
        self.render_workers = render_workers
        self.pool: RenderPool | None = None
        self._cam_pending: dict[int, tuple[Any, int, float, float]] = {}
        self._next_job = 0
        self._stop = threading.Event()
        self._keep: list[Any] = []
        self.session: Any = None
        self.verifier: trust.Verifier | None = None
        self.signer: trust.Signer | None = None
        self.untrusted = 0  # requests refused by authentication
        self.bound: dict[int, int] = {}  # robot id -> the epoch of the session driving it
        if self.net.secure:
            creds = trust.Credentials(self.net.credentials)
            self.signer = creds.signer(trust.Identity("world"))
            self.verifier = creds.verifier()

    # ------------------------------------------------------------------ setup

    def open(self) -> None:
        if self.render_workers > 0:
            self.pool = RenderPool(
                self.world.scenario,
                self.render_workers,
                self.guard.wrap(lambda r: self._queue("rendered", r), "render result"),
            )
        self.session = zenoh.open(zenoh_config(self.net))
        s = self.session

        def handler(kind: str) -> Any:
            def on_query(q: Any) -> None:
                self.admit(kind, q)

            return on_query

        self._keep.append(s.declare_queryable(KEY_WORLD_REGISTER, handler("register")))
        for kind in ("camera", "walk", "turn"):
            self._keep.append(s.declare_queryable(f"world/robot/*/{kind}", handler(kind)))

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
        return (
            f"served {' '.join(parts) or 'nothing'}; errors={self.errors} "
            f"rejected={self.rejected} dropped={self.dropped} "
            f"contacts={self.world.locomotion.contacts} t_sim={self.world.t_sim:.2f} s"
        )

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

    def admit(self, kind: str, q: Any) -> None:
        """A query arrived: check it cheaply and queue it as valid or malformed."""
        self._admit(kind, q, self.verifier, self.signer)

    def admit_local(self, kind: str, q: Any) -> None:
        """A request of an in-process gateway (the virtual NAOs of ``sim.naoqi_gateway``):
        trusted as a NAO trusts its own qi port, checked like any other and served by the
        same loop; replies are not sealed."""
        self._admit(kind, q, None, None)

    def _admit(
        self, kind: str, q: Any, verifier: trust.Verifier | None, signer: trust.Signer | None
    ) -> None:
        try:
            try:
                target: Request | Any = Request(q, verifier, signer)
            except trust.TrustError as exc:  # unsigned, forged, replayed: no answer at all
                self.guard.reject(f"{kind} request", exc)
                self._queue("malformed", (kind, q, None), _payload_size(q))
                return
            except Exception as exc:  # too big for a request: answered when insecure
                self.guard.reject(f"{kind} request", exc)
                self._queue("malformed", (kind, q, reason(exc)), _payload_size(q))
                return
            try:
                req = self._check(kind, target)
            except Exception as exc:  # ValueError/ProtocolError, or anything unforeseen
                why = reason(exc) if isinstance(exc, ValueError) else f"internal: {reason(exc)}"
                self.guard.reject(f"{kind} request", exc)
                self._queue("malformed", (kind, target, why), _payload_size(q))
                return
            self._queue("valid", req)
        except Exception as exc:
            self.guard.reject(f"{kind} request", exc)

    def _check(self, kind: str, q: Request) -> _Request:
        """The request ``q`` decoded and checked, or a ``ValueError`` saying why not."""
        payload = q.payload
        if kind == "register":
            if payload is None:
                return _Request(kind, q, -1, RegisterRequest())
            return _Request(kind, q, -1, self._decode(payload, RegisterRequest))
        rid = id_from_key(q.key)
        if rid not in self.robot_ids:
            raise ValueError(f"unknown robot {rid}; robots are {sorted(self.robot_ids)}")
        if kind == "camera":
            if payload is not None:
                yaw = self._decode(payload, CameraRequest).yaw
            else:
                raw = q.parameters.get("yaw")
                if raw is not None and len(raw) > MAX_PARAM_CHARS:
                    raise ValueError(f"yaw parameter of {len(raw)} characters is not a number")
                try:
                    yaw = float(raw) if raw is not None else 0.0
                except ValueError:
                    raise ValueError(f"yaw parameter {raw!r} is not a number") from None
            return _Request(kind, q, rid, CameraRequest(yaw=camera.check_yaw(yaw)))
        if kind == "walk":
            return _Request(kind, q, rid, self._decode(payload, WalkRequest))
        if kind == "turn":
            return _Request(kind, q, rid, self._decode(payload, TurnRequest))
        raise ValueError(f"unknown request kind {kind!r}")

    @staticmethod
    def _decode(payload: bytes | None, cls: type[Message]) -> Any:
        """``payload`` (already bounded by :class:`Request`) decoded as a ``cls``."""
        if payload is None:
            raise ProtocolError(f"missing {cls.TAG!r} payload")
        return decode(payload, expect=cls, max_bytes=MAX_REQUEST_BYTES)

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
        for p in list(self._pending.values()):
            for q in (p.query, *p.waiters):
                self._reply(q, ErrorReply(reason="world shutting down"))
        self._pending.clear()
        for q, *_ in list(self._cam_pending.values()):
            self._reply(q, ErrorReply(reason="world shutting down"))
        self._cam_pending.clear()
        if self.pool is not None:
            self.pool.close()
            self.pool = None
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
            if now >= next_truth:
                self._publish_truth()
                next_truth = now + self.truth_period
            if loco.active:
                # Serving requests costs no sim time: when pacing, the wall time spent on
                # them (a render) moves the pacing origin instead of causing a catch-up.
                pace_wall += self._drain(block=False)
                if self.speed > 0:
                    target = pace_wall + (self.world.t_sim + loco.dt - pace_sim) / self.speed
                    delay = target - time.monotonic()
                    if delay > 0:
                        pace_wall += self._drain(block=True, timeout=delay)
                done, contacts = loco.step()
                if done or contacts:
                    self._finish(done, contacts)
            else:
                self._drain(block=True, timeout=min(0.05, max(0.0, next_truth - now)))
                pace_wall = time.monotonic()
                pace_sim = self.world.t_sim

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
            if gone:
                self.alive.discard(rid)
                if rid in self.claims:
                    self.claims.discard(rid)
                    self._log(f"robot {rid} released (agent gone)")
            else:
                self.alive.add(rid)
            return
        if lane == "rendered":
            self._rendered(item)
            return
        if lane == "malformed":
            _, target, why = item
            self.errors += 1
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
        req: _Request = item
        q, rid = req.query, req.robot_id
        try:
            if req.kind != "register" and q.who is not None:
                self._authorise(q, rid)
            if req.kind == "register":
                self._reply(q, self._register(q, req.msg))
            elif req.kind == "camera":
                rep = self._camera(q, rid, req.msg.yaw)
                if rep is not None:  # else a render worker has it
                    self._reply(q, rep)
            elif req.kind == "walk":
                d = req.msg.distance
                self._motion(
                    q, rid, "walk", req.msg.request_id, lambda: self.world.locomotion.walk(rid, d)
                )
            elif req.kind == "turn":
                a = req.msg.angle
                self._motion(
                    q, rid, "turn", req.msg.request_id, lambda: self.world.locomotion.turn(rid, a)
                )
        except ValueError as exc:  # ProtocolError is a ValueError
            self.errors += 1
            self.guard.reject(f"{req.kind} {q.key}", exc)
            self._reply(q, ErrorReply(reason=reason(exc, 500)))

    def _authorise(self, q: Request, rid: int) -> None:
        """Secure: only robot ``rid``'s key, in the session bound to ``rid``, drives it.

        A robot is bound to the epoch (session) that claimed it (``--id auto``) or, with
        a fixed id, that last commanded it; a newer epoch of the same key (a restart)
        takes an unclaimed robot over, an older one (a replay) is refused.
        """
        if q.who != trust.Identity.robot(rid):
            self.untrusted += 1
            raise ValueError(f"{q.who.cn if q.who else 'nobody'} may not command robot {rid}")
        bound = self.bound.get(rid)
        if bound is not None and q.epoch != bound and (rid in self.claims or q.epoch < bound):
            self.untrusted += 1
            raise ValueError(f"robot {rid} is bound to another session of its key")
        self.bound[rid] = q.epoch

    def _register(self, q: Request, req: RegisterRequest) -> Message:
        if q.who is not None:  # secure: a key claims its own robot id, and only that one
            if q.who.role != "robot":
                raise ValueError(f"{q.who.cn} is not a robot and may not claim one")
            if req.want not in (-1, q.who.robot_id):
                raise ValueError(f"{q.who.cn} may not claim robot {req.want}")
            req = RegisterRequest(want=q.who.robot_id)
        taken = self.claims | self.alive
        free = [r for r in self.world.robot_ids if r not in taken]
        if req.want >= 0:
            if req.want not in self.world.robot_ids:
                raise ValueError(f"robot {req.want} is not in this world's scenario")
            if req.want in self.claims:
                raise ValueError(f"robot {req.want} is already claimed")
            if req.want in self.alive:
                raise ValueError(f"robot {req.want} is already driven by a live agent")
            rid = req.want
        elif not free:
            raise ValueError(f"every robot is claimed ({list(self.world.robot_ids)})")
        else:
            rid = free[0]
        self.claims.add(rid)
        if q.who is not None:
            self.bound[rid] = q.epoch  # the claiming session drives it from now on
        self._log(f"robot {rid} claimed")
        return RegisterReply(robot_id=rid)

    def _camera(self, q: Request, rid: int, yaw: float) -> Message | None:
        if self.pool is not None and self.pool.alive > 0:
            if len(self._cam_pending) >= MAX_RENDER_PENDING:
                raise ValueError(f"world busy: {len(self._cam_pending)} pictures being drawn")
            # The state the picture depends on is taken now; a worker draws it.
            self.world.set_head_yaw(rid, yaw)
            job = Job(
                self._next_job,
                rid,
                yaw,
                self.world.poses(),
                {r: self.world.head_yaw(r) for r in self.world.robot_ids},
            )
            self._next_job += 1
            self._cam_pending[job.job_id] = (q, rid, yaw, self.world.t_sim)
            self.pool.submit(job)
            return None
        return self._render_here(rid, yaw, self.world.t_sim)

    def _render_here(self, rid: int, yaw: float, t_sim: float) -> Message:
        img = self.world.render(rid, yaw)
        ok, png = cv2.imencode(".png", img, PNG_PARAMS)
        if not ok:
            raise ValueError("PNG encoding failed")
        return CameraReply(
            robot_id=rid,
            yaw=self.world.head_yaw(rid),
            t_sim=t_sim,
            width=img.shape[1],
            height=img.shape[0],
            encoding="png",
            data=png.tobytes(),
        )

    def _rendered(self, res: Result) -> None:
        """A worker's picture (or failure) for a pending camera request."""
        assert self.pool is not None
        self.pool.worker_done(res)
        pending = self._cam_pending.pop(res.job_id, None)
        if pending is not None:
            q, rid, yaw, t_sim = pending
            if res.error:
                self.errors += 1
                self._log(f"camera robot {rid}: render failed: {reason(res.error)}")
                self._reply(q, ErrorReply(reason=f"render failed: {reason(res.error, 480)}"))
            else:
                msg = CameraReply(
                    robot_id=rid,
                    yaw=yaw,
                    t_sim=t_sim,
                    width=camera.WIDTH,
                    height=camera.HEIGHT,
                    encoding="png",
                    data=res.png,
                )
                self._reply(q, msg)
        if res.dead:
            self._log(f"render worker {res.worker} died; {self.pool.alive} left")
            if self.pool.alive == 0:  # render what is left here, and from now on
                for job in self.pool.take_backlog():
                    left = self._cam_pending.pop(job.job_id, None)
                    if left is not None:
                        self._reply(left[0], self._render_here(job.robot_id, job.yaw, left[3]))

    def _motion(self, q: Request, rid: int, kind: str, request_id: int, start: Any) -> None:
        """Start a motion, or answer a repeat of ``request_id`` without executing it."""
        if request_id:
            done = self._results.get(rid, OrderedDict()).get(request_id)
            p = self._pending.get(rid)
            first = (
                done[0] if done is not None else p.kind if p and p.request_id == request_id else ""
            )
            if first and first != kind:
                raise ValueError(
                    f"request id {request_id} of robot {rid} was a {first}, not a {kind}"
                )
            if done is not None:
                self.repeats += 1
                self._reply(q, done[1])
                return
            if p is not None and p.request_id == request_id:
                self.repeats += 1
                p.waiters.append(q)  # answered with the running motion's result
                return
        self._start(q, rid, kind, start, request_id)

    def _start(self, q: Request, rid: int, kind: str, start: Any, request_id: int = 0) -> None:
        if rid in self._pending or self.world.locomotion.busy(rid):
            raise ValueError(f"robot {rid} is busy with a motion")
        start()
        self._pending[rid] = _Pending(q, kind, rid, request_id)

    def _finish(self, done: list[Done], contacts: list[Contact]) -> None:
        for c in contacts:
            self._put(KEY_WORLD_TRUTH_CONTACTS, ContactMsg(t_sim=c.t_sim, a=c.a, b=c.b))
            self._log(f"contact t={c.t_sim:.2f} between {c.a} and {c.b}")
        for d in done:
            p = self._pending.pop(d.robot_id, None)
            if p is not None:
                rep = CommandReply(
                    robot_id=d.robot_id, status=d.status, t_sim=d.t_sim, detail=d.detail
                )
                if p.request_id:
                    cache = self._results.setdefault(d.robot_id, OrderedDict())
                    cache[p.request_id] = (p.kind, rep)
                    while len(cache) > MOTION_CACHE:
                        cache.popitem(last=False)
                for q in (p.query, *p.waiters):
                    self._reply(q, rep)
        self._publish_truth()

    # ------------------------------------------------------------------ output

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
