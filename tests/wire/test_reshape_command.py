"""The operator's reshape command (agent/wire/command.py): its bounds, its signer, the ACL."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import pytest

from agent import wire as P
from agent.wire import trust as T

BASE = "ab" * 32
SHAPE = "cd" * 32


def command(**kw: Any) -> P.ReshapeMsg:
    fields: dict[str, Any] = {
        "command": 1,
        "base": BASE,
        "name": "line",
        "rule": "line",
        "orient": "width",
        "shape_digest": SHAPE,
    }
    fields.update(kw)
    return P.ReshapeMsg(**fields)


def test_a_builtin_and_a_tree_round_trip() -> None:
    for msg in (
        command(),
        command(name="v", rule="tree", slots=((0, 0.8, 2.3), (1, 0.8, -2.3))),
    ):
        assert P.decode(P.encode(msg), expect=P.ReshapeMsg) == msg


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"command": 0}, "command: 0 outside"),
        ({"command": True}, "command: expected int"),
        ({"base": "AB" * 32}, "base: expected 64 lowercase hex"),
        ({"shape_digest": ""}, "shape_digest: expected 64"),
        ({"name": ""}, "a shape needs a name"),
        ({"name": "n" * 65}, "name: 65 characters"),
        ({"rule": "Line"}, "rule: 'Line' is not a lowercase word"),
        ({"rule": "x" * 17}, "rule: 17 characters"),
        ({"orient": "depth width"}, "orient: 'depth width' is not"),
        ({"rule": "tree"}, "a tree shape needs at least one child slot"),
        ({"slots": ((0, 0.8, 0.0),)}, "the built-in rule 'line' takes none"),
        ({"rule": "tree", "slots": ((1, 0.8, 0.0),)}, r"slots\[0\]: parent 1 is not an earlier"),
        ({"rule": "tree", "slots": ((0, -0.1, 0.0),)}, "slot distance: -0.1 outside"),
        ({"rule": "tree", "slots": ((0, 0.8, 11.0),)}, "slot angle: 11.0 outside"),
        ({"rule": "tree", "slots": ((0, 0.8),)}, "slot: expected a list of 3 items"),
        (
            {"rule": "tree", "slots": ((0, 0.8, 0.1),) * (P.MAX_SHAPE_SLOTS + 1)},
            "slots: 1024 items",
        ),
    ],
)
def test_every_bad_field_is_refused(kw: dict[str, Any], match: str) -> None:
    with pytest.raises(P.ProtocolError, match=match):
        command(**kw)


def test_the_largest_command_fits_a_publication() -> None:
    slots = tuple((k, 99.5, -9.5) for k in range(P.MAX_SHAPE_SLOTS))
    big = command(name="n" * 64, rule="tree", slots=slots, command=2**31 - 1)
    assert len(P.encode(big)) < P.MAX_PUBLICATION_BYTES


# --------------------------------------------------------------------------- trust


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> T.Credentials:
    root = tmp_path_factory.mktemp("reshape") / "fleet"
    T.create_fleet(root, [1, 2])
    return T.Credentials(root)


def test_a_fleet_has_an_operator_identity(fleet: T.Credentials) -> None:
    op = T.Identity("operator")
    assert op in fleet.roster and op.cn == "operator"
    assert T.Identity.parse("operator") == op == T.Identity.from_code(op.code)


def test_a_command_signed_by_a_robot_key_is_refused(fleet: T.Credentials) -> None:
    from agent.net.bus import Bus, BusConfig

    data = P.encode(command())
    forged = fleet.signer(T.Identity.robot(1)).seal(P.KEY_RESHAPE, data)
    by_world = fleet.signer(T.Identity("world")).seal(P.KEY_RESHAPE, data)
    genuine = fleet.signer(T.Identity("operator")).seal(P.KEY_RESHAPE, data)
    cfg = BusConfig(
        multicast_scouting=False, credentials=str(fleet.root), identity="robot-2", tls=False
    )
    with Bus(cfg) as bus:
        bus._enqueue_sample(P.KEY_RESHAPE, forged)
        bus._enqueue_sample(P.KEY_RESHAPE, by_world)
        assert bus.stats.untrusted == 2 and bus.drain() == []
        bus._enqueue_sample(P.KEY_RESHAPE, genuine)
        (ev,) = bus.drain()
        assert ev.msg == command() and ev.signer == "operator"


def test_the_operator_key_speaks_for_no_robot(fleet: T.Credentials) -> None:
    from agent.net.bus import Bus, BusConfig

    status = P.StatusMsg(sender=1, phase="done")
    forged = fleet.signer(T.Identity("operator")).seal(P.key_status(1), P.encode(status))
    cfg = BusConfig(
        multicast_scouting=False, credentials=str(fleet.root), identity="robot-2", tls=False
    )
    with Bus(cfg) as bus:
        bus._enqueue_sample(P.key_status(1), forged)
        assert bus.stats.untrusted == 1 and bus.drain() == []


def _may(acl: dict[str, Any], cn: str, message: str, flow: str, key: str) -> bool:
    import zenoh

    rules = {r["id"]: r for r in acl["rules"]}
    ids = [r for p in acl["policies"] if cn in _names(acl, p["subjects"]) for r in p["rules"]]
    return any(
        message in rules[r]["messages"]
        and flow in rules[r]["flows"]
        and any(zenoh.KeyExpr(k).includes(zenoh.KeyExpr(key)) for k in rules[r]["key_exprs"])
        for r in ids
    )


def _names(acl: dict[str, Any], subjects: list[str]) -> set[str]:
    return {n for s in acl["subjects"] if s["id"] in subjects for n in s["cert_common_names"]}


def test_the_acl_lets_only_the_operator_publish_a_command(fleet: T.Credentials) -> None:
    acl = T.acl_settings(fleet.roster)
    assert _may(acl, "operator", "put", "ingress", P.KEY_RESHAPE)
    for cn in ("robot-1", "robot-2", "world", "observer"):
        assert not _may(acl, cn, "put", "ingress", P.KEY_RESHAPE), cn
    # every robot hears it, and the router delivers it
    for cn in ("robot-1", "robot-2"):
        assert _may(acl, cn, "declare_subscriber", "ingress", P.KEY_RESHAPE)
        assert _may(acl, cn, "put", "egress", P.KEY_RESHAPE)
    # the operator hears the fleet's statuses and publishes nothing of a robot's
    assert _may(acl, "operator", "declare_subscriber", "ingress", P.key_status(1))
    assert not _may(acl, "operator", "put", "ingress", P.key_status(1))


def test_without_an_operator_key_nobody_may_command(fleet: T.Credentials) -> None:
    roster = {who: k for who, k in fleet.roster.items() if who.role != "operator"}
    acl = T.acl_settings(roster)
    assert not any(s["id"] == "operator" for s in acl["subjects"])
    assert not _may(acl, "robot-1", "put", "ingress", P.KEY_RESHAPE)
    assert replace(command(), command=2).command == 2
