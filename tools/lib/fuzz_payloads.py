"""Hostile payloads for the wire codec and the world, made from a seed (every input hardened;
docs/design.md §3: decoding validates types, ranges and sizes and rejects what does not fit; §8:
every message bounded and validated).

The generators of ``python -m tools.fuzz`` and tests/wire/test_fuzz.py (the runner, the
measurements and their report are in :mod:`tools.fuzz`):

- **Mutants** (:func:`payloads`): each derived from a valid message of its type
  (:data:`SAMPLES`, typical and at the limits): structure mutations (wrong types, extra
  and missing fields, odd versions and tags, long sequences, text/binary keys), byte
  mutations (flips, truncation, insertion, msgpack type bytes) and random bytes.
- **Worst payloads** (:func:`worst_payloads`): what costs the decoder the most memory at
  or under the size limit (8 MiB of empty arrays, nesting, short strings, the largest
  valid image message, ...).
- **Malformed world requests** (:func:`malformed_requests`): (key, payload) of every kind
  the world's callbacks check, none of which the world takes as well-formed (a valid
  camera request would cost a render).

Deterministic: ``random.Random`` seeded per (seed, type), no global RNG.
"""

from __future__ import annotations

import math
import random
from collections.abc import Callable, Iterator
from typing import Any

import msgpack

from agent import wire as P

# ===================================================================== mutants


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
        "scenario?": [P.ScenarioRequest()],
        "scenario": [P.ScenarioReply(scenario=b'{"seed": 7}')],
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
        "thumbnail": [
            P.CameraMsg(robot=2, seq=0, t_sim=0.0, width=160, height=120, jpeg=b"\xff\xd8\xff\xe0"),
            P.CameraMsg(
                robot=P.MAX_ROBOT_ID,
                seq=41,
                t_sim=12.5,
                width=P.MAX_THUMBNAIL_WIDTH,
                height=P.MAX_THUMBNAIL_HEIGHT,
                jpeg=b"\xff\xd8\xff" + bytes(range(256)) * 16,
                yaw=1.2,
                detections=tuple(
                    P.CameraDetection(id=i, box=(10 * i, 5, 9, 30), d=0.5 + 0.1 * i, phi=0.05 * i)
                    for i in range(P.MAX_CAMERA_DETECTIONS)
                ),
            ),
        ],
        "reshape": [
            P.ReshapeMsg(
                command=1, base="ab" * 32, name="line", rule="line", orient="width",
                shape_digest="cd" * 32,
            ),
            P.ReshapeMsg(
                command=2**31 - 1, base="ab" * 32, name="w" * 64, rule="tree", orient="depth",
                shape_digest="cd" * 32,
                slots=tuple((k // 2, 0.8, 2.356) for k in range(P.MAX_SHAPE_SLOTS)),
            ),
        ],
    }  # fmt: skip
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


# ===================================================================== worst payloads


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


# ===================================================================== world requests


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
