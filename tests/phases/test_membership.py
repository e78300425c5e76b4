"""agent/phases/membership.py alone, on a bus without a network (tests/phases/fakes.py):
what it keeps of each member, whose messages count, departures after the grace, the
restarted member's new session, the fleet's reason to stop, and what it hands its
observers.

Robot 3 of the three robots of ``records()``; the waits on the bus are in
tests/test_waiting.py.
"""

from __future__ import annotations

import dataclasses

import pytest

from agent.adapters import FormationAdapter
from agent.config import AgentConfig
from agent.core.agreement import Agreement
from agent.core.formation.params import PlanParams
from agent.net.bus import Event
from agent.phases.membership import Membership, Peer
from agent.phases.reporting import Phase
from agent.wire import (
    KEY_RECORD_ALL,
    DigestMsg,
    NeighborRecordMsg,
    RecordSetReply,
    RecordSetRequest,
    StatusMsg,
    canonical_digest,
    key_alive,
    key_records,
)
from tests.phases.fakes import Clock, FakeBus, context, records


def membership(**cfg: object) -> tuple[Membership, Clock]:
    clock = Clock()
    ctx = context(AgentConfig(robot_id=3, fleet_size=3, **cfg), FormationAdapter(), clock=clock)  # type: ignore[arg-type]
    return Membership(ctx), clock


def test_start_subscribes_declares_the_token_and_serves_the_agreed_set() -> None:
    m, _ = membership()
    m.start()
    bus = m.ctx.bus
    assert isinstance(bus, FakeBus)
    assert KEY_RECORD_ALL in bus.subscribed and key_alive(3) in bus.subscribed
    answer = bus.served[key_records(3)]
    assert answer(RecordSetRequest(digest="")) is None  # nothing agreed yet
    m.served = RecordSetReply(sender=3, digest="ab" * 32, records=())
    assert answer(RecordSetRequest(digest="")) is m.served


def test_progress_heard_only_grows_for_one_plan() -> None:
    m, _ = membership()
    m.handle(Event("alive", "nao/alive/2", robot_id=2))
    d1, d2 = "ab" * 32, "cd" * 32
    for walked, digest in ((2.0, d1), (1.0, d1)):  # a late, older status changes nothing
        msg = StatusMsg(sender=2, phase="move", plan_digest=digest, walked=walked)
        m.handle(Event("msg", "nao/2/status", msg))
    assert m.peers[2].walked == 2.0
    msg = StatusMsg(sender=2, phase="move", plan_digest=d2, walked=0.5)  # a new plan
    m.handle(Event("msg", "nao/2/status", msg))
    assert m.peers[2].walked == 0.5


def test_messages_whose_sender_does_not_own_the_key_are_dropped() -> None:
    m, _ = membership()
    impostor = NeighborRecordMsg(sender=2, round=0, neighbours=((1.0, 0.0),))
    m.handle(Event("msg", "nao/1/record", impostor))
    assert m.early_records == {}
    m.handle(Event("msg", "nao/2/record", impostor))
    assert m.early_records == {}  # 2 is no member yet: no state kept for it
    m.handle(Event("alive", "nao/alive/2", robot_id=2))
    m.handle(Event("msg", "nao/2/record", impostor))
    assert m.early_records == {2: impostor}


def test_only_the_current_session_of_a_member_counts() -> None:
    m, _ = membership()
    m.handle(Event("alive", "nao/alive/2", robot_id=2))
    new = NeighborRecordMsg(sender=2, round=0, neighbours=((1.0, 0.0),))
    old = NeighborRecordMsg(sender=2, round=3, neighbours=((9.0, 0.0),))
    m.handle(Event("msg", "nao/2/record", new, signer="robot-2", epoch=200))
    m.handle(Event("msg", "nao/2/record", old, signer="robot-2", epoch=100))
    assert m.early_records == {2: new}  # the older session (a replay) is ignored
    m.agreed_epochs = {2: 200}
    m.handle(Event("msg", "nao/2/status", StatusMsg(sender=2, phase="done"), epoch=300))
    assert m.peers[2].phase != "done"  # after agreement only the agreed session counts


def test_a_restarted_member_counts_once_it_shows_the_agreed_digest() -> None:
    m, _ = membership()
    m.agreement = Agreement.restored(
        3, records(), 0.0, params="ab" * 32, digest_fn=canonical_digest
    )
    m.handle(Event("alive", "nao/alive/2", robot_id=2))
    m.epochs = {2: 100}
    m.pin_sessions({1, 2, 3}, "cd" * 32)
    assert m.agreed_epochs == {2: 100}
    _, digest = m.agreement.digest()
    # a new session that does not show the agreed digest is ignored
    wrong = DigestMsg(sender=2, round=0, digest="0" * 64, members=(1, 2, 3), params="ab" * 32)
    m.handle(Event("msg", "nao/2/digest", wrong, epoch=300))
    m.handle(Event("msg", "nao/2/status", StatusMsg(sender=2, phase="wait"), epoch=300))
    assert m.agreed_epochs[2] == 100 and m.peers[2].phase != "wait"
    # ... one that does is the same member from now on; the old session no longer counts
    right = DigestMsg(sender=2, round=0, digest=digest, members=(1, 2, 3), params="ab" * 32)
    m.handle(Event("msg", "nao/2/digest", right, epoch=300))
    assert m.agreed_epochs[2] == 300
    m.handle(Event("msg", "nao/2/status", StatusMsg(sender=2, phase="move"), epoch=300))
    assert m.peers[2].phase == "move"
    m.handle(Event("msg", "nao/2/status", StatusMsg(sender=2, phase="done"), epoch=100))
    assert m.peers[2].phase == "move"
    # a status with the agreed plan digest proves it too
    st = StatusMsg(sender=2, phase="hold", plan_digest="cd" * 32)
    m.handle(Event("msg", "nao/2/status", st, epoch=400))
    assert m.agreed_epochs[2] == 400 and m.peers[2].phase == "hold"


def test_a_vanished_token_is_a_departure_only_after_the_grace_period() -> None:
    m, clock = membership(member_grace=10.0)
    m.agreement = Agreement(3, records()[2], 0.0, fleet_size=3, digest_fn=canonical_digest)
    for i in (1, 2):
        m.handle(Event("alive", f"nao/alive/{i}", robot_id=i))
    m.handle(Event("gone", "nao/alive/1", robot_id=1))
    m.handle(Event("gone", "nao/alive/2", robot_id=2))
    clock.t = 8.0  # robot 2 is heard from: a heartbeat
    m.handle(Event("msg", "nao/2/status", StatusMsg(sender=2, phase="agree")))
    clock.t = 9.9
    m.pump()
    assert m.peers[1].alive and m.peers[2].alive and m.agreement.left == set()
    clock.t = 10.0
    m.pump()
    assert not m.peers[1].alive and m.agreement.left == {1}
    assert m.peers[2].alive  # its grace runs from its last status
    m.handle(Event("alive", "nao/alive/2", robot_id=2))  # reconnected
    clock.t = 30.0
    m.pump()
    assert m.peers[2].alive and m.agreement.left == {1}


def test_observers_see_what_is_accepted_before_it_is_handled() -> None:
    m, _ = membership()
    seen: list[tuple[str, str]] = []
    m.observers.append(lambda ev: seen.append((ev.key, m.peer(ev.msg.sender).phase)))
    m.handle(Event("alive", "nao/alive/2", robot_id=2))
    m.handle(Event("msg", "nao/1/status", StatusMsg(sender=2, phase="search")))  # not its key
    m.handle(Event("msg", "nao/2/status", StatusMsg(sender=2, phase="search")))
    assert seen == [("nao/2/status", "")]  # the peer's phase not yet updated


def test_the_fleet_stops_for_a_failed_member_of_the_plan() -> None:
    """No 'formation held' around a hole: the fleet's one reason (jam.py rule 4)."""
    m, _ = membership()
    plan = FormationAdapter().plan(records(), PlanParams())
    assert m.fleet_stop(None) == ""  # no plan yet: nothing to stop for
    m.peers[1] = Peer(alive=True, phase="done", seen_alive=True)
    m.peers[2] = Peer(alive=False, phase="move", seen_alive=True)  # only left: no reason
    assert m.fleet_stop(plan) == ""
    m.peers[2] = Peer(
        alive=True, phase="failed", seen_alive=True, error="robot 2 cannot reach its slot"
    )
    assert m.fleet_stop(plan) == (
        "formation incomplete: robot 2 failed: robot 2 cannot reach its slot"
    )
    left_out = dataclasses.replace(plan, excluded=(2,))  # it stops by design
    assert m.fleet_stop(left_out) == ""


@pytest.mark.parametrize(
    ("phases", "arrived"),
    [(("hold", "done"), True), (("move", "done"), False), (("march", "failed"), True)],
)
def test_arrived_is_every_live_member_in_an_arrived_phase(
    phases: tuple[str, str], arrived: bool
) -> None:
    m, _ = membership()
    m.peers[1] = Peer(alive=True, phase=phases[0], seen_alive=True)
    m.peers[2] = Peer(alive=True, phase=phases[1], seen_alive=True)
    assert m.arrived((1, 2, 3)) is arrived
    m.peers[1].alive = False  # out of reach: not waited for
    assert m.arrived((1, 2, 3)) is (phases[1] != "move")


def test_a_member_that_appears_or_comes_back_hears_our_status_within_the_interval() -> None:
    """Statuses repeat slowly (a heartbeat); a member new to us, or back after its links
    were cut, may have missed ours: it goes out again one status interval after the last."""
    m, clock = membership(member_grace=20.0)
    report, bus = m.ctx.report, m.ctx.bus
    report.status(Phase.AGREE, 0.5, "waiting")
    assert len(bus.statuses()) == 1 and report.due() == 10.0  # the heartbeat
    clock.t = 1.0
    m.handle(Event("alive", "nao/alive/1", robot_id=1))
    assert report.due() == 3.0  # the status interval, not the heartbeat
    clock.t = 2.9
    report.status(Phase.AGREE, 0.5, "waiting")
    assert len(bus.statuses()) == 1
    clock.t = 3.0
    report.status(Phase.AGREE, 0.5, "waiting")
    assert len(bus.statuses()) == 2 and report.due() == 13.0
    clock.t = 4.0
    m.handle(Event("alive", "nao/alive/1", robot_id=1))  # still there: nothing new
    m.handle(Event("alive", "nao/alive/3", robot_id=3))  # our own token
    assert report.due() == 13.0
    m.handle(Event("gone", "nao/alive/1", robot_id=1))
    m.handle(Event("alive", "nao/alive/1", robot_id=1))  # back within its grace
    assert report.due() == 6.0
    report.status(Phase.AGREE, 0.5, "waiting")
    assert len(bus.statuses()) == 2  # not before 6 s
    clock.t = 6.0
    report.status(Phase.AGREE, 0.5, "waiting")
    assert len(bus.statuses()) == 3 and report.due() == 16.0
    m.handle(Event("gone", "nao/alive/1", robot_id=1))
    clock.t = 30.0  # its grace ran out
    m.pump()
    assert not m.peers[1].alive
    m.handle(Event("alive", "nao/alive/1", robot_id=1))  # back
    assert report.due() == 9.0  # 3 s after the last status: at once
    report.status(Phase.AGREE, 0.5, "waiting")
    assert len(bus.statuses()) == 4
