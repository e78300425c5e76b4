"""The agreed record set by digest (for agents restarted after a crash): served by every agent,
checked by the asker.

Pure checks (agent/phases/record_sets.py, used by agent/recovery/runs.py), the restored
agreement (agent/core/agreement.py), and the query over real zenoh sessions: plain, and
through a TLS router with the fleet's access control. (The membership's acceptance of a
restarted member's new session: tests/phases/test_membership.py.)
"""

from __future__ import annotations

import math
import signal
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import pytest

from agent.core.agreement import Agreement
from agent.net.bus import Bus, BusConfig, BusError
from agent.phases.record_sets import answer, record_set
from agent.recovery.runs import agreed_by_others
from agent.wire import (
    KEY_RECORDS_ALL,
    NeighborRecordMsg,
    RecordSetReply,
    RecordSetRequest,
    StatusMsg,
    canonical_digest,
    encode,
    key_records,
    records_of,
)
from agent.wire.trust import Identity, TrustError, create_fleet
from tests.fakes import zb
from tests.phases.fakes import records

REPO = Path(__file__).resolve().parents[2]


def agreed() -> Agreement:
    a = Agreement.restored(3, records(), 0.0, params="ab" * 32, digest_fn=canonical_digest)
    assert a.agreed
    return a


def test_restored_agreement_has_the_digest_of_the_normal_one() -> None:
    recs = records()
    a = Agreement(1, recs[0], 0.0, fleet_size=3, digest_fn=canonical_digest)
    for r in recs[1:]:
        a.member_joined(r.sender, 0.0)
        a.on_record(r, 0.0)
    members, digest = a.digest()
    d = agreed().decide(1.0)
    assert d.kind == "agreed" and d.digest == digest == canonical_digest(recs)
    assert d.members == members == (1, 2, 3) and d.records == recs
    assert agreed().due(0.0) == ["digest"]  # until the others report a post-agreement phase


def test_restored_agreement_errors() -> None:
    with pytest.raises(ValueError, match="repeat a sender"):
        Agreement.restored(1, (records()[0], records()[0]), 0.0, digest_fn=canonical_digest)
    with pytest.raises(ValueError, match="none of robot 9"):
        Agreement.restored(9, records(), 0.0, digest_fn=canonical_digest)


def test_answer_only_the_set_asked_for() -> None:
    d = agreed().decide(0.0)
    served = record_set(3, d)
    assert answer(served, RecordSetRequest(digest=d.digest)) is served
    assert answer(served, RecordSetRequest(digest="0" * 64)) is None
    assert answer(served, RecordSetRequest(digest="")) is served  # any agreed set
    assert answer(None, RecordSetRequest(digest=d.digest)) is None
    assert answer(served, StatusMsg(sender=1, phase="done")) is None
    assert records_of(served, d.digest, d.members) == records()


def _reply(recs: tuple[bytes, ...], digest: str) -> RecordSetReply:
    return RecordSetReply(sender=1, digest=digest, records=recs)


@pytest.mark.parametrize(
    ("case", "match"),
    [
        ("other digest", "not the one asked for"),
        ("undecodable", "record set from robot 1"),
        ("missing member", "covers"),
        ("unsorted", "covers"),
        ("tampered", "hashes to"),
    ],
)
def test_records_of_each_error_branch(case: str, match: str) -> None:
    recs = records()
    digest = canonical_digest(recs)
    wire = tuple(encode(r) for r in recs)
    members = (1, 2, 3)
    if case == "other digest":
        rep = _reply(wire, "0" * 64)
    elif case == "undecodable":
        rep = _reply((b"\x80", *wire[1:]), digest)
    elif case == "missing member":
        rep = _reply(wire[:2], digest)
    elif case == "unsorted":
        rep = _reply((wire[1], wire[0], wire[2]), digest)
    else:
        forged = NeighborRecordMsg(sender=3, round=0, neighbours=((5.0, 5.0),))
        rep = _reply((*wire[:2], encode(forged)), digest)
    with pytest.raises(ValueError, match=match):
        records_of(rep, digest, members)


def test_reply_signed_by_another_robot_than_the_key_names_is_refused(tmp_path: Path) -> None:
    create_fleet(tmp_path / "fleet", [1, 2])
    from agent.wire.trust import Credentials

    creds = Credentials(tmp_path / "fleet")
    bus = Bus.__new__(Bus)  # only the reply check, no session
    bus.verifier = creds.verifier()
    signer2 = creds.signer(Identity.robot(2))
    asker = creds.signer(Identity.robot(1))
    _, nonce = asker.seal_request(KEY_RECORDS_ALL, b"")
    sealed = signer2.seal(key_records(1), encode(RecordSetRequest(digest="0" * 64)), bind=nonce)
    ok = SimpleNamespace(payload=zb(sealed), key_expr=key_records(1))
    with pytest.raises(TrustError, match="not robot-1"):
        bus._reply_message(KEY_RECORDS_ALL, SimpleNamespace(ok=ok), nonce)
    mine = signer2.seal(key_records(2), encode(RecordSetRequest(digest="0" * 64)), bind=nonce)
    ok2 = SimpleNamespace(payload=zb(mine), key_expr=key_records(2))
    got = bus._reply_message(KEY_RECORDS_ALL, SimpleNamespace(ok=ok2), nonce)
    assert got == RecordSetRequest(digest="0" * 64)


def _free_port() -> int:
    from tools.harness.procs import free_port

    return free_port()


def _fetch(bus: Bus, digest: str, members: tuple[int, ...], deadline: float = 20.0) -> object:
    end = time.monotonic() + deadline
    last: Exception | None = None
    while time.monotonic() < end:
        try:
            return bus.query(
                KEY_RECORDS_ALL,
                RecordSetRequest(digest=digest),
                RecordSetReply,
                2.0,
                lambda rep: "" if records_of(rep, digest, members) else "bad",
            )
        except BusError as exc:  # routes not built yet
            last = exc
            time.sleep(0.2)  # polling for the route, bounded by the deadline
    raise AssertionError(f"no record set: {last}")


@pytest.mark.system
def test_record_set_query_over_plain_sessions() -> None:
    ep = f"tcp/127.0.0.1:{_free_port()}"
    a = Bus(BusConfig(listen=(ep,), multicast_scouting=False))
    b = Bus(BusConfig(connect=(ep,), multicast_scouting=False))
    try:
        d = agreed().decide(0.0)
        served = record_set(3, d)
        a.serve(key_records(3), lambda req: answer(served, req))
        rep = _fetch(b, d.digest, d.members)
        assert rep == served
        # a restarted agent whose record the others agreed on adopts their set
        assert agreed_by_others(b, records()[0]) == (d.digest, (1, 2, 3))
        stranger = NeighborRecordMsg(sender=1, round=0, neighbours=((3.0, 3.0),))
        assert agreed_by_others(b, stranger) is None  # not with another record of ours
        # an unknown digest: nobody answers (no reply), never a wrong set
        with pytest.raises(BusError):
            b.query(KEY_RECORDS_ALL, RecordSetRequest(digest="0" * 64), RecordSetReply, 1.0)
        # a request that does not decode is counted and gets no reply
        before = a.stats.rejected
        a._on_query(
            SimpleNamespace(payload=zb(b"\x80"), key_expr=key_records(3)), "k", lambda r: None
        )
        assert a.stats.rejected == before + 1
    finally:
        b.close()
        a.close()


@pytest.mark.system
def test_record_set_query_through_the_secure_router(tmp_path: Path) -> None:
    """Robot 3 serves; robot 1 asks through a TLS router with the fleet's access
    control: the query and the reply pass, signed by robot 3."""
    fleet = tmp_path / "fleet"
    create_fleet(fleet, [1, 2, 3])
    ep = f"tls/127.0.0.1:{_free_port()}"
    router = subprocess.Popen(
        [sys.executable, "-m", "tools.router", "--credentials", str(fleet), "--listen", ep,
         "--no-multicast-scouting"],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, cwd=str(REPO),
    )  # fmt: skip

    def spec(who: str) -> BusConfig:
        return BusConfig(
            connect=(ep,), multicast_scouting=False, mode="client",
            credentials=str(fleet), identity=who,
        )  # fmt: skip

    try:
        assert router.stdout is not None and "router ready" in router.stdout.readline()
        server, asker = Bus(spec("robot-3")), Bus(spec("robot-1"))
        try:
            d = agreed().decide(0.0)
            served = record_set(3, d)
            server.serve(key_records(3), lambda req: answer(served, req))
            rep = _fetch(asker, d.digest, d.members)
            assert isinstance(rep, RecordSetReply) and rep.sender == 3
            assert records_of(rep, d.digest, d.members) == records()
        finally:
            asker.close()
            server.close()
    finally:
        router.send_signal(signal.SIGTERM)
        router.wait(timeout=15)


def test_digest_of_records_is_order_independent() -> None:
    recs = records()
    assert canonical_digest(recs) == canonical_digest(tuple(reversed(recs)))
    assert math.isfinite(len(recs))
