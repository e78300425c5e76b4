"""``python -m sim.server.client``: poke a running world by hand (camera, walk, turn, poses).

A small command-line client of the world's bus contract (docs/design.md §3), for people
trying the world and for debugging; agents use ``agent/body/zenoh_world.py`` instead::

    python -m sim.server.client --credentials fleet/ --connect tls/127.0.0.1:7447 \
        camera 1 --yaw 30
    python -m sim.server.client --credentials fleet/ --connect tls/127.0.0.1:7447 \
        walk 1 0.2 --times 5
    python -m sim.server.client --credentials fleet/ --connect tls/127.0.0.1:7447 poses
    python -m sim.server.client --insecure --connect tcp/127.0.0.1:7447 turn 1 -15

With credentials (docs/design.md §8) the client acts with a key of the folder: robot N's for
``camera``/``walk``/``turn N`` and ``register --want N``, the observer's for ``poses``
(``--as CN`` chooses another); it seals its requests and accepts only what the world
signed. The world obeys robot N's key only in the session that drives robot N, so a
robot that an agent drives refuses the client's commands. Angles on the command line are
degrees. ``poses`` reads ``world/truth/poses`` (evaluation data: fine for a person, never
for an agent). Exit status 0 on success, 1 if the world refused or did not answer, 2 on
bad arguments.
"""

from __future__ import annotations

import argparse
import math
import queue
import sys
import time
from pathlib import Path
from typing import Any

import cv2
import zenoh

from agent.wire import (
    KEY_WORLD_REGISTER,
    KEY_WORLD_TRUTH_POSES,
    MAX_PUBLICATION_BYTES,
    CameraReply,
    CameraRequest,
    CommandReply,
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
    add_network_arguments,
    decode,
    encode,
    key_camera,
    key_turn,
    key_walk,
    network_spec,
    picture,
    take_payload,
    trust,
)


class WorldError(RuntimeError):
    """The world refused a request or did not answer."""


#: Counts and logs (cut, rate limited) what this client refuses; never raises.
GUARD = Guard(lambda line: print(f"sim.server.client: {line}", file=sys.stderr))


class Link:
    """The client's zenoh session; secure, it seals requests with its key and opens only
    what the world signed (a reply bound to its request, publications)."""

    def __init__(self, session: Any, spec: NetworkSpec) -> None:
        self.session = session
        self.signer: trust.Signer | None = None
        self.verifier: trust.Verifier | None = None
        if spec.secure:
            creds = trust.Credentials(spec.credentials)
            self.signer = creds.signer(trust.Identity.parse(spec.identity))
            self.verifier = creds.verifier()

    def get(self, key: str, msg: Message, timeout: float) -> tuple[Any, bytes]:
        """The replies to ``msg`` on ``key``, and the nonce they must be bound to. A camera
        query goes to one complete queryable if any (a render worker), as an agent's."""
        data, nonce = encode(msg), b""
        if self.signer is not None:
            data, nonce = self.signer.seal_request(key, data)
        best = isinstance(msg, CameraRequest)
        replies = self.session.get(
            key,
            payload=data,
            timeout=timeout,
            target=zenoh.QueryTarget.BEST_MATCHING if best else zenoh.QueryTarget.ALL,
            consolidation=zenoh.ConsolidationMode.NONE,
        )
        return replies, nonce

    def open(self, key: str, data: bytes, bind: bytes = b"", reply: bool = False) -> bytes:
        """The payload of what the world sent on ``key`` (:class:`ProtocolError` if not)."""
        if self.verifier is None:
            return data
        opened = self.verifier.open(key, data, bind=bind, replay=not reply)
        signers = [trust.Identity("world")]
        if key.startswith("world/robot/") and key.endswith("/camera"):
            signers.append(trust.Identity("render"))  # a render worker's picture
        if opened.who not in signers:
            raise trust.TrustError(f"{opened.who.cn} is not the world")
        return opened.payload


def save_picture(rep: CameraReply, path: str | Path) -> None:
    """Write the picture ``rep`` carries to ``path`` as an image file (PNG for ``.png``).

    Raises ``ValueError`` for a picture that does not decode or a file that cannot be
    written.
    """
    img = picture.picture_of(rep.encoding, rep.width, rep.height, rep.data)
    if not cv2.imwrite(str(path), img):
        raise ValueError(f"cannot write the picture to {path}")


def ask(link: Link, key: str, msg: Message, timeout: float) -> Any:
    replies, nonce = link.get(key, msg, timeout)
    for r in replies:
        if r.ok is None:
            continue
        try:
            raw = take_payload(r.ok.payload, trust.MAX_SEALED_BYTES)
            rep = decode(link.open(key, raw, nonce, reply=True))
        except ProtocolError as exc:
            GUARD.reject(f"reply on {key}", exc)
            continue
        if isinstance(rep, ErrorReply):
            raise WorldError(f"the world says: {rep.reason}")
        return rep
    raise WorldError(f"no reply on {key} within {timeout:g} s (is the world running?)")


def truth(link: Link, timeout: float, after: float = -1.0) -> TruthPosesMsg:
    """The first truth message with ``t_sim`` >= ``after``."""
    q: Inbox[bytes] = Inbox({"truth": 16})
    key = KEY_WORLD_TRUTH_POSES

    def on_truth(s: Any) -> None:
        q.put("truth", link.open(key, take_payload(s.payload, MAX_PUBLICATION_BYTES)))

    sub = link.session.declare_subscriber(
        KEY_WORLD_TRUTH_POSES, GUARD.wrap(on_truth, KEY_WORLD_TRUTH_POSES)
    )
    try:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                m = decode(q.get(timeout=0.1)[1], expect=TruthPosesMsg)
            except queue.Empty:
                continue
            except ProtocolError as exc:
                GUARD.reject(KEY_WORLD_TRUTH_POSES, exc)
                continue
            if m.t_sim >= after:
                return m
        raise WorldError("no truth poses from the world")
    finally:
        sub.undeclare()


def _print_poses(m: TruthPosesMsg) -> None:
    print(f"t_sim {m.t_sim:.2f} s, contacts {m.contacts}")
    for rid, x, y, th in m.poses:
        print(f"  robot {rid:3d}: x {x:+.3f} m  y {y:+.3f} m  heading {math.degrees(th):+7.2f}°")


def identity(args: argparse.Namespace) -> str:
    """Whose key the client acts with: ``--as``, else the one the command needs."""
    if args.as_:
        return str(args.as_)
    if args.cmd in ("camera", "walk", "turn"):
        return f"robot-{args.robot}"
    if args.cmd == "register":
        if args.want < 0:
            raise ValueError("with credentials, register --want N: a key claims its own id")
        return f"robot-{args.want}"
    return "observer"


def run(args: argparse.Namespace, session: Link) -> int:
    t = args.timeout
    if args.cmd == "camera":
        rep = ask(session, key_camera(args.robot), CameraRequest(yaw=math.radians(args.yaw)), t)
        assert isinstance(rep, CameraReply)
        save_picture(rep, args.out)
        print(
            f"robot {rep.robot_id} yaw {math.degrees(rep.yaw):+.1f}° t_sim {rep.t_sim:.2f}: {args.out}"
        )
    elif args.cmd in ("walk", "turn"):
        last = 0.0
        for _ in range(args.times):
            if args.cmd == "walk":
                rep = ask(session, key_walk(args.robot), WalkRequest(distance=args.amount), t)
            else:
                msg = TurnRequest(angle=math.radians(args.amount))
                rep = ask(session, key_turn(args.robot), msg, t)
            assert isinstance(rep, CommandReply)
            print(
                f"{args.cmd} robot {rep.robot_id}: {rep.status} at t_sim {rep.t_sim:.2f} {rep.detail}"
            )
            last = rep.t_sim
            if rep.status != "done":
                return 1
        if session.verifier is None or args.as_ == "observer":
            _print_poses(truth(session, t, after=last))
    elif args.cmd == "poses":
        _print_poses(truth(session, t))
    elif args.cmd == "register":
        rep = ask(session, KEY_WORLD_REGISTER, RegisterRequest(want=args.want), t)
        assert isinstance(rep, RegisterReply)
        print(f"claimed robot {rep.robot_id}")
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m sim.server.client", description=__doc__.split("\n")[0]
    )
    add_network_arguments(p, ("peer", "client"))
    p.add_argument("--as", dest="as_", default="", help="act with this identity's key")
    p.add_argument("--timeout", type=float, default=60.0, help="seconds to wait for a reply")
    sub = p.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("camera", help="save a robot's camera image")
    c.add_argument("robot", type=int)
    c.add_argument("--yaw", type=float, default=0.0, help="head yaw, degrees (+ left)")
    c.add_argument("--out", default="view.png")
    for name, unit in (("walk", "metres (negative: backwards)"), ("turn", "degrees (+ CCW)")):
        w = sub.add_parser(name, help=f"{name} a robot, then print the truth poses")
        w.add_argument("robot", type=int)
        w.add_argument("amount", type=float, help=unit)
        w.add_argument("--times", type=int, default=1, help="repeat the command")
    sub.add_parser("poses", help="print the ground-truth poses")
    r = sub.add_parser("register", help="claim a robot id")
    r.add_argument("--want", type=int, default=-1)
    args = p.parse_args(argv)
    cfg = zenoh.Config()
    try:
        spec = network_spec(args, identity(args))
        for k, v in spec.json5_items():
            cfg.insert_json5(k, v)
        with zenoh.open(cfg) as session:
            return run(args, Link(session, spec))
    except WorldError as exc:
        print(f"sim.server.client: {exc}", file=sys.stderr)
        return 1
    except (ValueError, OSError) as exc:  # ProtocolError is a ValueError
        print(f"sim.server.client: {exc}", file=sys.stderr)
        return 2
    except zenoh.ZError as exc:
        print(f"sim.server.client: zenoh: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
