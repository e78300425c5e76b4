"""zenoh TLS and access-control settings built from the fleet credentials (docs/design.md §8,
layer 2: transport). Pure data: dicts that become JSON5 in ``zenoh.Config``.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from agent.wire.credentials import Credentials
from agent.wire.identity import Identity
from agent.wire.keys import (
    KEY_CAMERA_ALL,
    KEY_RECORDS_ALL,
    KEY_RESHAPE,
    KEY_WORLD_SCENARIO,
    KEY_WORLD_TRUTH_POSES,
)

# --------------------------------------------------------------------------- zenoh settings


def tls_settings(creds: Credentials, who: Identity) -> dict[str, Any]:
    """zenoh ``transport/link/tls``: mutual TLS against the fleet CA with ``who``'s key.

    :class:`TrustError` when ``who``'s certificate is revoked: the process does not start.
    """
    creds.check_active(who)
    key, cert = str(creds.paths.key(who)), str(creds.paths.cert(who))
    return {
        "root_ca_certificate": str(creds.paths.ca),
        "enable_mtls": True,
        "listen_private_key": key,
        "listen_certificate": cert,
        "connect_private_key": key,
        "connect_certificate": cert,
        "verify_name_on_connect": True,
    }


_ALL = [
    "put",
    "delete",
    "declare_subscriber",
    "query",
    "reply",
    "declare_queryable",
    "liveliness_token",
    "liveliness_query",
    "declare_liveliness_subscriber",
]


def _rule(rid: str, messages: list[str], flows: list[str], keys: list[str]) -> dict[str, Any]:
    return {
        "id": rid,
        "messages": messages,
        "flows": flows,
        "permission": "allow",
        "key_exprs": keys,
    }


def acl_settings(roster: Iterable[Identity]) -> dict[str, Any]:
    """zenoh ``access_control`` for a router: deny by default, each common name its role.

    Ingress is what a subject may send; egress what the router may deliver to it. Only
    ``roster`` gets rules: a common name left out of it (a revoked key,
    :class:`~agent.wire.credentials.Credentials` leaves those out) matches no subject, so
    the router denies everything it sends and delivers nothing to it.
    """
    roster = sorted(set(roster))
    rules = [
        # every fleet member may watch membership, hear the fleet's statuses and the
        # operator's commands
        _rule(
            "hear-fleet",
            ["declare_subscriber"],
            ["ingress"],
            ["nao/**", "world/clock", KEY_RESHAPE],
        ),
        _rule(
            "watch-alive",
            ["declare_liveliness_subscriber", "liveliness_query"],
            ["ingress"],
            ["nao/alive/*"],
        ),
        _rule(
            "deliver-fleet",
            ["put", "liveliness_token", "declare_subscriber"],
            ["egress"],
            ["nao/**", "world/clock", KEY_RESHAPE],
        ),
        # the operator: publishes the reshape command, and nothing else; no robot may
        _rule("operator-command", ["put"], ["ingress"], [KEY_RESHAPE]),
        # the agreed record sets (for agents restarted after a crash): any member asks, every robot
        # serves its own
        _rule("ask-records", ["query"], ["ingress"], [KEY_RECORDS_ALL]),
        _rule(
            "deliver-records",
            ["query", "reply", "declare_queryable"],
            ["egress"],
            [KEY_RECORDS_ALL],
        ),
        # the world: serves and publishes world/**, hears membership
        _rule("world-serve", ["declare_queryable", "reply", "put"], ["ingress"], ["world/**"]),
        _rule("world-take", ["query", "declare_subscriber"], ["egress"], ["world/**"]),
        # render workers (cameras drawn by other processes, for large fleets): follow the world's
        # poses, ask its scenario, serve the cameras; nothing else (no walking, no registering, no
        # fleet traffic)
        _rule(
            "render-serve",
            ["declare_queryable", "reply", "query", "declare_subscriber"],
            ["ingress"],
            [KEY_CAMERA_ALL, KEY_WORLD_SCENARIO, KEY_WORLD_TRUTH_POSES],
        ),
        _rule(
            "render-take",
            ["query", "reply", "declare_queryable", "put", "declare_subscriber"],
            ["egress"],
            [KEY_CAMERA_ALL, KEY_WORLD_SCENARIO, KEY_WORLD_TRUTH_POSES],
        ),
        # observers: evaluation reads ground truth too
        _rule("observe", ["declare_subscriber"], ["ingress"], ["world/**"]),
        _rule("observe-deliver", ["put"], ["egress"], ["world/**"]),
    ]
    members = sorted(i.cn for i in roster if i.role not in ("router", "render"))
    subjects: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []
    member_rules = ["hear-fleet", "watch-alive", "deliver-fleet", "ask-records", "deliver-records"]
    roles = [
        ("members", members, member_rules),
        ("world", ["world"] if Identity("world") in roster else [], ["world-serve", "world-take"]),
        (
            "render",
            ["render"] if Identity("render") in roster else [],
            ["render-serve", "render-take"],
        ),
        (
            "observer",
            ["observer"] if Identity("observer") in roster else [],
            ["observe", "observe-deliver"],
        ),
        (
            "operator",
            ["operator"] if Identity("operator") in roster else [],
            ["operator-command"],
        ),
    ]
    for sid, names, rule_ids in roles:
        if names:  # a subject without common names would match nothing (or be refused)
            subjects.append({"id": sid, "cert_common_names": names})
            policies.append({"id": sid, "rules": rule_ids, "subjects": [sid]})
    for who in roster:
        if who.role != "robot":
            continue
        i = who.robot_id
        rules += [
            _rule(f"r{i}-out", ["put"], ["ingress"], [f"nao/{i}/**"]),
            _rule(f"r{i}-alive", ["liveliness_token"], ["ingress"], [f"nao/alive/{i}"]),
            _rule(f"r{i}-serve", ["declare_queryable", "reply"], ["ingress"], [f"nao/{i}/records"]),
            _rule(f"r{i}-ask", ["query"], ["ingress"], [f"world/robot/{i}/**", "world/register"]),
            _rule(
                f"r{i}-answer",
                ["reply", "declare_queryable"],
                ["egress"],
                [f"world/robot/{i}/**", "world/register"],
            ),
        ]
        subjects.append({"id": who.cn, "cert_common_names": [who.cn]})
        policies.append(
            {
                "id": who.cn,
                "rules": [
                    f"r{i}-out",
                    f"r{i}-alive",
                    f"r{i}-serve",
                    f"r{i}-ask",
                    f"r{i}-answer",
                ],
                "subjects": [who.cn],
            }
        )
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }
