"""The agreement's timeout (agent/core/agreement.py): it counts from the fleet's last news.

News is a record that changes the set held or a member's digest that changes; an agent
that searched early waits while the others' records keep arriving (at 100
NAOs the searches end over ~15 minutes) and fails, naming who is missing, once nothing
moved for ``timeout`` seconds.
"""

from __future__ import annotations

from agent.core.agreement import Agreement
from agent.wire import DigestMsg, canonical_digest
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
