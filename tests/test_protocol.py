"""Round trips and rejections of the wire codec (agent/protocol.py)."""

from __future__ import annotations

import math

import msgpack
import pytest

from agent import protocol as p

SAMPLES: list[p.Message] = [
    p.NeighborRecordMsg(
        sender=2,
        round=0,
        neighbours=((0.5, 1.0), (-0.7, 0.2)),
        orientations=(0.1, 3.0),
        confidences=(0.9, 0.7),
    ),
    p.NeighborRecordMsg(sender=0, round=3, neighbours=()),
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
    p.CameraRequest(yaw=0.3),
    p.CameraReply(
        robot_id=1, yaw=-1.0, t_sim=3.0, width=640, height=480, encoding="png", data=b"\x89PNG..."
    ),
    p.WalkRequest(distance=0.2),
    p.TurnRequest(angle=-0.26),
    p.CommandReply(robot_id=1, status="done", t_sim=4.0),
    p.ErrorReply(reason="unknown robot 9"),
    p.ClockMsg(t_sim=1.0),
    p.TruthPosesMsg(t_sim=1.0, poses=((1, 0.0, 0.5, 1.57),), contacts=0),
    p.ContactMsg(t_sim=2.0, a=1, b=-1),
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
        (_raw(v=1, t="record", sender=1, round=0, neighbours=[[0.0, 1.0]] * 65), "at most"),
        (
            _raw(
                v=1, t="record", sender=1, round=0, neighbours=[[0.0, 1.0]], confidences=[0.5, 0.5]
            ),
            "2 values for 1",
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
    assert spec.json5_items() == [
        ("mode", '"client"'),
        ("connect/endpoints", '["tcp/10.0.0.1:7447"]'),
        ("scouting/multicast/enabled", "false"),
    ]
    router = p.NetworkSpec(mode="router", listen=("tcp/0.0.0.0:7447",))
    assert ("listen/endpoints", '["tcp/0.0.0.0:7447"]') in router.json5_items()
    assert p.NetworkSpec().json5_items() == [
        ("mode", '"peer"'),
        ("scouting/multicast/enabled", "true"),
    ]


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
