"""Agreement over real zenoh sessions: the runner's exchange phase in several peers.

Each peer is a real :class:`agent.net.bus.Bus` (its own zenoh session, loopback TCP, no
multicast) driving :meth:`agent.phases.agreeing.Agreeing.agree`, the code every agent process
runs. Covered: all agree on one digest; a late joiner is waited for; a lost record is
re-sent; a member that dies before agreement stops everyone safely.
"""

from __future__ import annotations

import functools
import threading
from collections.abc import Callable, Iterator
from typing import Any

import pytest

from agent.adapters import FormationAdapter, PerceptionAdapter
from agent.body.zenoh_world import ZenohBody
from agent.config import AgentConfig
from agent.core.agreement import Decision
from agent.net.bus import Bus, BusConfig
from agent.phases.agreeing import Agreeing
from agent.phases.context import Context
from agent.phases.membership import Membership
from agent.phases.reporting import Phase
from agent.wire import Message, NeighborRecordMsg, StatusMsg
from tools.harness.procs import free_port


@functools.cache
def _perception() -> PerceptionAdapter:
    """One perception for every peer (agreement never looks at an image)."""
    return PerceptionAdapter()


pytestmark = pytest.mark.system


def record(i: int) -> NeighborRecordMsg:
    return NeighborRecordMsg(sender=i, round=0, neighbours=((0.3 * i, 0.9), (-0.5, 0.1 * i)))


class Peer:
    def __init__(self, rid: int, ep: str, fleet: int, timeout: float = 30.0, listen: bool = False):
        cfg = (
            BusConfig(listen=(ep,), multicast_scouting=False)
            if listen
            else BusConfig(connect=(ep,), multicast_scouting=False)
        )
        self.bus = Bus(cfg)
        cfg = AgentConfig(robot_id=rid, fleet_size=fleet, timeout=timeout)
        body = ZenohBody(self.bus, rid)
        self.ctx = Context.of(self.bus, body, cfg, _perception(), FormationAdapter())
        self.membership = Membership(self.ctx)
        self.agreeing = Agreeing(self.ctx, self.membership)
        self.membership.start()
        self.decision: Decision | None = None
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        d = self.agreeing.agree(record(self.ctx.me))
        self.decision = d
        if d.kind == "agreed":
            # what the runner does next: a post-agreement status acknowledges the digest
            self.ctx.report.status(Phase.PLAN, 0.0, force=True)
            end = self.ctx.clock() + 3.0
            while (
                self.ctx.clock() < end
                and self.membership.agreement is not None
                and (self.membership.agreement.due(self.ctx.clock() + 100.0))
            ):
                self.membership.pump(0.1)

    def start(self) -> Peer:
        self.thread.start()
        return self

    def join(self, timeout: float = 60.0) -> Decision:
        self.thread.join(timeout)
        assert not self.thread.is_alive(), "agreement did not end"
        assert self.decision is not None
        return self.decision


@pytest.fixture()
def endpoint() -> Iterator[str]:
    ep = f"tcp/127.0.0.1:{free_port()}"
    hub = Bus(BusConfig(listen=(ep,), multicast_scouting=False))  # the rendezvous, like the world
    try:
        yield ep
    finally:
        hub.close()


def close_all(peers: list[Peer]) -> None:
    for p in peers:
        p.bus.close()


def test_three_peers_agree_on_one_digest(endpoint: str) -> None:
    peers = [Peer(i, endpoint, 3).start() for i in (1, 2, 3)]
    try:
        ds = [p.join() for p in peers]
    finally:
        close_all(peers)
    assert [d.kind for d in ds] == ["agreed"] * 3, [d.reason for d in ds]
    assert len({d.digest for d in ds}) == 1
    assert ds[0].members == (1, 2, 3)
    assert [r.sender for r in ds[0].records] == [1, 2, 3]
    # one exchange and a few re-publications: the number of backoff re-sends grows with
    # the wall time the agreement takes (a loaded machine), so this is a sanity bound
    # against a run-away re-sender; the measured bytes are tools.bench agent's (~310 B)
    for p in peers:
        st = p.bus.stats
        assert st.published_bytes["record"] + st.published_bytes["digest"] < 8000


def test_late_joiner_is_waited_for(endpoint: str) -> None:
    early = [Peer(i, endpoint, 3).start() for i in (1, 2)]
    try:
        early[0].thread.join(3.0)
        assert early[0].decision is None  # still waiting for the third member
        assert "2 of 3" in early[0].membership.agreement.decide(early[0].ctx.clock()).reason  # type: ignore[union-attr]
        late = Peer(3, endpoint, 3).start()
        ds = [p.join() for p in [*early, late]]
    finally:
        close_all([*early, late])
    assert all(d.kind == "agreed" for d in ds), [d.reason for d in ds]
    assert len({d.digest for d in ds}) == 1 and ds[0].members == (1, 2, 3)


def drop_first(bus: Bus, lost_category: str, n: int) -> list[int]:
    """Make ``bus`` lose its first ``n`` publications of ``category`` (a lossy link)."""
    real: Callable[..., int] = bus.publish
    lost: list[int] = []

    def publish(key: str, msg: Message, category: str = "") -> int:
        if category == lost_category and len(lost) < n:
            lost.append(1)
            return 0
        return real(key, msg, category)

    bus.publish = publish  # type: ignore[method-assign]
    return lost


def test_lost_record_is_resent(endpoint: str) -> None:
    peers = [Peer(i, endpoint, 3) for i in (1, 2, 3)]
    lost = drop_first(peers[2].bus, "record", 2)
    for p in peers:
        p.start()
    try:
        ds = [p.join() for p in peers]
    finally:
        close_all(peers)
    assert len(lost) == 2
    assert all(d.kind == "agreed" for d in ds), [d.reason for d in ds]
    assert len({d.digest for d in ds}) == 1
    assert peers[2].bus.stats.published_count["record"] >= 1


def test_member_that_dies_stops_everyone_safely(endpoint: str) -> None:
    peers = [Peer(i, endpoint, 3) for i in (1, 2)]
    doomed = Peer(3, endpoint, 3)  # alive (liveliness token) but never gets a record out ...
    for p in peers:
        p.start()
    try:
        # ... and dies once the others know it is a member
        end = peers[0].ctx.clock() + 20
        while peers[0].ctx.clock() < end:
            agr = peers[0].membership.agreement
            if agr is not None and 3 in agr.live:
                break
            peers[0].thread.join(0.1)
        doomed.bus.close()
        ds = [p.join() for p in peers]
    finally:
        close_all(peers)
    for d in ds:
        assert d.kind == "failed"
        assert "[3] left before agreement" in d.reason


def test_timeout_gives_a_reason(endpoint: str) -> None:
    peers = [Peer(i, endpoint, 3, timeout=2.0).start() for i in (1, 2)]
    try:
        ds = [p.join() for p in peers]
    finally:
        close_all(peers)
    for d in ds:
        assert d.kind == "failed" and "no news for 2 s" in d.reason and "2 of 3" in d.reason


def test_bad_messages_on_the_bus_do_not_disturb_agreement(endpoint: str) -> None:
    peers = [Peer(i, endpoint, 2) for i in (1, 2)]
    noise = Bus(BusConfig(connect=(endpoint,), multicast_scouting=False))
    for p in peers:
        p.start()
    try:
        for _ in range(20):
            noise.session.put("nao/9/record", b"\x93garbage")
            noise.session.put("nao/1/status", b"")
            peers[0].thread.join(0.05)
        ds = [p.join() for p in peers]
    finally:
        noise.close()
        close_all(peers)
    assert all(d.kind == "agreed" for d in ds), [d.reason for d in ds]
    assert any(p.bus.stats.rejected > 0 for p in peers)


def test_status_is_valid_and_counts_bytes(endpoint: str) -> None:
    p = Peer(5, endpoint, 1)
    got: list[Any] = []
    try:
        p.ctx.report.status(Phase.SEARCH, 0.5, "sweep", force=True)
        got = [
            p.ctx.bus.stats.published_count["status"],
            p.ctx.bus.stats.total_published,
        ]
    finally:
        p.bus.close()
    assert got[0] == 1 and got[1] > 0
    assert isinstance(StatusMsg(sender=5, phase="search"), StatusMsg)
