"""``python -m tools.fuzz``: attack the wire codec and the world as an attacker would (issue #8).

    python -m tools.fuzz --n 1000000 [--seed 1] [--json FILE]
    python -m tools.fuzz --n 0 --flood                  (start a world on loopback)
    python -m tools.fuzz --n 0 --connect tcp/HOST:7447  (flood a running world)

Three measurements:

1. **Fuzz**: ``--n`` payloads, spread evenly over the message types, each derived from a
   valid message of its type (structure mutations: wrong types, extra and missing
   fields, odd versions and tags, long sequences, text/binary keys; byte mutations:
   flips, truncation, insertion, msgpack type bytes; random bytes) and fed to
   :func:`agent.wire.decode`. Prints per type: accepted / rejected (ProtocolError) /
   crashed (any other exception: a bug) and the time. Target: 0 crashes in 10^6.
2. **Memory** (``--no-memory`` skips it): the peak memory of decoding each of the worst
   payloads under the size limit (8 MiB of empty arrays, nesting, 8 MiB of short
   strings, the largest valid image message, ...), measured with ``tracemalloc``.
   Target: under 50 MB for any single payload.
3. **Flood** (``--flood`` or ``--connect``): 10 000 malformed requests (``--flood-n``) sent
   to a world without waiting, then a valid camera request, timed against the same
   request on an idle world. Target: delayed by under 1 s.

Exit status 0 when every target is met, 1 otherwise, 2 on bad arguments.
The generators are shared with tests/test_fuzz.py, which runs a shorter fuzz in CI.
"""

from __future__ import annotations

import argparse
import json
import math
import random
import shutil
import statistics
import sys
import threading
import time
import tracemalloc
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgpack

from agent import wire as P
from tools.harness.procs import free_port, start_world, stop, wait_ready

MEMORY_TARGET = 50 * 1024 * 1024
FLOOD_TARGET_S = 1.0

# ===================================================================== generators


def valid_samples() -> dict[str, list[P.Message]]:
    """Valid messages of every type (typical and at the limits), by tag."""
    big_rec = P.NeighborRecordMsg(
        sender=P.MAX_ROBOT_ID,
        round=1_000_000,
        neighbours=tuple((float(i), -float(i)) for i in range(P.MAX_NEIGHBOURS)),
        orientations=tuple(0.1 * (i % 20) for i in range(P.MAX_NEIGHBOURS)),
        confidences=tuple(1.0 / (1 + i) for i in range(P.MAX_NEIGHBOURS)),
    )
    out: dict[str, list[P.Message]] = {
        "record": [
            P.NeighborRecordMsg(sender=2, round=0, neighbours=((0.5, 1.0), (-0.7, 0.2))),
            P.NeighborRecordMsg(
                sender=1,
                round=3,
                neighbours=((0.5, 1.0),),
                orientations=(0.1,),
                confidences=(0.9,),
            ),
            big_rec,
        ],
        "digest": [
            P.DigestMsg(sender=1, round=0, digest="a" * 64, members=(0, 1, 2)),
            P.DigestMsg(sender=0, round=2, digest="0f" * 32, members=tuple(range(40))),
        ],
        "status": [
            P.StatusMsg(
                sender=1,
                phase="move",
                progress=0.5,
                detail="wave 1",
                plan_digest="0" * 64,
                wave=1,
                t_sim=12.5,
                bytes_sent=900,
            ),
            P.StatusMsg(sender=3, phase="failed", error="é" * P.MAX_TEXT),
        ],
        "register": [P.RegisterRequest(), P.RegisterRequest(want=3)],
        "registered": [P.RegisterReply(robot_id=4)],
        "camera": [P.CameraRequest(yaw=0.3), P.CameraRequest()],
        "image": [
            P.CameraReply(
                robot_id=1,
                yaw=-1.0,
                t_sim=3.0,
                width=640,
                height=480,
                encoding="png",
                data=b"\x89PNG\r\n\x1a\n" + bytes(range(256)),
            ),
        ],
        "walk": [P.WalkRequest(distance=0.2), P.WalkRequest(distance=-50.0)],
        "turn": [P.TurnRequest(angle=-0.26)],
        "done": [P.CommandReply(robot_id=1, status="contact", t_sim=4.0, detail="robot 2")],
        "error": [P.ErrorReply(reason="unknown robot 9")],
        "clock": [P.ClockMsg(t_sim=1.0)],
        "truth": [
            P.TruthPosesMsg(t_sim=1.0, poses=((1, 0.0, 0.5, 1.57), (2, 1.0, -1.0, 0.0))),
            P.TruthPosesMsg(t_sim=9.0, poses=tuple((i, 0.1 * i, 1.0, 0.0) for i in range(200))),
        ],
        "contact": [P.ContactMsg(t_sim=2.0, a=1, b=-1)],
        "recordset?": [P.RecordSetRequest(digest="ab" * 32)],
        "recordset": [
            P.RecordSetReply(
                sender=2,
                digest="ab" * 32,
                records=tuple(
                    P.encode(P.NeighborRecordMsg(sender=i, round=0, neighbours=((1.0, 0.5),)))
                    for i in (1, 2)
                ),
            )
        ],
    }
    assert set(out) == set(P.message_types()), "every message type needs a sample"
    return out


SAMPLES = valid_samples()
TAGS = tuple(sorted(SAMPLES))
_WIRE = {tag: [m.to_wire() for m in msgs] for tag, msgs in SAMPLES.items()}
_ENCODED = {tag: [P.encode(m) for m in msgs] for tag, msgs in SAMPLES.items()}
_ODD_VERSIONS = (True, False, 1.0, 0, 2, -1, "1", b"1", None, [1], 2**64 - 1)
_TYPE_BYTES = (0xC0, 0xC1, 0xC2, 0xC3, 0xC4, 0xC6, 0xC7, 0xCA, 0xCB, 0xD4, 0xD9, 0xDB,
               0xDC, 0xDD, 0xDE, 0xDF, 0x80, 0x8F, 0x90, 0x9F, 0xA0, 0xBF, 0xFF, 0x7F)  # fmt: skip
_FLOATS = (math.nan, math.inf, -math.inf, -0.0, 1e308, -1e308, 5e-324, 1000.0000001, 0.5)
_INTS = (0, 1, -1, 2**31, 2**32, 2**63 - 1, -(2**63), 2**64 - 1, 65535, 65536, -2)


def random_text(rng: random.Random, n: int) -> str:
    alphabet = "ab0 9é\u0661²\u200b\ufeff\U0001f600/\\\"'\n"
    return "".join(rng.choice(alphabet) for _ in range(n))


def random_obj(rng: random.Random, depth: int = 3) -> Any:
    """A random msgpack-able object: odd numbers, text, binary, lists, maps."""
    r = rng.random()
    if depth <= 0 or r < 0.55:
        k = rng.randrange(9)
        if k == 0:
            return None
        if k == 1:
            return rng.random() < 0.5
        if k == 2:
            return rng.choice(_INTS)
        if k == 3:
            return rng.randint(-1000, 70000)
        if k == 4:
            return rng.choice(_FLOATS)
        if k == 5:
            return rng.uniform(-2000.0, 2000.0)
        if k == 6:
            return random_text(rng, rng.choice((0, 1, 5, 64, 600)))
        if k == 7:
            return rng.randbytes(rng.choice((0, 1, 8, 100)))
        return rng.choice(TAGS)
    if r < 0.8:
        return [random_obj(rng, depth - 1) for _ in range(rng.choice((0, 1, 2, 4, 17)))]
    keys: list[Any] = [random_text(rng, 3), rng.randbytes(2), rng.randint(0, 9), "v", "t"]
    return {rng.choice(keys): random_obj(rng, depth - 1) for _ in range(rng.randrange(5))}


def mutate_struct(rng: random.Random, wire: dict[str, Any]) -> Any:
    """1-3 structure mutations of a message's wire map."""
    obj: Any = dict(wire)
    for _ in range(rng.randint(1, 3)):
        if not isinstance(obj, dict):
            break
        names = [k for k in obj if k not in ("v", "t")] or ["v"]
        op = rng.randrange(11)
        name = rng.choice(names)
        obj.setdefault(name, None)
        if op <= 2:
            obj[name] = random_obj(rng)
        elif op == 3:
            obj.pop(name, None)
        elif op == 4:
            obj[rng.choice((random_text(rng, 4), rng.randbytes(3), str(name).encode()))] = 1
        elif op == 5:
            obj["v"] = rng.choice(_ODD_VERSIONS)
        elif op == 6:
            obj["t"] = rng.choice((*TAGS, random_obj(rng, 1)))
        elif op == 7 and isinstance(obj[name], list):
            item = obj[name][0] if obj[name] else random_obj(rng, 1)
            obj[name] = obj[name] + [item] * rng.choice((1, 63, 64, 65, 1025))
        elif op == 8:
            other = rng.choice(names)
            obj[name], obj[other] = obj.get(other), obj.get(name)
        elif op == 9:
            obj = rng.choice((list(obj.values()), list(obj.items()), obj.get(name)))
        else:
            v = obj[name]
            if isinstance(v, float | int) and not isinstance(v, bool):
                obj[name] = rng.choice((*_FLOATS, *_INTS, True, str(v)))
            elif isinstance(v, str):
                obj[name] = rng.choice((v.encode(), v * 9, v.upper(), v[:-1], None))
            else:
                obj[name] = rng.choice((v, [v], {name: v}, None))
    return obj


def pack(rng: random.Random, obj: Any) -> bytes | None:
    try:
        return bytes(msgpack.packb(obj, use_bin_type=rng.random() < 0.85))
    except (TypeError, ValueError, OverflowError):  # not packable (e.g. an int over 2**64)
        return None


def mutate_bytes(rng: random.Random, data: bytes) -> bytes:
    """1-4 byte-level mutations: flips, msgpack type bytes, cuts, insertions, copies."""
    b = bytearray(data)
    for _ in range(rng.randint(1, 4)):
        op = rng.randrange(7)
        i = rng.randrange(len(b)) if b else 0
        if op == 0 and b:
            b[i] ^= 1 << rng.randrange(8)
        elif op == 1 and b:
            b[i] = rng.choice(_TYPE_BYTES)
        elif op == 2:
            del b[i:]
        elif op == 3:
            b[i:i] = rng.randbytes(rng.choice((1, 2, 4, 9)))
        elif op == 4 and b:
            j = rng.randrange(i, len(b) + 1)
            b[j:j] = b[i:j]
        elif op == 5 and b:
            b[i : i + 4] = rng.choice(
                (b"\xff\xff\xff\xff", b"\x00\x00\x00\x00", b"\x7f\xff\xff\xff")
            )
        else:
            b += rng.randbytes(rng.randrange(1, 8))
    return bytes(b)


def fuzz_payload(rng: random.Random, tag: str) -> bytes:
    """One hostile payload derived from a valid message of type ``tag``."""
    r = rng.random()
    k = rng.randrange(len(_WIRE[tag]))
    if r < 0.45:
        data = pack(rng, mutate_struct(rng, _WIRE[tag][k]))
        if data is not None:
            return data
    if r < 0.85:
        return mutate_bytes(rng, _ENCODED[tag][k])
    if r < 0.95:
        data = pack(rng, mutate_struct(rng, _WIRE[tag][k]))
        return mutate_bytes(rng, data if data is not None else _ENCODED[tag][k])
    return rng.randbytes(rng.randrange(0, 40))


def payloads(seed: int, tag: str, n: int) -> Iterator[bytes]:
    rng = random.Random(f"{seed}/{tag}")
    for _ in range(n):
        yield fuzz_payload(rng, tag)


# ===================================================================== fuzz


@dataclass
class TypeCounts:
    accepted: int = 0
    rejected: int = 0
    crashed: int = 0
    seconds: float = 0.0
    crashes: list[str] = field(default_factory=list)  # first few: exception and payload


def decode_one(data: bytes, c: TypeCounts) -> None:
    try:
        P.decode(data)
        c.accepted += 1
    except P.ProtocolError:
        c.rejected += 1
    except Exception as exc:  # the bug this tool hunts
        c.crashed += 1
        if len(c.crashes) < 5:
            c.crashes.append(f"{type(exc).__name__}: {P.reason(exc, 120)} on {data[:64].hex()}")


def fuzz(
    n: int, seed: int = 1, progress: Callable[[str], None] | None = None
) -> dict[str, TypeCounts]:
    """``n`` payloads spread over the message types through ``decode``."""
    per = max(1, math.ceil(n / len(TAGS))) if n > 0 else 0
    out: dict[str, TypeCounts] = {}
    for tag in TAGS:
        c = TypeCounts()
        t0 = time.perf_counter()
        for data in payloads(seed, tag, per):
            decode_one(data, c)
        c.seconds = time.perf_counter() - t0
        out[tag] = c
        if progress is not None:
            progress(f"{tag:10s} {per} payloads in {c.seconds:.1f} s")
    return out


# ===================================================================== memory


def worst_payloads() -> dict[str, bytes]:
    """Payloads at or under ``MAX_MESSAGE_BYTES`` that cost the decoder the most."""
    lim = P.MAX_MESSAGE_BYTES
    mib8 = 8 * 1024 * 1024

    def arr32(n: int) -> bytes:
        return b"\xdd" + n.to_bytes(4, "big")

    str2k = b"\xda" + (2048).to_bytes(2, "big") + b"a" * 2048  # max string, 1 object
    strings = arr32(4) + (b"\xdc\x03\xfc" + str2k * 1020) * 4  # 4080 x 2 KiB of text
    four_byte = "\U0001f600" * 512  # 2048 bytes of UTF-8, 512 characters
    big_image = P.CameraReply(robot_id=1, yaw=0.0, t_sim=0.0, width=640, height=480,
                              encoding="png", data=b"\x00" * P.MAX_IMAGE_BYTES)  # fmt: skip
    image_extra = dict(big_image.to_wire(), extra=1)
    floats = arr32(8) + (b"\xdc\x03\xfe" + (b"\xcb" + b"\x3f\xf0" + b"\x00" * 6) * 1022) * 8
    maps = arr32(240) + (b"\xdf\x00\x00\x00\x10" + b"".join(
        b"\xa2k" + bytes([65 + i]) + b"\xc0" for i in range(16)))  * 240  # fmt: skip
    out = {
        "8 MiB of empty arrays (was 580 MiB)": arr32(1000) + b"\x90" * (mib8 - 5),
        "8 MiB of nested 1-arrays": b"\x91" * mib8,
        "8 MiB array header, no items": arr32(2**32 - 1) + b"\x00" * (mib8 - 5),
        "4080 strings of 2 KiB (8 MiB)": strings,
        "4-byte UTF-8 strings": msgpack.packb([four_byte] * 1000),
        "8185 float objects": floats,
        "240 maps of 16 fields (7921 objects)": maps,
        "record with 8 Mi empty neighbours": msgpack.packb(
            {"v": 1, "t": "record", "sender": 1, "round": 0}
        )[: -0 or None].replace(b"\x84", b"\x85", 1)
        + b"\xaaneighbours"
        + arr32(8 * 1024 * 1024 - 64)
        + b"\x90" * (8 * 1024 * 1024 - 64),
        "largest valid image (accepted)": P.encode(big_image),
        "largest image + unknown field": msgpack.packb(image_extra, use_bin_type=True),
        "binary 32 header of 4 GiB": b"\xc6\xff\xff\xff\xff" + b"\x00" * (mib8 - 5),
        "truth for 1024 robots (accepted)": P.encode(
            P.TruthPosesMsg(t_sim=1.0, poses=tuple((i, 1.0, 1.0, 0.0) for i in range(1024)))
        ),
    }
    for name, data in out.items():
        assert len(data) <= lim, f"{name}: {len(data)} bytes over the limit"
    return out


@dataclass
class MemoryResult:
    name: str
    size: int
    peak: int
    seconds: float
    outcome: str


def memory(names: list[str] | None = None) -> list[MemoryResult]:
    """Peak traced memory of taking each worst payload out of a zenoh ``ZBytes`` and
    decoding it, as the bus and the world do (the ZBytes itself, in zenoh's memory, is
    not counted; the copy out of it is)."""
    import zenoh

    out = []
    for name, raw in worst_payloads().items():
        if names and name not in names:
            continue
        zb = zenoh.ZBytes(raw)
        tracemalloc.start()
        tracemalloc.reset_peak()
        base = tracemalloc.get_traced_memory()[0]
        t0 = time.perf_counter()
        try:
            msg = P.decode(P.take_payload(zb, P.MAX_MESSAGE_BYTES))
            outcome = f"accepted {type(msg).__name__}"
            del msg
        except P.ProtocolError as exc:
            outcome = f"rejected: {P.reason(exc, 70)}"
        except Exception as exc:
            outcome = f"CRASHED {P.reason(exc, 70)}"
        dt = time.perf_counter() - t0
        peak = tracemalloc.get_traced_memory()[1] - base
        tracemalloc.stop()
        out.append(MemoryResult(name, len(raw), peak, dt, outcome))
    return out


# ===================================================================== flood


def _world_accepts(key: str, payload: bytes | None) -> bool:
    """Whether the world's callback would take this request as well-formed (the flood
    must be malformed only: a valid camera request costs a render)."""
    kind = key.rsplit("/", 1)[-1]
    cls = {"camera": P.CameraRequest, "walk": P.WalkRequest, "turn": P.TurnRequest,
           "register": P.RegisterRequest}[kind]  # fmt: skip
    if payload is None:
        return kind in ("camera", "register")
    try:
        msg = P.decode(payload, expect=cls, max_bytes=P.MAX_REQUEST_BYTES)
        if kind != "register":
            P.id_from_key(key)
    except P.ProtocolError:
        return False
    return not (isinstance(msg, P.CameraRequest) and abs(msg.yaw) > P.HEAD_YAW_LIMIT + 1e-9)


def malformed_requests(rng: random.Random, n: int) -> Iterator[tuple[str, bytes | None]]:
    """(key, payload) of ``n`` malformed world requests of every kind the callbacks check."""
    kinds: list[Callable[[], tuple[str, bytes | None]]] = [
        lambda: (P.key_camera(1), rng.randbytes(rng.randrange(1, 40))),
        lambda: (P.key_camera(1), fuzz_payload(rng, "camera")),
        lambda: (P.key_walk(2), fuzz_payload(rng, "walk")),
        lambda: (P.key_turn(3), fuzz_payload(rng, "turn")),
        lambda: (P.key_camera(9), P.encode(P.CameraRequest(yaw=0.0))),  # no such robot
        lambda: ("world/robot/01/camera", P.encode(P.CameraRequest(yaw=0.0))),  # alias
        lambda: (P.key_camera(1), b"\x91" * 2000),  # over MAX_REQUEST_BYTES: never copied
        lambda: (P.key_walk(1), None),
        lambda: (P.KEY_WORLD_REGISTER, fuzz_payload(rng, "register")),
    ]
    made = 0
    while made < n:
        key, payload = kinds[made % len(kinds)]()
        if key.startswith("world/robot/") and key.split("/")[2] == "9":
            pass  # well-formed but for a robot the world does not have
        elif _world_accepts(key, payload):
            continue
        made += 1
        yield key, payload


@dataclass
class FloodResult:
    n: int
    baseline_s: list[float]
    send_s: float
    during_s: float
    after_s: float
    error_replies: int
    finished: int
    all_done_s: float = math.nan  # from the first malformed request to the last one's end
    world_summary: str = ""

    @property
    def delay_s(self) -> float:
        return self.during_s - statistics.median(self.baseline_s)


def _timed_camera(session: Any, timeout: float = 60.0) -> float:
    t0 = time.perf_counter()
    for r in session.get(
        P.key_camera(1), payload=P.encode(P.CameraRequest(yaw=0.2)), timeout=timeout
    ):
        if r.ok is not None and isinstance(P.decode(r.ok.payload.to_bytes()), P.CameraReply):
            return time.perf_counter() - t0
    raise RuntimeError("no camera reply")


def flood(endpoint: str | None, n: int = 10_000, seed: int = 1) -> FloodResult:
    """Baseline camera requests, then ``n`` malformed requests without waiting and a valid
    camera request timed while they are served. Starts a world when ``endpoint`` is None."""
    import zenoh

    world = None
    log_dir = None
    if endpoint is None:
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        import tempfile

        log_dir = Path(tempfile.mkdtemp(prefix="fuzz-world-"))
        world = start_world(3, 7, endpoint, log_dir, [])
    cfg = zenoh.Config()
    cfg.insert_json5("connect/endpoints", json.dumps([endpoint]))
    cfg.insert_json5("scouting/multicast/enabled", "false")
    rng = random.Random(seed)
    counts = {"error": 0, "done": 0}
    last_done = [0.0]
    lock = threading.Lock()

    def on_reply(r: Any) -> None:
        if r.ok is not None:
            with lock:
                counts["error"] += 1

    def on_done() -> None:
        with lock:
            counts["done"] += 1
            last_done[0] = time.perf_counter()

    try:
        if world is not None:
            wait_ready(world, 120.0)
        with zenoh.open(cfg) as s:
            deadline = time.monotonic() + 60.0
            while True:  # until the route to the world exists
                try:
                    _timed_camera(s, 5.0)
                    break
                except RuntimeError:
                    if time.monotonic() > deadline:
                        raise
            baseline = [_timed_camera(s) for _ in range(5)]
            t0 = time.perf_counter()
            for key, payload in malformed_requests(rng, n):
                s.get(
                    key, zenoh.handlers.Callback(on_reply, on_done), payload=payload, timeout=30.0
                )
            send = time.perf_counter() - t0
            during = _timed_camera(s)
            after = _timed_camera(s)
            end = time.monotonic() + 60.0
            while time.monotonic() < end and counts["done"] < n:
                time.sleep(0.05)  # polling the reply counter, bounded by the deadline
        result = FloodResult(
            n, baseline, send, during, after, counts["error"], counts["done"], last_done[0] - t0
        )
    finally:
        if world is not None:
            stop(world, 30.0)
    if log_dir is not None:
        log_path = log_dir / "world.log"
        lines = [ln for ln in log_path.read_text(errors="replace").splitlines() if "served" in ln]
        result.world_summary = lines[-1] if lines else ""
        shutil.rmtree(log_dir)
    return result


# ===================================================================== main


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tools.fuzz", description=__doc__.split("\n")[0])
    ap.add_argument(
        "--n", type=int, default=100_000, help="fuzzed payloads in all (default 100000)"
    )
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--no-memory", action="store_true", help="skip the memory measurement")
    ap.add_argument("--flood", action="store_true", help="flood a world started on loopback")
    ap.add_argument("--connect", default=None, help="flood the running world at this endpoint")
    ap.add_argument("--flood-n", type=int, default=10_000, help="malformed requests (10000)")
    ap.add_argument("--json", type=Path, default=None, help="write the results here")
    args = ap.parse_args(argv)
    if args.n < 0 or args.flood_n < 1:
        print("fuzz: --n must be >= 0 and --flood-n >= 1", file=sys.stderr)
        return 2
    ok = True
    report: dict[str, Any] = {"seed": args.seed}
    if args.n:
        t0 = time.perf_counter()
        res = fuzz(args.n, args.seed, progress=lambda s: print(s, file=sys.stderr, flush=True))
        total = time.perf_counter() - t0
        print(f"{'type':10s} {'accepted':>9s} {'rejected':>9s} {'crashed':>8s} {'time':>8s}")
        for tag, c in res.items():
            print(f"{tag:10s} {c.accepted:9d} {c.rejected:9d} {c.crashed:8d} {c.seconds:7.1f}s")
            for line in c.crashes:
                print(f"    crash: {line}")
        n = sum(c.accepted + c.rejected + c.crashed for c in res.values())
        crashed = sum(c.crashed for c in res.values())
        print(f"{'all':10s} {sum(c.accepted for c in res.values()):9d} "
              f"{sum(c.rejected for c in res.values()):9d} {crashed:8d} {total:7.1f}s "
              f"({n / total:,.0f} payloads/s)")  # fmt: skip
        report["fuzz"] = {tag: vars(c) for tag, c in res.items()}
        report["fuzz_total"] = {"n": n, "crashed": crashed, "seconds": total}
        ok &= crashed == 0
    if not args.no_memory:
        print(
            f"\n{'worst payload under the size limit':38s} {'size':>9s} {'peak':>9s} {'time':>8s}"
        )
        mem = memory()
        for m in mem:
            print(f"{m.name:38s} {m.size / 2**20:6.2f} MiB {m.peak / 2**20:6.2f} MiB "
                  f"{1000 * m.seconds:6.1f} ms  {m.outcome}")  # fmt: skip
        worst = max(mem, key=lambda m: m.peak)
        print(f"worst: {worst.name}: {worst.peak / 2**20:.1f} MiB (target < 50 MB)")
        report["memory"] = [vars(m) for m in mem]
        ok &= worst.peak < MEMORY_TARGET and not any("CRASHED" in m.outcome for m in mem)
    if args.flood or args.connect:
        fr = flood(args.connect, args.flood_n, args.seed)
        base = statistics.median(fr.baseline_s)
        print(f"\nflood: {fr.n} malformed requests sent in {fr.send_s:.2f} s")
        print(f"  valid camera request: idle {base:.3f} s (median of 5), during the flood "
              f"{fr.during_s:.3f} s, after {fr.after_s:.3f} s: delayed {fr.delay_s:+.3f} s "
              f"(target < {FLOOD_TARGET_S:g} s)")  # fmt: skip
        print(f"  malformed: {fr.error_replies} error replies, {fr.finished} queries finished, "
              f"the last {fr.all_done_s:.2f} s after the first was sent")  # fmt: skip
        if fr.world_summary:
            print(f"  world: {fr.world_summary}")
        report["flood"] = dict(vars(fr), delay_s=fr.delay_s)
        ok &= fr.delay_s < FLOOD_TARGET_S
    if args.json is not None:
        args.json.write_text(json.dumps(report, indent=1, default=str))
    print("\nall targets met" if ok else "\nTARGET MISSED")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
