"""Waiting agents cost nothing (agent/phases/membership.py, agent/phases/context.py).

A waiting phase sleeps on the bus's queue until something arrives or its next
deadline, never on a fixed short poll; statuses go out on change, with a slow
heartbeat; and a member that is still searching keeps the agreement open (patience,
agent/core/agreement.py).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from typing import cast

import pytest

from agent.adapters import FormationAdapter
from agent.body.base import Body
from agent.config import AgentConfig
from agent.core.agreement import Agreement
from agent.core.grace import Grace
from agent.net.bus import Bus, BusConfig, Event
from agent.phases.context import Context
from agent.phases.membership import MAX_WAIT, Membership
from agent.phases.reporting import Phase, heartbeat_interval, status_interval
from agent.seams import Perception
from agent.wire import NeighborRecordMsg, StatusMsg, canonical_digest, encode


class _Still:
    """A body that stands still at sim time 0."""

    robot_id = 3
    t_sim = 0.0

    def stop(self) -> None:
        """Nothing moves."""


def _context(bus: Bus, clock: object = time.monotonic, **kw: object) -> Context:
    cfg = AgentConfig(robot_id=3, fleet_size=3, **kw)  # type: ignore[arg-type]
    return Context.of(
        bus, cast(Body, _Still()), cfg, cast(Perception, None), FormationAdapter(), clock
    )  # type: ignore[arg-type]


@pytest.fixture()
def bus() -> Iterator[Bus]:
    with Bus(BusConfig(multicast_scouting=False)) as b:
        yield b


def test_the_wait_returns_at_once_when_something_arrives(bus: Bus) -> None:
    fleet = Membership(_context(bus))
    fleet.handle(Event("alive", "nao/alive/1", robot_id=1))
    status = encode(StatusMsg(sender=1, phase="agree"))
    timer = threading.Timer(0.2, bus._enqueue_sample, ("nao/1/status", status))
    timer.start()
    t0 = time.monotonic()
    fleet.wait_until(t0 + 30.0)
    took = time.monotonic() - t0
    timer.join()
    assert 0.15 <= took < 1.0  # woken by the status, not by a poll nor the deadline
    assert fleet.peer(1).phase == "agree"


def test_the_wait_returns_at_its_deadline_when_nothing_arrives(bus: Bus) -> None:
    fleet = Membership(_context(bus))
    t0 = time.monotonic()
    fleet.wait_until(t0 + 0.3)
    took = time.monotonic() - t0
    assert 0.29 <= took < 0.6


def test_the_wait_sleeps_once_until_its_deadline_without_polling(
    bus: Bus, monkeypatch: pytest.MonkeyPatch
) -> None:
    fleet = Membership(_context(bus))
    sleeps: list[float] = []
    drain = bus.drain

    def counted(timeout: float = 0.0) -> list[Event]:
        sleeps.append(timeout)
        return drain(timeout)

    monkeypatch.setattr(bus, "drain", counted)
    t0 = time.monotonic()
    fleet.wait_until(t0 + 2.5)
    assert 2.49 <= time.monotonic() - t0 < 3.0
    assert len(sleeps) == 1 and sleeps[0] == pytest.approx(2.5, abs=0.05)  # one sleep
    assert MAX_WAIT >= 30.0  # no safety poll: the waits name their deadlines
    monkeypatch.setattr("agent.phases.membership.MAX_WAIT", 0.2)
    t0 = time.monotonic()
    fleet.wait_until(t0 + 60.0)  # a caller naming no near deadline: capped
    assert 0.19 <= time.monotonic() - t0 < 0.6


def test_the_wait_wakes_for_the_agreements_resend_and_a_members_grace(bus: Bus) -> None:
    ctx = _context(bus, member_grace=0.4)
    fleet = Membership(ctx)
    now = ctx.clock()
    rec = NeighborRecordMsg(sender=3, round=0, neighbours=())
    agr = Agreement(3, rec, now, fleet_size=3, digest_fn=canonical_digest)
    fleet.open_round(agr)
    fleet.handle(Event("alive", "nao/alive/1", robot_id=1))
    sent = bus.stats.published_count
    t0 = time.monotonic()
    # publishes the record and digest before it sleeps, and wakes for the digest's first
    # repair (robot 1's digest is missing), backoff_min = 0.25 s later
    fleet.wait_until(t0 + 60.0)
    assert sent["record"] == 1 and sent["digest"] == 2
    assert 0.2 <= time.monotonic() - t0 < 0.6
    fleet.wait_until(t0 + 60.0)
    assert sent["digest"] == 3 and 0.7 <= time.monotonic() - t0 < 1.2  # 0.5 s after
    fleet.handle(Event("gone", "nao/alive/1", robot_id=1))
    assert fleet.next_wake(ctx.clock()) <= ctx.clock() + 0.4
    t0 = time.monotonic()
    while fleet.member(1) and time.monotonic() - t0 < 3.0:
        fleet.wait_until(t0 + 60.0)
    assert not fleet.member(1) and time.monotonic() - t0 < 1.0  # gone after its grace
    assert agr.left == {1}


def test_a_searching_members_status_is_news_for_the_agreement(bus: Bus) -> None:
    t = [0.0]
    ctx = _context(bus, clock=lambda: t[0])
    fleet = Membership(ctx)
    agr = Agreement(3, NeighborRecordMsg(sender=3, round=0, neighbours=()), 0.0,
                    fleet_size=3, timeout=120.0, digest_fn=canonical_digest)  # fmt: skip
    fleet.open_round(agr)
    for i in (1, 2):
        fleet.handle(Event("alive", f"nao/alive/{i}", robot_id=i))
    t[0] = 100.0
    fleet.handle(Event("msg", "nao/1/status", StatusMsg(sender=1, phase="search", progress=0.4)))
    fleet.handle(Event("msg", "nao/2/status", StatusMsg(sender=2, phase="exchange")))
    assert agr.last_news == 100.0
    assert agr.decide(219.0).kind == "wait"  # robot 1 searched at 100 s
    d = agr.decide(220.5)
    assert d.kind == "failed" and "no record from [1, 2]" in d.reason


def test_statuses_go_out_on_change_with_a_slow_heartbeat(bus: Bus) -> None:
    t = [0.0]
    ctx = _context(bus, clock=lambda: t[0], member_grace=20.0)
    report = ctx.report
    assert report.interval == status_interval(3) == 3.0
    assert report.heartbeat == heartbeat_interval(3, 20.0) == 10.0  # twice per grace
    assert heartbeat_interval(100, 20.0) == 10.0  # never more often than the fleet's budget
    assert heartbeat_interval(300, 20.0) == 30.0
    assert heartbeat_interval(3, 60.0) == 30.0
    sent = bus.stats.published_count

    def at(when: float, detail: str, phase: Phase = Phase.AGREE) -> int:
        t[0] = when
        report.status(phase, 0.5, detail)
        return sent["status"]

    assert at(0.0, "a") == 1  # a new phase: at once
    assert at(1.0, "a") == 1 and report.due() == 10.0  # unchanged
    assert at(2.0, "b") == 1 and report.due() == 3.0  # changed: held back to 3 s
    assert at(3.0, "b") == 2  # ... and out then
    assert at(6.0, "b") == 2 and at(12.9, "b") == 2  # unchanged: no sooner than 10 s
    assert at(13.0, "b") == 3  # the heartbeat
    assert at(13.5, "c", Phase.WAIT) == 4  # a new phase: at once again
    assert at(14.0, "d", Phase.WAIT) == 4 and at(16.5, "d", Phase.WAIT) == 5


def test_a_wake_up_that_publishes_nothing_builds_no_message(
    bus: Bus, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A waiting robot's status is compared as plain values; the wire message (checked
    field by field) is built only when it goes out."""
    t = [0.0]
    report = _context(bus, clock=lambda: t[0]).report
    built: list[StatusMsg] = []
    make = report._message
    monkeypatch.setattr(report, "_message", lambda *a: built.append(make(*a)) or built[-1])
    report.status(Phase.AGREE, 0.5, "waiting")
    for k in range(1, 10):
        t[0] = float(k)
        report.status(Phase.AGREE, 0.5, "waiting")
    assert len(built) == 1 and bus.stats.published_count["status"] == 1
    report.show_blocked_by(2)  # a changed figure is a changed status
    t[0] = 9.5
    report.status(Phase.AGREE, 0.5, "waiting")
    assert len(built) == 2 and built[-1].blocked_by == 2 and built[-1].detail == "waiting"


def test_grace_names_its_next_expiry() -> None:
    g = Grace(5.0)
    assert g.next_expiry() == float("inf")
    g.token(1, False, 2.0)
    g.token(2, False, 3.0)
    g.heard(1, 4.0)
    assert g.next_expiry() == 8.0
