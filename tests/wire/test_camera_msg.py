"""The camera frames agents publish for viewers: ``CameraMsg`` on
``nao/{id}/camera``, its bounds and every validation error, its key and the access
control and signatures that keep a robot to its own camera."""

from __future__ import annotations

import math
import re
from typing import Any

import msgpack
import pytest

from agent import wire as P
from agent.wire import trust as T
from tests.fakes import FakeZBytes

JPEG = b"\xff\xd8\xff\xe0" + b"\x00" * 100


def frame(**kw: Any) -> dict[str, Any]:
    """A valid camera frame's wire map, with ``kw`` replacing fields."""
    msg = P.CameraMsg(
        robot=3,
        seq=5,
        t_sim=2.0,
        width=160,
        height=120,
        jpeg=JPEG,
        yaw=0.5,
        detections=(P.CameraDetection(id=0, box=(150, 0, 10, 120), d=1.1, phi=0.4),),
    )
    return {**msg.to_wire(), **kw}


def det(**kw: Any) -> dict[str, Any]:
    return {"id": 1, "box": [0, 0, 5, 5], "d": 1.0, "phi": 0.0, **kw}


def test_round_trip_and_wire_form() -> None:
    wire = frame()
    msg = P.decode(msgpack.packb(wire, use_bin_type=True), expect=P.CameraMsg)
    assert msg.detections[0] == P.CameraDetection(id=0, box=(150, 0, 10, 120), d=1.1, phi=0.4)
    assert P.encode(msg) == msgpack.packb(wire, use_bin_type=True)
    # each detection is a map of exactly id, box, d, phi on the wire
    assert wire["detections"] == [{"id": 0, "box": [150, 0, 10, 120], "d": 1.1, "phi": 0.4}]
    assert wire["t"] == "thumbnail" and wire["t_sim"] == 2.0
    # dicts are accepted on construction too, and validated the same way
    m = P.CameraMsg(
        robot=1, seq=0, t_sim=0.0, width=1, height=1, jpeg=JPEG, detections=(det(box=[0, 0, 1, 1]),)
    )
    assert m.detections[0].box == (0, 0, 1, 1)


def test_the_largest_frame_fits_the_publication_bound() -> None:
    big = P.CameraMsg(
        robot=P.MAX_ROBOT_ID,
        seq=2**53,
        t_sim=1e9,
        width=P.MAX_THUMBNAIL_WIDTH,
        height=P.MAX_THUMBNAIL_HEIGHT,
        jpeg=b"\xff\xd8\xff" + b"\x01" * (P.MAX_THUMBNAIL_BYTES - 3),
        yaw=-P.HEAD_YAW_LIMIT,
        detections=tuple(
            P.CameraDetection(id=P.MAX_ROBOT_ID, box=(0, 0, 320, 240), d=100.0, phi=-6.0)
            for _ in range(P.MAX_CAMERA_DETECTIONS)
        ),
    )
    sealed_overhead = 128  # the envelope (tests/wire/test_trust.py: under 100 B)
    assert len(P.encode(big)) + sealed_overhead <= P.MAX_CAMERA_PUBLICATION_BYTES
    assert P.MAX_CAMERA_PUBLICATION_BYTES <= P.MAX_PUBLICATION_BYTES
    assert P.decode(P.encode(big)) == big


@pytest.mark.parametrize(
    ("change", "reason"),
    [
        ({"robot": -1}, "robot: -1 outside"),
        ({"robot": "2"}, "robot: expected int"),
        ({"seq": -1}, "seq: -1 outside"),
        ({"seq": 1.0}, "seq: expected int"),
        ({"t_sim": -0.5}, "t_sim: -0.5 outside"),
        ({"t_sim": math.nan}, "t_sim: nan is not finite"),
        ({"width": 0}, "width: 0 outside"),
        ({"width": 640}, "width: 640 outside"),
        ({"height": 241}, "height: 241 outside"),
        ({"jpeg": "text"}, "jpeg: expected bytes"),
        ({"jpeg": b"\x89PNG\r\n\x1a\n"}, "not a JPEG image"),
        ({"jpeg": b""}, "not a JPEG image"),
        ({"jpeg": b"\xff\xd8\xff" + bytes(P.MAX_THUMBNAIL_BYTES)}, "jpeg: 32771 bytes, at most"),
        ({"yaw": 2.5}, "yaw: 2.5 outside"),
        ({"yaw": True}, "yaw: expected a number"),
        ({"detections": {"id": 1}}, "detections: expected a list"),
        ({"detections": [det()] * 17}, "detections: 17 items, at most 16"),
        ({"detections": [[1, [0, 0, 5, 5], 1.0, 0.0]]}, "detection: expected a map"),
        ({"detections": [{"id": 1, "box": [0, 0, 5, 5], "d": 1.0}]}, "expected exactly the keys"),
        ({"detections": [det(x=1)]}, "expected exactly the keys"),
        ({"detections": [det(id=-2)]}, "id: -2 outside"),
        ({"detections": [det(box=[0, 0, 5])]}, "box: expected a list of 4 items"),
        ({"detections": [det(box=[0, 0, -1, 5])]}, "box: -1 outside"),
        ({"detections": [det(box=[0, 0, 5.0, 5])]}, "box: expected int"),
        ({"detections": [det(box=[150, 0, 11, 5])]}, "outside the 160x120 thumbnail"),
        ({"detections": [det(box=[0, 100, 5, 21])]}, "outside the 160x120 thumbnail"),
        ({"detections": [det(d=-0.1)]}, "d: -0.1 outside"),
        ({"detections": [det(d=math.inf)]}, "d: inf is not finite"),
        ({"detections": [det(phi=7.0)]}, "phi: 7.0 outside"),
        ({"detections": [det(phi="0")]}, "phi: expected a number"),
    ],
)
def test_every_validation_error_has_its_reason(change: dict[str, Any], reason: str) -> None:
    data = msgpack.packb(frame(**change), use_bin_type=True)
    with pytest.raises(P.ProtocolError, match=re.escape(reason)):
        P.decode(data)


def test_missing_fields_are_refused_and_defaults_apply() -> None:
    wire = frame()
    del wire["jpeg"]
    with pytest.raises(P.ProtocolError, match=r"thumbnail: .*jpeg"):
        P.decode(msgpack.packb(wire, use_bin_type=True))
    wire = frame()
    del wire["yaw"], wire["detections"]
    msg = P.decode(msgpack.packb(wire, use_bin_type=True))
    assert (msg.yaw, msg.detections) == (0.0, ())


def test_an_oversized_frame_is_never_copied() -> None:
    with pytest.raises(P.ProtocolError, match="exceeds"):
        P.take_payload(
            FakeZBytes(P.MAX_CAMERA_PUBLICATION_BYTES + 1), P.MAX_CAMERA_PUBLICATION_BYTES
        )


def test_camera_key_is_the_robots_own() -> None:
    assert P.key_camera_feed(4) == "nao/4/camera"
    assert P.id_from_key(P.key_camera_feed(4)) == 4
    assert P.KEY_CAMERA_FEED_ALL == "nao/*/camera"
    assert P.key_camera(4) == "world/robot/4/camera"  # the world's queryable, not this
    with pytest.raises(P.ProtocolError):
        P.key_camera_feed(-1)


# --------------------------------------------------------------------------- trust


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> T.Credentials:
    root = tmp_path_factory.mktemp("cam") / "fleet"
    T.create_fleet(root, [1, 2])
    return T.Credentials(root)


def test_the_acl_lets_a_robot_put_only_its_own_camera(fleet: T.Credentials) -> None:
    acl = T.acl_settings(fleet.roster)
    rules = {r["id"]: r for r in acl["rules"]}
    policies = {p["id"]: p["rules"] for p in acl["policies"]}

    def may_put(cn: str, key: str) -> bool:
        import zenoh

        return any(
            "put" in rules[r]["messages"]
            and "ingress" in rules[r]["flows"]
            and any(zenoh.KeyExpr(k).includes(zenoh.KeyExpr(key)) for k in rules[r]["key_exprs"])
            for r in policies[cn]
        )

    assert may_put("robot-2", P.key_camera_feed(2))
    assert not may_put("robot-2", P.key_camera_feed(1))
    assert not may_put("robot-1", P.key_camera_feed(2))
    assert not may_put("observer", P.key_camera_feed(2))
    assert not may_put("world", P.key_camera_feed(2))
    # the observer may subscribe to every robot's camera and have it delivered
    observer_rules = [rules[r] for r in policies["members"]]
    assert (
        "observer" in next(s for s in acl["subjects"] if s["id"] == "members")["cert_common_names"]
    )
    for flow, message in (("ingress", "declare_subscriber"), ("egress", "put")):
        assert any(
            flow in r["flows"] and message in r["messages"] and "nao/**" in r["key_exprs"]
            for r in observer_rules
        )


def test_a_frame_signed_by_another_robot_is_refused(fleet: T.Credentials) -> None:
    from agent.net.bus import Bus, BusConfig

    msg = P.CameraMsg(robot=2, seq=0, t_sim=0.0, width=160, height=120, jpeg=JPEG)
    forged = fleet.signer(T.Identity.robot(1)).seal(P.key_camera_feed(2), P.encode(msg))
    genuine = fleet.signer(T.Identity.robot(2)).seal(P.key_camera_feed(2), P.encode(msg))
    cfg = BusConfig(
        multicast_scouting=False, credentials=str(fleet.root), identity="observer", tls=False
    )
    with Bus(cfg) as bus:
        bus._enqueue_sample(P.key_camera_feed(2), forged)
        assert bus.stats.untrusted == 1 and bus.drain() == []
        bus._enqueue_sample(P.key_camera_feed(2), genuine)
        (ev,) = bus.drain()
        assert ev.msg == msg and ev.signer == "robot-2"
