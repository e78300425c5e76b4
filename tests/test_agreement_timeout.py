"""The agreement's timeout (agent/core/agreement.py): it counts from the fleet's last news.

News is a record that changes the set held or a member's digest that changes; an agent
that searched early waits while the others' records keep arriving (at 100
NAOs the searches end over ~15 minutes) and fails, naming who is missing, once nothing
moved for ``timeout`` seconds.
"""

from __future__ import annotations

import pytest

from agent.core.agreement import Agreement
from agent.wire import DigestMsg, NeighborRecordMsg, canonical_digest
from tests.test_exchange import Net, rec


def test_timeout_names_who_is_missing() -> None:
    net = Net([0, 1], timeout=5.0)
    net.run(6.0)
    d = net.agents[0].decide(net.t)
    assert d.kind == "failed"
    assert "no news for 5 s" in d.reason and "2 of 3" in d.reason


def test_timeout_names_missing_record_and_digest() -> None:
    net = Net([0, 1], fleet_size=2, timeout=2.0, drop=lambda kind, s, d, t: s == 1)
    net.run(3.0)
    d = net.agents[0].decide(net.t)
    assert d.kind == "failed"
    assert "no record from [1]" in d.reason and "from [1]" in d.reason


def test_records_arriving_late_keep_an_early_agent_waiting() -> None:
    # 0 searched first; 1 and 2 finish their searches 4 s apart, each within the timeout
    # of the news before it, the last one 8 s after 0 began (> its 5 s timeout)
    net = Net([0], fleet_size=3, timeout=5.0)
    net.run(4.0)
    assert net.agents[0].decide(net.t).kind == "wait"
    net.add(1)
    net.run(8.0)
    assert net.agents[0].decide(net.t).kind == "wait"
    net.add(2)
    net.run(12.0)
    ds = [a.decide(net.t) for a in net.agents.values()]
    assert [d.kind for d in ds] == ["agreed"] * 3
    assert len({d.digest for d in ds}) == 1


def test_the_timeout_runs_again_once_nothing_moves() -> None:
    net = Net([0], fleet_size=3, timeout=5.0)
    net.run(4.0)
    net.add(1)  # its record is news at ~4 s; then nobody else comes
    net.run(9.0)
    assert net.agents[0].decide(net.t).kind == "wait"
    net.run(9.5)
    d = net.agents[0].decide(net.t)
    assert d.kind == "failed"
    assert "no news for 5 s" in d.reason and "2 of 3" in d.reason


def test_a_changed_digest_is_news_an_unchanged_one_is_not() -> None:
    a = Agreement(0, rec(0), 0.0, fleet_size=2, timeout=5.0, digest_fn=canonical_digest)
    a.member_joined(1, 0.0)
    own = (rec(1),)
    note = DigestMsg(sender=1, round=0, digest=canonical_digest(own), members=(1,))
    a.on_digest(note, 4.0)
    assert a.last_news == 4.0 and not a.timed_out(9.0) and a.timed_out(9.1)
    a.on_digest(note, 8.0)  # a repeat: no news
    assert a.last_news == 4.0
    a.on_record(rec(1), 8.0)  # the record: news
    assert a.last_news == 8.0
    a.on_record(rec(1), 8.5)  # a repeat: no news
    assert a.last_news == 8.0


# ------------------------------------------------- patience follows the fleet (module doc)


def _waiting_for_2(timeout: float = 5.0) -> Agreement[NeighborRecordMsg]:
    """Robot 0 holds its record and 1's; robot 2 is a live member with no record yet."""
    a = Agreement(0, rec(0), 0.0, fleet_size=3, timeout=timeout, digest_fn=canonical_digest)
    for i in (1, 2):
        a.member_joined(i, 0.0)
    a.on_record(rec(1), 0.0)
    return a


def test_a_searching_member_keeps_the_agreement_waiting() -> None:
    a = _waiting_for_2()
    # robot 2's statuses of its search (progress, then heartbeats) for 60 s: 12 timeouts
    for t in range(3, 61, 3):
        a.on_peer_phase(2, "search" if t < 50 else "localise", float(t))
        assert a.decide(t + 0.5).kind == "wait"
    a.on_record(rec(2), 62.0)  # its search ended: its record
    assert a.decide(62.0).kind == "wait"  # (the digests are still to match)


def test_a_silent_member_still_times_out() -> None:
    a = _waiting_for_2()
    a.on_peer_phase(2, "search", 3.0)
    assert a.decide(8.0).kind == "wait"
    d = a.decide(8.1)  # nothing from robot 2 for 5 s since its last search status
    assert d.kind == "failed" and "no news for 5 s" in d.reason and "no record from [2]" in d.reason


def test_only_a_searcher_whose_record_is_missing_is_news() -> None:
    a = _waiting_for_2()
    a.on_peer_phase(1, "search", 4.0)  # robot 1's record is held: it searches a later round
    a.on_peer_phase(2, "exchange", 4.0)  # waiting like us: no news
    a.on_peer_phase(2, "search")  # remembered from before, not heard now: no news
    assert a.last_news == 0.0 and a.timed_out(5.1)
    a.on_peer_phase(3, "search", 4.0)  # not a member: ignored
    assert a.last_news == 0.0 and a.ignored == 1


def test_the_next_wake_is_a_resend_or_the_timeout_and_always_ahead() -> None:
    a = _waiting_for_2(timeout=30.0)
    assert a.due(0.0) == ["record", "digest"]  # due at once: sent before any sleep
    a.sent(["record", "digest"], 0.0)
    assert a.next_wake(0.0) == 0.25  # the digest's repair (robot 2's record is missing)
    t, gaps = 0.25, []
    while t < 20.0:  # the repairs back off to backoff_max (4 s); every wake lies ahead
        a.sent(a.due(t), t)
        wake = a.next_wake(t)
        assert wake > t
        gaps.append(wake - t)
        t = wake
    assert gaps[:4] == [0.5, 1.0, 2.0, 4.0] and set(gaps[4:]) == {4.0}
    a.on_peer_phase(2, "search", 20.0)  # news: the timeout now falls at 50 s
    assert a.next_wake(49.0) == pytest.approx(50.0, abs=0.01)
