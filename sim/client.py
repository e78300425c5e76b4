"""``python -m sim.client``: poke a running world by hand (camera, walk, turn, poses).

A small command-line client of the world's bus contract (DESIGN.md §3), for people
trying the world and for debugging; agents use ``agent/robot.py`` instead::

    python -m sim.client --connect tcp/127.0.0.1:7447 camera 1 --yaw 30 --out v.png
    python -m sim.client --connect tcp/127.0.0.1:7447 walk 1 0.2 --times 5
    python -m sim.client --connect tcp/127.0.0.1:7447 turn 1 -15
    python -m sim.client --connect tcp/127.0.0.1:7447 poses

Angles on the command line are degrees. ``poses`` reads ``world/truth/poses``
(evaluation data: fine for a person, never for an agent). Exit status 0 on success,
1 if the world refused or did not answer, 2 on bad arguments.
"""

from __future__ import annotations

import argparse
import json
import math
import queue
import sys
import time
from pathlib import Path
from typing import Any

import zenoh

from agent.protocol import (
    KEY_WORLD_REGISTER,
    KEY_WORLD_TRUTH_POSES,
    MAX_MESSAGE_BYTES,
    MAX_PUBLICATION_BYTES,
    CameraReply,
    CameraRequest,
    CommandReply,
    ErrorReply,
    Guard,
    Inbox,
    Message,
    ProtocolError,
    RegisterReply,
    RegisterRequest,
    TruthPosesMsg,
    TurnRequest,
    WalkRequest,
    decode,
    encode,
    key_camera,
    key_turn,
    key_walk,
    take_payload,
)


class WorldError(RuntimeError):
    """The world refused a request or did not answer."""


#: Counts and logs (cut, rate limited) what this client refuses; never raises.
GUARD = Guard(lambda line: print(f"sim.client: {line}", file=sys.stderr))


def ask(session: Any, key: str, msg: Message, timeout: float) -> Any:
    for r in session.get(key, payload=encode(msg), timeout=timeout):
        if r.ok is None:
            continue
        try:
            rep = decode(take_payload(r.ok.payload, MAX_MESSAGE_BYTES))
        except ProtocolError as exc:
            GUARD.reject(f"reply on {key}", exc)
            continue
        if isinstance(rep, ErrorReply):
            raise WorldError(f"the world says: {rep.reason}")
        return rep
    raise WorldError(f"no reply on {key} within {timeout:g} s (is the world running?)")


def truth(session: Any, timeout: float, after: float = -1.0) -> TruthPosesMsg:
    """The first truth message with ``t_sim`` >= ``after``."""
    q: Inbox[bytes] = Inbox({"truth": 16})

    def on_truth(s: Any) -> None:
        q.put("truth", take_payload(s.payload, MAX_PUBLICATION_BYTES))

    sub = session.declare_subscriber(
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


def run(args: argparse.Namespace, session: Any) -> int:
    t = args.timeout
    if args.cmd == "camera":
        rep = ask(session, key_camera(args.robot), CameraRequest(yaw=math.radians(args.yaw)), t)
        assert isinstance(rep, CameraReply)
        Path(args.out).write_bytes(rep.data)
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
        _print_poses(truth(session, t, after=last))
    elif args.cmd == "poses":
        _print_poses(truth(session, t))
    elif args.cmd == "register":
        rep = ask(session, KEY_WORLD_REGISTER, RegisterRequest(want=args.want), t)
        assert isinstance(rep, RegisterReply)
        print(f"claimed robot {rep.robot_id}")
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m sim.client", description=__doc__.split("\n")[0])
    p.add_argument("--connect", action="append", default=[], help="zenoh endpoint of the world")
    p.add_argument("--no-multicast-scouting", action="store_true")
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
        if args.connect:
            cfg.insert_json5("connect/endpoints", json.dumps(list(args.connect)))
        if args.no_multicast_scouting:
            cfg.insert_json5("scouting/multicast/enabled", "false")
        with zenoh.open(cfg) as session:
            return run(args, session)
    except WorldError as exc:
        print(f"sim.client: {exc}", file=sys.stderr)
        return 1
    except (ValueError, OSError) as exc:  # ProtocolError is a ValueError
        print(f"sim.client: {exc}", file=sys.stderr)
        return 2
    except zenoh.ZError as exc:
        print(f"sim.client: zenoh: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
