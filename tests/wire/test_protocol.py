"""Round trips and rejections of the wire codec (agent/wire/)."""

from __future__ import annotations

import json
import math
import queue
import threading

import msgpack
import pytest

from agent import wire as p
from tests.fakes import FakeZBytes

SAMPLES: list[p.Message] = [
    p.NeighborRecordMsg(
        sender=2,
        round=0,
        neighbours=((0.5, 1.0), (-0.7, 0.2)),
        orientations=(0.1, 3.0),
        confidences=(0.9, 0.7),
    ),
    p.NeighborRecordMsg(sender=0, round=3, neighbours=()),
    p.NeighborRecordMsg(sender=4, round=0, neighbours=((1.0, 0.0),), obstacles=((0.4, -1.2),)),
    p.DigestMsg(sender=1, round=0, digest="a" * 64, members=(0, 1, 2)),
    p.StatusMsg(
        sender=1,
        phase="move",
        progress=0.5,
        detail="wave 1",
        plan_digest="0" * 64,
        wave=1,
        t_sim=12.5,
        bytes_sent=900,
    ),
    p.RegisterRequest(),
    p.RegisterReply(robot_id=4),
    p.ScenarioRequest(),
    p.ScenarioReply(scenario=b'{"seed": 7}'),
    p.CameraRequest(yaw=0.3),
    p.CameraReply(
        robot_id=1, yaw=-1.0, t_sim=3.0, width=640, height=480, encoding="png", data=b"\x89PNG..."
    ),
    p.WalkRequest(distance=0.2, request_id=12),
    p.WalkRequest(distance=0.0, request_id=13, lateral=-0.05),
    p.TurnRequest(angle=-0.26, request_id=p.MAX_REQUEST_ID),
    p.CommandReply(robot_id=1, status="done", t_sim=4.0),
    p.ErrorReply(reason="unknown robot 9"),
    p.ClockMsg(t_sim=1.0),
    p.TruthPosesMsg(t_sim=1.0, poses=((1, 0.0, 0.5, 1.57),), contacts=0),
    p.ContactMsg(t_sim=2.0, a=1, b=-1),
    p.RecordSetRequest(digest="ab" * 32),
    p.RecordSetReply(sender=2, digest="ab" * 32, records=(b"\x80",)),
    p.CameraMsg(
        robot=2,
        seq=7,
        t_sim=3.5,
        width=160,
        height=120,
        jpeg=b"\xff\xd8\xff\xe0 a thumbnail",
        yaw=-0.4,
        detections=(p.CameraDetection(id=0, box=(10, 20, 30, 60), d=1.2, phi=-0.3),),
    ),
    p.ReshapeMsg(
        command=3,
        base="ab" * 32,
        name="v",
        rule="tree",
        orient="width",
        shape_digest="cd" * 32,
        slots=((0, 0.8, 2.3), (0, 0.8, -2.3)),
    ),
]


def test_every_message_type_has_a_sample() -> None:
    assert {type(m) for m in SAMPLES} == set(p.message_types().values())


@pytest.mark.parametrize("msg", SAMPLES, ids=lambda m: m.TAG)
def test_round_trip(msg: p.Message) -> None:
    assert p.decode(p.encode(msg)) == msg
    assert p.decode(p.encode(msg), expect=type(msg)) == msg


def _raw(**obj: object) -> bytes:
    return msgpack.packb(obj, use_bin_type=True)


@pytest.mark.parametrize(
    ("payload", "reason"),
    [
        (b"\xc1", "not msgpack"),
        (_raw(), "schema version"),
        (msgpack.packb([1, 2]), "expected a map"),
        (_raw(v=2, t="walk", distance=1.0), "schema version"),
        (_raw(v=1, t="nope"), "unknown message type"),
        (_raw(v=1, t="walk"), "walk"),
        (_raw(v=1, t="walk", distance="far"), "expected a number"),
        (_raw(v=1, t="walk", distance=float("nan")), "not finite"),
        (_raw(v=1, t="walk", distance=1.0, extra=1), "unknown fields"),
        (_raw(v=1, t="registered", robot_id=-1), "outside"),
        (_raw(v=1, t="registered", robot_id=True), "expected int"),
        (_raw(v=1, t="record", sender=1, round=0, neighbours=[[0.0]]), "list of 2"),
        (_raw(v=1, t="record", sender=1, round=0, neighbours=[[0.0, 1.0]] * 129), "at most"),
        (
            _raw(
                v=1, t="record", sender=1, round=0, neighbours=[[0.0, 1.0]], confidences=[0.5, 0.5]
            ),
            "2 values for 1",
        ),
        (_raw(v=1, t="record", sender=1, round=0, neighbours=[], obstacles=[[0.0]]), "list of 2"),
        (
            _raw(v=1, t="record", sender=1, round=0, neighbours=[], obstacles=[[0.0, 1.0]] * 33),
            "obstacles: 33 items",
        ),
        (
            _raw(v=1, t="record", sender=1, round=0, neighbours=[], obstacles=[[1e9, 0.0]]),
            "outside",
        ),
        (_raw(v=1, t="digest", sender=1, round=0, digest="xyz", members=[]), "hex"),
        (_raw(v=1, t="status", sender=1, phase="dancing"), "not one of"),
        (
            _raw(
                v=1,
                t="image",
                robot_id=1,
                yaw=0.0,
                t_sim=0.0,
                width=1,
                height=1,
                encoding="png",
                data="s",
            ),
            "expected bytes",
        ),
        (
            _raw(
                v=1,
                t="image",
                robot_id=1,
                yaw=3.0,
                t_sim=0.0,
                width=1,
                height=1,
                encoding="png",
                data=b"",
            ),
            "outside",
        ),
    ],
)
def test_rejections_carry_a_reason(payload: bytes, reason: str) -> None:
    with pytest.raises(p.ProtocolError, match=reason):
        p.decode(payload)


def test_expect_restricts_type() -> None:
    with pytest.raises(p.ProtocolError, match="expected a 'walk'"):
        p.decode(p.encode(p.TurnRequest(angle=0.1)), expect=p.WalkRequest)


def test_construction_validates() -> None:
    with pytest.raises(p.ProtocolError):
        p.WalkRequest(distance=math.inf)


@pytest.mark.parametrize(
    ("distance", "lateral", "reason"),
    [(0.1, 0.05, "not both"), (0.0, p.MAX_SIDE_STEP + 0.01, "lateral: .*outside")],
)
def test_a_sidestep_is_bounded_and_never_mixed_with_a_walk(
    distance: float, lateral: float, reason: str
) -> None:
    wire = {"v": p.SCHEMA_VERSION, "t": "walk", "distance": distance, "lateral": lateral}
    with pytest.raises(p.ProtocolError, match=reason):
        p.decode(msgpack.packb(wire))


@pytest.mark.parametrize(
    ("rid", "reason"),
    [(-1, "outside"), (p.MAX_REQUEST_ID + 1, "outside"), (1.5, "expected int"), (True, "int")],
)
def test_motion_request_ids_are_bounded_ints(rid: object, reason: str) -> None:
    for cls, field in ((p.WalkRequest, "distance"), (p.TurnRequest, "angle")):
        wire = {"v": p.SCHEMA_VERSION, "t": cls.TAG, field: 0.1, "request_id": rid}
        with pytest.raises(p.ProtocolError, match=f"request_id: .*{reason}"):
            p.decode(msgpack.packb(wire))
    assert p.decode(p.encode(p.WalkRequest(distance=0.1))) == p.WalkRequest(0.1, request_id=0)


def test_keys_and_ids() -> None:
    assert p.key_record(3) == "nao/3/record"
    assert p.key_camera(7) == "world/robot/7/camera"
    for key in (p.key_record(3), p.key_alive(3), p.key_status(3), p.key_walk(3)):
        assert p.id_from_key(key) == 3
    with pytest.raises(p.ProtocolError):
        p.id_from_key("nao/x/record")
    with pytest.raises(p.ProtocolError):
        p.id_from_key("other/1")
    with pytest.raises(p.ProtocolError):
        p.key_record(-1)


def test_network_spec_json5_items() -> None:
    spec = p.NetworkSpec(connect=("tcp/10.0.0.1:7447",), multicast_scouting=False, mode="client")
    lossy = [*p.LOSSY_LINK_SETTINGS, *p.QUIET_SETTINGS]
    assert spec.json5_items() == [
        ("mode", '"client"'),
        *lossy,
        ("connect/endpoints", '["tcp/10.0.0.1:7447"]'),
        ("scouting/multicast/enabled", "false"),
    ]
    router = p.NetworkSpec(mode="router", listen=("tcp/0.0.0.0:7447",))
    assert ("listen/endpoints", '["tcp/0.0.0.0:7447"]') in router.json5_items()
    assert p.NetworkSpec().json5_items() == [
        ("mode", '"peer"'),
        *lossy,
        ("scouting/multicast/enabled", "true"),
    ]


def test_lossy_link_settings_are_accepted_by_zenoh() -> None:
    import zenoh

    cfg = zenoh.Config()
    for key, value in p.LOSSY_LINK_SETTINGS:
        cfg.insert_json5(key, value)
    assert json.loads(cfg.get_json("transport/link/tx/lease")) == 30000
    # a link fails after 3.5 silent keep-alive intervals at least (ITU-T G.8013/Y.1731)
    assert json.loads(cfg.get_json("transport/link/tx/keep_alive")) == 4
    assert json.loads(cfg.get_json("connect"))["timeout_ms"]["client"] == 60000
    for key, value in p.QUIET_SETTINGS:
        cfg.insert_json5(key, value)
    assert json.loads(cfg.get_json("transport/shared_memory/enabled")) is False


@pytest.mark.parametrize(
    ("kwargs", "reason"),
    [
        ({"mode": "server"}, "mode must be"),
        ({"listen": ("localhost:7447",)}, "proto/address"),
        ({"mode": "client", "multicast_scouting": False}, "needs multicast scouting"),
        ({"mode": "router"}, "at least one --listen"),
    ],
)
def test_network_spec_rejects(kwargs: dict[str, object], reason: str) -> None:
    with pytest.raises(ValueError, match=reason):
        p.NetworkSpec(**kwargs)  # type: ignore[arg-type]


# --------------------------------------------------------------------------- strictness


@pytest.mark.parametrize("version", [True, 1.0, "1", None, [1]])
def test_version_must_be_the_int_1(version: object) -> None:
    with pytest.raises(p.ProtocolError, match="schema version"):
        p.decode(_raw(v=version, t="walk", distance=1.0))


@pytest.mark.parametrize(
    "raw",
    ["01", "00", "١", "+1", "-1", " 1", "1 ", "1.0", "", "0x1", "1_0", "²", "123456"],
)
def test_key_ids_are_plain_ascii_digits(raw: str) -> None:
    for key in (f"nao/alive/{raw}", f"nao/{raw}/record", f"world/robot/{raw}/camera"):
        with pytest.raises(p.ProtocolError, match="robot id"):
            p.id_from_key(key)


def test_key_id_range_and_one_spelling_per_robot() -> None:
    assert p.id_from_key("nao/alive/0") == 0
    assert p.id_from_key("nao/alive/65535") == 65535
    with pytest.raises(p.ProtocolError, match="outside"):
        p.id_from_key("nao/alive/65536")
    with pytest.raises(p.ProtocolError, match="at most 256"):
        p.id_from_key("nao/1/" + "x" * 300)
    with pytest.raises(p.ProtocolError, match="key expression"):
        p.id_from_key(b"nao/1/record")  # type: ignore[arg-type]


def test_unknown_fields_mixing_text_and_binary_names_are_rejected() -> None:
    # was a TypeError: sorted() over str and bytes
    data = msgpack.packb({"v": 1, "t": "walk", "distance": 1.0, "a": 1, b"b": 2}, use_bin_type=True)
    with pytest.raises(p.ProtocolError, match="field names must be text"):
        p.decode(data)


def test_many_unknown_fields_give_a_short_reason() -> None:
    fields = {f"f{i:02d}" + "x" * 100: i for i in range(20)}
    with pytest.raises(p.ProtocolError, match="and 16 more") as info:
        p.decode(_raw(v=1, t="walk", distance=1.0, **fields))
    assert len(str(info.value)) < 200


def test_huge_tag_is_cut_in_the_reason() -> None:
    with pytest.raises(p.ProtocolError, match="unknown message type") as info:
        p.decode(_raw(v=1, t="x" * 2000))
    assert len(str(info.value)) < 100


def _bin32(size: int, body: bytes = b"") -> bytes:
    return b"\xc6" + size.to_bytes(4, "big") + body


def _array32(n: int, body: bytes = b"") -> bytes:
    return b"\xdd" + n.to_bytes(4, "big") + body


@pytest.mark.parametrize(
    ("payload", "reason"),
    [
        (b"", "truncated"),
        (b"\x92\x01", "truncated"),
        (b"\xa5ab", "truncated"),
        (b"\xcb\x00", "truncated"),
        (b"\x01\x02", "trailing data"),
        (b"\xc1", "invalid byte 0xc1"),
        (b"\xd6\xff\x00\x00\x00\x01", "ext type"),  # a msgpack Timestamp
        (b"\xc7\x00\x05", "ext type"),
        (b"\x91" * 9 + b"\x90", "nested deeper than 8"),
        (_array32(1025), "array of 1025 entries, at most 1024"),
        (b"\xde" + (33).to_bytes(2, "big"), "map of 33 entries, at most 32"),
        (b"\xdb" + (2049).to_bytes(4, "big"), "string of 2049 bytes, at most 2048"),
        (_bin32(p.MAX_IMAGE_BYTES + 1), "binary of"),
        (
            b"\x9f" + (b"\x9f" + (b"\x9f" + b"\x90" * 15) * 15) * 15,
            "more than 1000 msgpack objects",
        ),
        (b"\xa2\xff\xfe", "not msgpack: UnicodeDecodeError"),
        (msgpack.packb({1: 2}), "not msgpack"),  # int map keys
    ],
)
def test_unpack_bounded_rejects(payload: bytes, reason: str) -> None:
    with pytest.raises(p.ProtocolError, match=reason):
        p.unpack_bounded(payload, max_objects=1000)
    with pytest.raises(p.ProtocolError):
        p.decode(payload)


def test_unpack_bounded_size_and_type() -> None:
    assert p.unpack_bounded(msgpack.packb([1, "a", b"b"], use_bin_type=True)) == [1, "a", b"b"]
    assert p.unpack_bounded(memoryview(msgpack.packb({"k": None}))) == {"k": None}
    with pytest.raises(p.ProtocolError, match="exceeds 3"):
        p.unpack_bounded(b"\x94\x01\x02\x03\x04", max_bytes=3)
    with pytest.raises(p.ProtocolError, match="expected bytes"):
        p.unpack_bounded("text")  # type: ignore[arg-type]
    with pytest.raises(p.ProtocolError, match="exceeds"):
        p.decode(p.encode(p.ErrorReply(reason="x" * 100)), max_bytes=50)
    # an envelope around a whole message: a binary field bigger than an image
    inner = p.encode(
        p.CameraReply(robot_id=1, yaw=0.0, t_sim=0.0, width=1, height=1, encoding="png",
                      data=b"\x00" * p.MAX_IMAGE_BYTES)
    )  # fmt: skip
    env = msgpack.packb({"payload": inner, "sig": b"s" * 64}, use_bin_type=True)
    with pytest.raises(p.ProtocolError, match="binary of"):
        p.unpack_bounded(env, p.MAX_MESSAGE_BYTES + 512)
    got = p.unpack_bounded(env, p.MAX_MESSAGE_BYTES + 512, max_bin_bytes=p.MAX_MESSAGE_BYTES)
    assert p.decode(got["payload"]).width == 1
    with pytest.raises(p.ProtocolError, match="string of 9 bytes, at most 8"):
        p.unpack_bounded(msgpack.packb("x" * 9), max_str_bytes=8)
    deep = b"\x91" * 7 + b"\x90"  # depth 8 is allowed
    assert p.unpack_bounded(deep) == [[[[[[[[]]]]]]]]


def test_objects_limit_bounds_the_largest_message() -> None:
    poses = tuple((i, 1.0, 2.0, 0.5) for i in range(p.MAX_MEMBERS))
    big = p.TruthPosesMsg(t_sim=1.0, poses=poses, contacts=3)
    data = p.encode(big)
    assert len(data) < p.MAX_PUBLICATION_BYTES
    assert p.decode(data, max_bytes=p.MAX_PUBLICATION_BYTES) == big


def test_eight_mib_of_empty_arrays_is_rejected_fast_and_small() -> None:
    # was: 3 s and 580 MiB to reject
    import time
    import tracemalloc

    payloads = [
        _array32(1000, b"\x90" * (8 * 1024 * 1024 - 8)),
        b"\x9f" * (8 * 1024 * 1024),
        b"\xdc\x04\x00" + b"\xdc\x04\x00" * 2000,
    ]
    for data in payloads:
        tracemalloc.start()
        t0 = time.perf_counter()
        with pytest.raises(p.ProtocolError):
            p.decode(data)
        dt = time.perf_counter() - t0
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        assert dt < 0.5 and peak < 50 * 2**20, (dt, peak)


def test_take_payload_checks_the_size_before_the_copy() -> None:
    with pytest.raises(p.ProtocolError, match="exceeds 1024"):
        p.take_payload(FakeZBytes(2**30), 1024)
    with pytest.raises(p.ProtocolError, match="no payload"):
        p.take_payload(None, 1024)
    with pytest.raises(p.ProtocolError, match="said 3 bytes, gave 5"):
        p.take_payload(FakeZBytes(3, b"12345"), 1024)
    assert p.take_payload(FakeZBytes(3, b"123"), 1024) == b"123"


# --------------------------------------------------------------------------- receiving


def test_reason_is_one_short_line() -> None:
    assert p.reason(p.ProtocolError("bad")) == "bad"
    assert p.reason(TypeError("x\ny")) == "TypeError: x y"
    long = p.reason(ValueError("z" * 11_000_000))
    assert len(long) == 200 and long.endswith("...")

    class Unprintable(Exception):
        def __str__(self) -> str:
            raise RuntimeError("no")

    assert p.reason(Unprintable()) == "Unprintable: <unprintable>"


def test_guard_counts_logs_and_throttles() -> None:
    lines: list[str] = []
    counted: list[int] = []
    now = [0.0]
    g = p.Guard(
        lines.append, on_reject=lambda: counted.append(1), burst=2, per_second=1.0,
        clock=lambda: now[0],
    )  # fmt: skip

    def boom(x: int) -> None:
        raise TypeError("t" * 1000)

    cb = g.wrap(boom, "nao/1/status")
    for _ in range(5):
        cb(1)  # never raises
    assert g.rejected == 5 and len(counted) == 5
    assert len(lines) == 2 and g.suppressed == 3
    assert all(len(line) < 300 and "TypeError" in line for line in lines)
    now[0] = 1.0
    g.reject("world/robot/1/camera", "why")
    assert lines[-1].endswith("why (+3 suppressed)")
    ok = g.wrap(lambda x: None, "k")
    ok(1)
    assert g.rejected == 6


def test_guard_survives_a_broken_log_and_counter() -> None:
    def broken(_: object = None) -> None:
        raise OSError("disk full")

    g = p.Guard(broken, on_reject=broken)
    g.wrap(broken, "k")(None)
    assert g.rejected == 1
    with pytest.raises(ValueError, match="burst"):
        p.Guard(print, burst=0)


def test_inbox_drops_oldest_and_counts() -> None:
    box: p.Inbox[int] = p.Inbox({"a": 2, "b": 3})
    assert box.put("a", 1) == 0
    box.put("b", 10)
    box.put("a", 2)
    assert box.put("a", 3) == 1  # the oldest of lane a (1) made room
    assert box.dropped == {"a": 1}
    assert len(box) == 3 and box.lengths() == {"a": 2, "b": 1}
    # arrival order across lanes
    assert [box.get_nowait() for _ in range(3)] == [("b", 10), ("a", 2), ("a", 3)]
    with pytest.raises(queue.Empty):
        box.get_nowait()
    with pytest.raises(queue.Empty):
        box.get(timeout=0.01)


def test_inbox_priority_and_blocking_get() -> None:
    box: p.Inbox[str] = p.Inbox({"first": 4, "then": 4}, priority=True)
    box.put("then", "x")
    box.put("first", "y")
    assert box.get(timeout=1.0) == ("first", "y")
    assert box.get() == ("then", "x")
    t = threading.Timer(0.05, lambda: box.put("then", "late"))
    t.start()
    assert box.get(timeout=10.0) == ("then", "late")
    t.join()
    for caps in ({}, {"a": 0}, {"a": True}):
        with pytest.raises(ValueError, match="capacity"):
            p.Inbox(caps)  # type: ignore[arg-type]
    for weights in ({"a": 0}, {"b": 5}):
        with pytest.raises(ValueError, match="weight cap"):
            p.Inbox({"a": 3}, max_weight=weights)


def test_inbox_weight_cap_drops_oldest_until_the_new_item_fits() -> None:
    box: p.Inbox[str] = p.Inbox({"big": 100, "small": 2}, max_weight={"big": 10})
    assert box.put("big", "x", 4) == 0
    assert box.put("big", "y", 4) == 0
    assert box.put("big", "z", 5) == 1  # x went: 4 + 5 fits
    assert box.weights() == {"big": 9, "small": 0}
    assert box.put("big", "huge", 11) == 1  # heavier than the lane: itself dropped
    assert box.dropped == {"big": 2}
    assert box.get_nowait() == ("big", "y")
    assert box.weights()["big"] == 5
    assert box.put("small", "s", 10**9) == 0  # no weight cap on this lane


def test_status_carries_the_robot_s_own_check() -> None:
    msg = p.StatusMsg(sender=2, phase="done", check_parent=1, r_d=0.031, r_phi=-0.54)
    back = p.decode(p.encode(msg))
    assert back == msg and back.check_parent == 1 and back.r_phi == -0.54
    assert p.decode(p.encode(p.StatusMsg(sender=2, phase="hold"))).check_parent == -1


def test_status_names_the_blocker_of_a_jammed_robot() -> None:
    msg = p.StatusMsg(sender=4, phase="move", blocked_by=2)
    assert p.decode(p.encode(msg)).blocked_by == 2
    assert p.decode(p.encode(p.StatusMsg(sender=4, phase="move"))).blocked_by == -1
    with pytest.raises(p.ProtocolError, match="blocked_by"):
        p.StatusMsg(sender=4, phase="move", blocked_by=-2)


def test_status_carries_the_way_walked_along_the_path() -> None:
    """Finer waits: metres along the planned path, bounded and finite."""
    msg = p.StatusMsg(sender=4, phase="move", walked=12.5)
    assert p.decode(p.encode(msg)).walked == 12.5
    assert p.decode(p.encode(p.StatusMsg(sender=4, phase="move"))).walked == 0.0
    for bad in (-0.1, p.MAX_WALKED * 2, float("nan"), float("inf"), True, "1"):
        with pytest.raises(p.ProtocolError, match="walked"):
            p.StatusMsg(sender=4, phase="move", walked=bad)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("field", "value"), [("check_parent", -2), ("r_d", 1e9), ("r_phi", float("nan"))]
)
def test_status_check_fields_are_bounded(field: str, value: float) -> None:
    with pytest.raises(p.ProtocolError, match=field):
        p.StatusMsg(sender=2, phase="done", **{field: value})


def test_status_carries_the_steps_taken_since_arrival() -> None:
    """A child follows its parent's steps (agent/phases/hold.py)."""
    msg = p.StatusMsg(sender=4, phase="hold", shift_x=-0.15, shift_y=0.05)
    got = p.decode(p.encode(msg))
    assert (got.shift_x, got.shift_y) == (-0.15, 0.05)
    assert p.decode(p.encode(p.StatusMsg(sender=4, phase="hold"))).shift_x == 0.0
    for name in ("shift_x", "shift_y"):
        for bad in (p.MAX_SHIFT + 1.0, -p.MAX_SHIFT - 1.0, math.nan, "0.1"):
            with pytest.raises(p.ProtocolError, match=name):
                p.StatusMsg(sender=4, phase="hold", **{name: bad})  # type: ignore[arg-type]
