"""The observer asks the members for the agreed records it missed (tools/harness/observe.py
``fetch_agreed_records``): a record is published once, and under a flood the router can drop
the observer's copy while the agents agree on it. The set is taken only when it is the
one every member's digest names."""

from __future__ import annotations

from typing import Any

import pytest

from agent.net.bus import BusError
from agent.wire import (
    DigestMsg,
    NeighborRecordMsg,
    RecordSetReply,
    RecordSetRequest,
    canonical_digest,
    encode,
)
from tools.harness import observe
from tools.harness.observe import Observer, fetch_agreed_records

RECORDS = tuple(
    NeighborRecordMsg(sender=i, round=0, neighbours=((0.5 * i, 1.0),)) for i in (1, 2, 3)
)
DIGEST = canonical_digest(RECORDS)


class FakeBus:
    """Answers record-set queries with ``reply(robot)``; records what was asked."""

    def __init__(self, reply: Any) -> None:
        self.reply = reply
        self.asked: list[tuple[str, str]] = []

    def query(self, key: str, msg: Any, expect: type, timeout: float = 10.0) -> Any:
        assert isinstance(msg, RecordSetRequest) and expect is RecordSetReply
        self.asked.append((key, msg.digest))
        robot = int(key.split("/")[1])
        out = self.reply(robot)
        if isinstance(out, Exception):
            raise out
        return out


def _observer(missing: int = 1) -> Observer:
    obs = Observer(t0=0.0)
    for i in (1, 2, 3):
        obs.digests[i] = DigestMsg(sender=i, round=0, digest=DIGEST, members=(1, 2, 3))
    obs.records = {r.sender: r for r in RECORDS if r.sender != missing}
    return obs


def _set(sender: int, records: tuple[NeighborRecordMsg, ...] = RECORDS) -> RecordSetReply:
    return RecordSetReply(sender=sender, digest=DIGEST, records=tuple(encode(r) for r in records))


def test_a_missed_record_is_fetched_by_the_agreed_digest() -> None:
    obs = _observer()
    bus = FakeBus(lambda robot: BusError("no route") if robot == 1 else _set(robot))
    assert fetch_agreed_records(bus, obs)  # type: ignore[arg-type]
    assert obs.records == {r.sender: r for r in RECORDS}
    # robot 1 did not answer; robot 2 did: lowest id first, the first good set taken
    assert bus.asked == [("nao/1/records", DIGEST), ("nao/2/records", DIGEST)]
    assert not fetch_agreed_records(bus, obs)  # type: ignore[arg-type]  # nothing missing


def test_a_set_that_is_not_the_agreed_one_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    """A set whose records do not hash to the digest (a record changed) is not taken, and
    the members are asked at most FETCH_ASKS times, FETCH_GAP s apart."""
    forged = (RECORDS[0].__class__(sender=1, round=0, neighbours=((9.0, 9.0),)), *RECORDS[1:])
    obs = _observer()
    bus = FakeBus(lambda robot: _set(robot, forged))
    monkeypatch.setattr(observe, "FETCH_GAP", 0.0)
    for _ in range(observe.FETCH_ASKS + 2):
        assert not fetch_agreed_records(bus, obs)  # type: ignore[arg-type]
    assert 1 not in obs.records
    assert len(bus.asked) == 3 * observe.FETCH_ASKS  # every member, each ask
    assert obs.fetches[DIGEST][0] == observe.FETCH_ASKS


def test_nothing_is_asked_before_the_members_agree_or_too_soon() -> None:
    obs = _observer()
    obs.digests[3] = DigestMsg(sender=3, round=0, digest="ab" * 32, members=(1, 2, 3))
    bus = FakeBus(lambda robot: _set(robot))
    assert not fetch_agreed_records(bus, obs)  # type: ignore[arg-type]  # two digests
    obs.digests[3] = DigestMsg(sender=3, round=0, digest=DIGEST, members=(1, 2, 3))
    bus = FakeBus(lambda robot: BusError("no route"))
    assert not fetch_agreed_records(bus, obs)  # type: ignore[arg-type]
    assert not fetch_agreed_records(bus, obs)  # type: ignore[arg-type]  # within FETCH_GAP
    assert len(bus.asked) == 3


def test_a_record_of_another_round_is_replaced_by_the_agreed_one() -> None:
    """Every member's record is held, one of another round than the agreed set's: the held
    records do not hash to the digest, so the set is asked and taken as it is; once held,
    nothing more is asked."""
    obs = _observer(missing=0)
    obs.records[2] = NeighborRecordMsg(sender=2, round=1, neighbours=((7.0, 1.0),))
    bus = FakeBus(lambda robot: _set(robot))
    assert fetch_agreed_records(bus, obs)  # type: ignore[arg-type]
    assert obs.records == {r.sender: r for r in RECORDS}
    assert not fetch_agreed_records(bus, obs)  # type: ignore[arg-type]
    assert bus.asked == [("nao/1/records", DIGEST)]


def test_records_that_hash_to_the_digest_are_not_asked_for() -> None:
    obs = _observer(missing=0)
    bus = FakeBus(lambda robot: _set(robot))
    assert not fetch_agreed_records(bus, obs)  # type: ignore[arg-type]
    assert bus.asked == [] and obs.held_digest == DIGEST
