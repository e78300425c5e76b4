"""``python -m sim.server.render_worker``: forehead cameras drawn in a process of their own
(rendering is the world's bottleneck in large fleets).

    python -m sim.server.render_worker --connect tls/ROUTER:7448 --credentials DIR [--shard 1/2]

A render worker is the world's camera made a service (docs/world.md "Render workers"):

- it asks the world for its scenario (``world/scenario``) and builds its own copy of the
  room from it (same scenario and seed, same textures: the picture is the world's);
- it follows the world's poses: it subscribes to ``world/truth/poses``, which the world
  publishes at ``--truth-rate`` Hz and after every finished motion (before the motion's
  reply), and draws every picture from the newest poses it has;
- it answers camera queries (``world/robot/{id}/camera``) as *complete* zenoh queryables.
  Agents ask with zenoh's best-matching target, so each query goes to one complete
  queryable: a worker, or the world's own (not complete) camera when none is left.
  Zenoh does the routing; there is no scheduler of our own. ``--shard I/K`` declares
  the cameras of every K-th robot of the scenario (sorted ids, from the I-th): K workers
  with shards 1/K..K/K split the robots between them by key, whatever the network
  between them. Without ``--shard`` a worker serves every robot; several such workers
  then share the queries as zenoh routes them (the nearest; through one router, one of
  them takes every query).

The world keeps the physics, the clock and the authority over poses. Each reply carries
the world time of the poses it was drawn from (``CameraReply.t_sim``): an agent never
uses a frame older than its last motion (:mod:`agent.body.zenoh_world`). Heads: the
requesting robot's head is turned to the asked yaw; the others' heads are as this worker
last drew them (a worker does not hear other workers' requests).

Secure (docs/design.md §8): it joins with the ``render`` key; it opens only what the world
signed (scenario, poses), answers a robot's camera only to that robot's key, and signs
its replies (bound to the request) with its own key; the router's access control lets the
``render`` key do nothing else. Prints ``render ready robots=1,3 shard=1/2 seed=7`` on
stdout when it serves, one summary line on stderr when it stops (SIGINT/SIGTERM): camera
requests served (mean ms), errors, rejected, the world time of its poses.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import queue
import signal
import sys
import threading
import time
from typing import Any

import zenoh

from agent.wire import (
    KEY_WORLD_SCENARIO,
    KEY_WORLD_TRUTH_POSES,
    MAX_PUBLICATION_BYTES,
    CameraReply,
    CameraRequest,
    ErrorReply,
    Guard,
    Inbox,
    Message,
    NetworkSpec,
    ScenarioReply,
    ScenarioRequest,
    TruthPosesMsg,
    add_network_arguments,
    decode,
    key_camera,
    network_spec,
    picture,
    reason,
    take_payload,
    trust,
)
from sim.camera import camera, renderer
from sim.physics.world import World
from sim.scenarios import Scenario, from_dict
from sim.server.client import Link, WorldError, ask
from sim.server.requests import CheckedRequest, Query, Request, check, payload_size
from sim.server.server import MALFORMED_MAX_BYTES, zenoh_config

#: Lanes of the worker's inbox, served in this order (as the world's, sim.server.server).
INBOX_CAPS = {"valid": 256, "malformed": 1024}


def parse_shard(text: str) -> tuple[int, int]:
    """``I/K`` -> (I, K) with 1 <= I <= K <= 64; ``ValueError`` otherwise."""
    i, sep, k = text.partition("/")
    try:
        shard = (int(i), int(k))
    except ValueError:
        shard = (0, 0)
    if not sep or not 1 <= shard[0] <= shard[1] <= 64:
        raise ValueError(f"shard {text!r} is not I/K with 1 <= I <= K <= 64")
    return shard


def shard_robots(robot_ids: list[int], shard: tuple[int, int]) -> tuple[int, ...]:
    """The robots of shard ``(I, K)``: every K-th of the sorted ids, from the I-th."""
    i, k = shard
    return tuple(sorted(robot_ids)[i - 1 :: k])


class Poses:
    """The newest pose state the world published (thread-safe: set by zenoh's thread)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._msg: TruthPosesMsg | None = None
        self._seen = threading.Event()
        self.received = 0

    def put(self, msg: TruthPosesMsg) -> None:
        with self._lock:
            self._msg = msg  # in publication order (one reliable publisher)
            self.received += 1
        self._seen.set()

    def latest(self) -> TruthPosesMsg | None:
        with self._lock:
            return self._msg

    def wait(self, timeout: float) -> bool:
        return self._seen.wait(timeout)


class RenderWorker:
    """Serves the cameras of ``robots`` from its own copy of ``world``'s room."""

    def __init__(
        self,
        world: World,
        robots: tuple[int, ...],
        spec: NetworkSpec,
        session: Any,
        *,
        stop: threading.Event | None = None,
        log: Any = None,
        encoding: str = picture.DEFAULT_ENCODING,
    ) -> None:
        if encoding not in picture.ENCODINGS:
            raise ValueError(f"camera encoding {encoding!r} not one of {picture.ENCODINGS}")
        self.encoding = encoding
        self.world = world
        self.robots = frozenset(robots)
        self.session = session
        self.log = log if log is not None else sys.stderr
        self.signer: trust.Signer | None = None
        self.verifier: trust.Verifier | None = None
        if spec.secure:
            creds = trust.Credentials(spec.credentials)
            self.signer = creds.signer(trust.Identity("render"))
            self.verifier = creds.verifier()
        self.poses = Poses()
        self.inbox: Inbox[Any] = Inbox(
            INBOX_CAPS, priority=True, max_weight={"malformed": MALFORMED_MAX_BYTES}
        )
        self.guard = Guard(self._log)
        self.served = 0  # camera pictures sent
        self.errors = 0  # requests answered with an ErrorReply
        self.untrusted = 0  # requests refused by authentication (no answer)
        self.busy_s = 0.0
        self.t_poses = -1.0  # world time of the poses last drawn
        self._applied = -1  # Poses.received count last applied to the room
        self._stop = stop if stop is not None else threading.Event()
        self._keep: list[Any] = []

    # ------------------------------------------------------------------ setup

    def follow(self) -> None:
        """Subscribe to the world's poses (before waiting for them)."""

        def on_poses(sample: Any) -> None:
            try:
                data = take_payload(sample.payload, MAX_PUBLICATION_BYTES)
                self.poses.put(decode(self._open_world(KEY_WORLD_TRUTH_POSES, data), TruthPosesMsg))
            except Exception as exc:
                self.guard.reject("poses", exc)

        self._keep.append(self.session.declare_subscriber(KEY_WORLD_TRUTH_POSES, on_poses))

    def declare(self) -> None:
        """Declare one complete camera queryable per robot served."""

        def on_query(q: zenoh.Query) -> None:
            self.admit(q)

        for rid in sorted(self.robots):
            self._keep.append(
                self.session.declare_queryable(key_camera(rid), on_query, complete=True)
            )

    def _open_world(self, key: str, data: bytes) -> bytes:
        if self.verifier is None:
            return data
        opened = self.verifier.open(key, data)
        if opened.who != trust.Identity("world"):
            raise trust.TrustError(f"{opened.who.cn} signed {key}, not the world")
        return opened.payload

    # ------------------------------------------------------------------ callbacks

    def admit(self, q: Query) -> None:
        """A camera query arrived (zenoh's thread): check it cheaply and queue it."""
        try:
            try:
                req = Request(q, self.verifier, self.signer)
            except Exception as exc:  # unsigned, forged, replayed, too big: no answer
                self.guard.reject("camera request", exc)
                self.untrusted += isinstance(exc, trust.TrustError)
                with contextlib.suppress(Exception):
                    q.drop()
                return
            try:
                checked = check("camera", req, self.robots)
                if req.who is not None and req.who != trust.Identity.robot(checked.robot_id):
                    self.untrusted += 1
                    raise ValueError(f"{req.who.cn} may not see robot {checked.robot_id}'s camera")
            except Exception as exc:
                self.guard.reject("camera request", exc)
                self._put("malformed", (req, reason(exc, 500)), payload_size(q))
                return
            self._put("valid", checked)
        except Exception as exc:
            self.guard.reject("camera request", exc)

    def _put(self, lane: str, item: Any, size: int = 0) -> None:
        if self.inbox.put(lane, item, size):
            self.guard.reject(f"{lane} queue full", "oldest request dropped")

    # ------------------------------------------------------------------ loop

    def stop(self) -> None:
        self._stop.set()

    def serve(self) -> None:
        """Answer queued camera requests until :meth:`stop`."""
        while not self._stop.is_set():
            self.drain(timeout=0.2)

    def drain(self, timeout: float = 0.0) -> int:
        """Answer the queued requests (waiting up to ``timeout`` for the first); how many."""
        handled = 0
        while True:
            try:
                if handled == 0 and timeout > 0:
                    lane, item = self.inbox.get(timeout=timeout)
                else:
                    lane, item = self.inbox.get_nowait()
            except queue.Empty:
                return handled
            handled += 1
            t0 = time.monotonic()
            try:
                if lane == "valid":
                    self._camera(item)
                else:
                    req, why = item
                    self.errors += 1
                    self._reply(req, ErrorReply(reason=why))
            except Exception as exc:  # never let one request take the worker down
                self.guard.reject("camera", exc)
            self.busy_s += time.monotonic() - t0

    def _camera(self, req: CheckedRequest) -> None:
        msg = self.poses.latest()
        assert msg is not None  # queryables are declared once poses came
        try:
            self._apply(msg)
            if not isinstance(req.msg, CameraRequest):
                raise ValueError(f"not a camera request: {type(req.msg).__name__}")
            yaw = camera.check_yaw(req.msg.yaw)
            img = self.world.render(req.robot_id, yaw)
            rep: Message = CameraReply(
                robot_id=req.robot_id,
                yaw=self.world.head_yaw(req.robot_id),
                t_sim=msg.t_sim,
                width=img.shape[1],
                height=img.shape[0],
                encoding=self.encoding,
                data=picture.picture_data(img, self.encoding),
            )
        except ValueError as exc:
            self.errors += 1
            rep = ErrorReply(reason=f"render failed: {reason(exc, 480)}")
        if self._reply(req.query, rep) and isinstance(rep, CameraReply):
            self.served += 1

    def _apply(self, msg: TruthPosesMsg) -> None:
        """Move the room's robots to the poses of ``msg`` (once per pose message)."""
        n = self.poses.received
        if n == self._applied:
            return
        for rid, x, y, th in msg.poses:
            if rid in self.world.robot_ids:
                self.world.set_pose(rid, x, y, th)
        self._applied = n
        self.t_poses = msg.t_sim

    def _reply(self, q: Request, msg: Message) -> bool:
        try:
            q.reply(msg)
            return True
        except Exception as exc:  # the querier may have gone (timeout)
            self._log(f"reply failed: {reason(exc)}")
            return False

    def summary(self) -> str:
        mean = f" ({1000 * self.busy_s / self.served:.0f} ms)" if self.served else ""
        return (
            f"served camera={self.served}{mean}; errors={self.errors} "
            f"rejected={self.guard.rejected} untrusted={self.untrusted} "
            f"dropped={sum(self.inbox.dropped.values())} poses={self.poses.received} "
            f"t_poses={self.t_poses:.2f} s"
        )

    def close(self) -> None:
        for obj in reversed(self._keep):
            with contextlib.suppress(Exception):
                obj.undeclare()
        self._keep.clear()

    def _log(self, text: str) -> None:
        print(f"[render t={self.t_poses:8.2f}] {text}", file=self.log, flush=True)


def fetch_scenario(link: Link, wait_s: float) -> Scenario:
    """The world's scenario, asked until it answers or ``wait_s`` passes."""
    deadline = time.monotonic() + wait_s
    while True:
        try:
            rep = ask(link, KEY_WORLD_SCENARIO, ScenarioRequest(), min(5.0, wait_s))
        except WorldError:
            if time.monotonic() >= deadline:
                raise
            time.sleep(0.5)  # the world may not be up yet; asked again until the deadline
            continue
        if not isinstance(rep, ScenarioReply):
            raise WorldError(f"the world answered {type(rep).__name__}, not a scenario")
        return from_dict(json.loads(rep.scenario))


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m sim.server.render_worker",
        description="A render worker: draws the world's forehead cameras, so that the world "
        "spreads over cores and hosts.",
    )
    add_network_arguments(p, ("peer", "client"))
    p.add_argument(
        "--shard",
        default="1/1",
        metavar="I/K",
        help="serve every K-th robot of the scenario from the I-th (default 1/1: all)",
    )
    p.add_argument(
        "--wait", type=float, default=120.0, help="seconds to wait for the world's scenario/poses"
    )
    p.add_argument(
        "--renderer",
        choices=renderer.RENDERERS,
        default=renderer.DEFAULT,
        help=renderer.RENDERER_HELP,
    )
    p.add_argument(
        "--camera-encoding",
        choices=picture.ENCODINGS,
        default=picture.DEFAULT_ENCODING,
        help=picture.ENCODING_HELP,
    )
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        shard = parse_shard(args.shard)
        if not 0 < args.wait < float("inf"):
            raise ValueError(f"--wait {args.wait}: must be > 0")
        spec = network_spec(args, "render")
    except ValueError as exc:
        print(f"render: {exc}", file=sys.stderr)
        return 2
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        session = zenoh.open(zenoh_config(spec))
    except Exception as exc:
        print(f"render: cannot open the zenoh session: {exc}", file=sys.stderr)
        return 1
    try:
        return _run(session, spec, shard, args.wait, stop, args.renderer, args.camera_encoding)
    finally:
        with contextlib.suppress(Exception):
            session.close()


def _run(
    session: Any,
    spec: NetworkSpec,
    shard: tuple[int, int],
    wait: float,
    stop: threading.Event,
    kind: str = renderer.DEFAULT,
    encoding: str = picture.DEFAULT_ENCODING,
) -> int:
    try:
        sc = fetch_scenario(Link(session, spec), wait)
    except (WorldError, ValueError) as exc:  # ProtocolError, TrustError are ValueErrors
        print(f"render: no scenario from the world: {exc}", file=sys.stderr)
        return 1
    robots = shard_robots([r.id for r in sc.robots], shard)
    if not robots:
        print(
            f"render: shard {shard[0]}/{shard[1]} holds no robot of {len(sc.robots)}",
            file=sys.stderr,
        )
        return 2
    try:
        world = World(sc, noise=False, renderer=kind)
    except RuntimeError as exc:  # --renderer egl did not load
        print(f"render: {exc}", file=sys.stderr)
        return 1
    print(f"render: renderer {world.renderer} ({world.renderer_why})", file=sys.stderr, flush=True)
    with world:
        worker = RenderWorker(world, robots, spec, session, stop=stop, encoding=encoding)
        worker.follow()
        if not worker.poses.wait(wait) or stop.is_set():
            print("render: no poses from the world", file=sys.stderr)
            worker.close()
            return 1
        worker.declare()
        ids = ",".join(str(r) for r in robots)
        print(f"render ready robots={ids} shard={shard[0]}/{shard[1]} seed={sc.seed}", flush=True)
        try:
            worker.serve()
        finally:
            worker._log(worker.summary())
            worker.close()
    print("render stopped", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
