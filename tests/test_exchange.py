"""The agreement state machine (agent/core/agreement.py): every branch, with an in-memory bus."""

from __future__ import annotations

import itertools
from collections.abc import Callable

import pytest

from agent.core.agreed_params import odd_params, params_digest
from agent.core.agreement import HEARD_PER_S, Agreement
from agent.core.formation.params import D_E, PlanParams
from agent.wire import DigestMsg, NeighborRecordMsg, canonical_digest

Drop = Callable[[str, int, int, float], bool]


def rec(i: int, round_: int = 0) -> NeighborRecordMsg:
    return NeighborRecordMsg(sender=i, round=round_, neighbours=((0.1 * i, 1.0 + i),))


class Net:
    """Agents exchanging over a perfect broadcast medium, with a drop rule."""

    def __init__(
        self, ids: list[int], fleet_size: int | None = 3, drop: Drop | None = None, **kw: float
    ) -> None:
        self.t = 0.0
        self.kw = kw
        self.fleet = fleet_size
        self.drop = drop or (lambda kind, src, dst, t: False)
        self.agents: dict[int, Agreement] = {}
        self.sent: dict[int, int] = {}
        for i in ids:
            self.add(i)

    def add(self, i: int) -> None:
        a = Agreement(
            i, rec(i), self.t, fleet_size=self.fleet, **self.kw, digest_fn=canonical_digest
        )  # type: ignore[arg-type]
        for j, other in self.agents.items():
            other.member_joined(i, self.t)
            a.member_joined(j, self.t)
        self.agents[i] = a
        self.sent[i] = 0

    def kill(self, i: int) -> None:
        del self.agents[i]
        for other in self.agents.values():
            other.member_left(i, self.t)

    def step(self, dt: float = 0.05) -> None:
        self.t += dt
        for i, a in list(self.agents.items()):
            due = a.due(self.t)
            for what in due:
                self.sent[i] += 1
                for j, b in self.agents.items():
                    if j == i or self.drop(what, i, j, self.t):
                        continue
                    if what == "record":
                        b.on_record(a.records[i], self.t)
                    else:
                        b.on_digest(a.digest_note(), self.t)
            a.sent(due, self.t)
            d = a.decide(self.t)
            if d.kind == "agreed":
                for b in self.agents.values():
                    b.on_peer_phase(i, "plan")

    def run(self, until: float) -> None:
        while self.t < until:
            self.step()


def test_three_agents_agree_on_one_digest() -> None:
    net = Net([0, 1, 2])
    net.run(3.0)
    ds = [a.decide(net.t) for a in net.agents.values()]
    assert all(d.kind == "agreed" for d in ds), ds
    assert len({d.digest for d in ds}) == 1
    assert ds[0].members == (0, 1, 2)
    assert ds[0].digest == canonical_digest([rec(2), rec(0), rec(1)])
    assert [r.sender for r in ds[0].records] == [0, 1, 2]


def test_publications_stop_after_everyone_agreed() -> None:
    net = Net([0, 1, 2])
    net.run(3.0)
    before = dict(net.sent)
    net.run(30.0)
    assert net.sent == before
    assert all(n <= 6 for n in before.values()), before


def test_lost_record_is_resent_until_agreement() -> None:
    # every record from 2 to 0 is lost for the first 3 s
    net = Net(
        [0, 1, 2], drop=lambda kind, s, d, t: kind == "record" and s == 2 and d == 0 and t < 3.0
    )
    net.run(2.9)
    assert net.agents[0].decide(net.t).kind == "wait"
    assert net.agents[0].missing_records() == [2]
    assert net.agents[1].decide(net.t).kind == "wait"  # 0's digest lacks 2: nobody moves
    net.run(12.0)
    ds = [a.decide(net.t) for a in net.agents.values()]
    assert all(d.kind == "agreed" for d in ds)
    assert len({d.digest for d in ds}) == 1


def test_lost_digests_delay_but_do_not_break_agreement() -> None:
    net = Net([0, 1, 2], drop=lambda kind, s, d, t: kind == "digest" and t < 2.0)
    net.run(1.9)
    assert all(a.decide(net.t).kind == "wait" for a in net.agents.values())
    net.run(10.0)
    assert all(a.decide(net.t).kind == "agreed" for a in net.agents.values())


def test_late_joiner_is_waited_for_and_included() -> None:
    net = Net([0, 1])
    net.run(5.0)
    d0 = net.agents[0].decide(net.t)
    assert d0.kind == "wait" and "2 of 3" in d0.reason
    net.add(2)
    net.run(9.0)
    ds = [a.decide(net.t) for a in net.agents.values()]
    assert all(d.kind == "agreed" for d in ds)
    assert {d.members for d in ds} == {(0, 1, 2)}


def test_member_that_dies_before_agreement_fails_everyone_safely() -> None:
    net = Net([0, 1, 2], drop=lambda kind, s, d, t: s == 2)  # 2 is mute, then dies
    net.run(1.0)
    net.kill(2)
    net.step()
    for a in net.agents.values():
        d = a.decide(net.t)
        assert d.kind == "failed"
        assert "[2] left" in d.reason
        assert a.due(net.t + 100) == []


def test_more_members_than_fleet_size_fails() -> None:
    net = Net([0, 1, 2], fleet_size=2)
    net.step()
    d = net.agents[0].decide(net.t)
    assert d.kind == "failed" and "more than the fleet size 2" in d.reason


def test_without_fleet_size_membership_must_settle() -> None:
    net = Net([0, 1], fleet_size=None, settle=2.0)
    net.run(1.0)
    assert net.agents[0].decide(net.t).kind == "wait"
    assert "settle" in net.agents[0].decide(net.t).reason
    net.run(4.0)
    assert all(a.decide(net.t).kind == "agreed" for a in net.agents.values())


def test_agreed_and_failed_are_final() -> None:
    net = Net([0, 1], fleet_size=2)
    net.run(3.0)
    a = net.agents[0]
    assert a.decide(net.t).kind == "agreed"
    a.member_left(1, net.t)
    assert a.decide(net.t).kind == "agreed"


def test_after_agreement_digest_is_resent_until_peers_ack() -> None:
    a = Agreement(0, rec(0), 0.0, fleet_size=2, digest_fn=canonical_digest)
    a.member_joined(1, 0.0)
    a.on_record(rec(1), 0.0)
    members, digest = a.digest()
    a.on_digest(DigestMsg(sender=1, round=0, digest=digest, members=members), 0.0)
    assert a.decide(0.0).kind == "agreed"
    assert a.due(0.1) == ["digest"]
    a.sent(["digest"], 0.1)
    assert a.due(0.2) == []  # backing off
    assert a.due(0.4) == ["digest"]
    a.on_peer_phase(1, "agree")
    assert a.due(10.0) == ["digest"]
    a.on_peer_phase(1, "move")
    assert a.due(20.0) == []


def test_record_is_resent_only_while_unacknowledged() -> None:
    a = Agreement(0, rec(0), 0.0, fleet_size=3, digest_fn=canonical_digest)
    a.member_joined(1, 0.0)
    assert a.due(0.0) == ["record", "digest"]
    a.sent(["record", "digest"], 0.0)
    # peer 1 acknowledges holding record 0
    a.on_digest(DigestMsg(sender=1, round=0, digest="0" * 64, members=(0, 1)), 0.1)
    a.on_record(rec(1), 0.1)
    assert "record" not in a.due(5.0)


def test_backoff_doubles_and_caps() -> None:
    a = Agreement(
        0, rec(0), 0.0, fleet_size=2, backoff_min=0.25, backoff_max=1.0, digest_fn=canonical_digest
    )
    times = []
    t = 0.0
    while t < 5.0:
        due = a.due(t)
        if "record" in due:
            times.append(round(t, 2))
        a.sent(due, t)
        t = round(t + 0.05, 2)
    gaps = [round(b - a_, 2) for a_, b in itertools.pairwise(times)]
    assert gaps[:3] == [0.25, 0.5, 1.0]
    assert all(g == 1.0 for g in gaps[3:])


def test_rounds_older_is_stale_newer_is_left_to_the_next_round() -> None:
    a = Agreement(0, rec(0, 1), 0.0, digest_fn=canonical_digest)
    assert a.round == 1 and a.digest_note().round == 1
    a.member_joined(1, 0.0)
    assert not a.on_record(rec(1, 0), 0.0)  # an older round: stale
    assert a.stale == 1 and 1 not in a.records
    assert not a.on_record(rec(1, 2), 0.0)  # a newer round: for the next agreement
    assert a.on_record(rec(1, 1), 0.0)
    assert not a.on_record(rec(1, 1), 0.0)  # duplicate
    assert a.records[1].round == 1
    a.on_digest(DigestMsg(sender=1, round=0, digest="0" * 64, members=(0, 1)), 0.0)
    assert 1 not in a.digests and a.stale == 2
    impostor = NeighborRecordMsg(sender=0, round=5, neighbours=())
    assert not a.on_record(impostor, 0.0)
    assert a.records[0] == rec(0, 1)


def test_a_newer_round_acknowledges_an_agreed_digest() -> None:
    a = Agreement(0, rec(0), 0.0, fleet_size=2, digest_fn=canonical_digest)
    a.member_joined(1, 0.0)
    a.on_record(rec(1), 0.0)
    members, digest = a.digest()
    # before agreement a newer round proves nothing about ours
    a.on_digest(DigestMsg(sender=1, round=1, digest=digest, members=members), 0.0)
    assert a.peer_agreed == set() and 1 not in a.digests
    a.on_digest(DigestMsg(sender=1, round=0, digest=digest, members=members), 0.0)
    assert a.decide(0.0).kind == "agreed"
    assert a.due(0.1) == ["digest"]
    a.sent(["digest"], 0.1)
    a.on_record(rec(1, 1), 0.2)  # peer 1 moved on to re-search round 1
    assert a.peer_agreed == {1} and a.due(20.0) == []


def test_nothing_is_kept_for_non_members() -> None:
    a = Agreement(0, rec(0), 0.0, fleet_size=2, digest_fn=canonical_digest)
    for sender in range(1, 2000):  # a stranger cycling through ids
        assert not a.on_record(NeighborRecordMsg(sender=sender, round=0, neighbours=()), 0.0)
        a.on_digest(DigestMsg(sender=sender, round=0, digest="0" * 64, members=(0,)), 0.0)
        a.on_peer_phase(sender, "plan")
    assert a.records.keys() == {0} and a.digests == {} and a.peer_agreed == set()
    assert a.ignored == 3 * 1999
    a.member_joined(1, 0.0)
    assert a.on_record(rec(1), 0.0)
    assert a.held_members() == (0, 1)


def test_a_record_that_outran_its_token_is_sent_again() -> None:
    # b's record reaches a before b's liveliness token: a drops it; a's digest, which
    # does not list b, makes b re-send it, and the two agree.
    a = Agreement(0, rec(0), 0.0, fleet_size=2, digest_fn=canonical_digest)
    b = Agreement(1, rec(1), 0.0, fleet_size=2, digest_fn=canonical_digest)
    b.member_joined(0, 0.0)
    a.on_record(rec(1), 0.0)
    assert a.ignored == 1
    a.member_joined(1, 0.0)
    t = 0.0
    while t < 10.0 and not (a.agreed and b.agreed):
        t = round(t + 0.05, 2)
        for x, y, me in ((a, b, 0), (b, a, 1)):
            due = x.due(t)
            for what in due:
                if what == "record":
                    y.on_record(x.records[me], t)
                else:
                    y.on_digest(x.digest_note(), t)
            x.sent(due, t)
            x.decide(t)
    assert a.agreed and b.agreed and t < 2.0


def test_digest_is_order_independent_and_content_sensitive() -> None:
    assert canonical_digest([rec(0), rec(1)]) == canonical_digest([rec(1), rec(0)])
    assert canonical_digest([rec(0), rec(1)]) != canonical_digest([rec(0), rec(1, 1)])
    assert len(canonical_digest([])) == 64


def test_digest_covers_the_obstacles_of_a_record() -> None:
    seen = NeighborRecordMsg(sender=1, round=0, neighbours=((0.1, 2.0),), obstacles=((1.0, 0.5),))
    moved = NeighborRecordMsg(sender=1, round=0, neighbours=((0.1, 2.0),), obstacles=((1.0, 0.6),))
    assert canonical_digest([rec(0), seen]) != canonical_digest([rec(0), rec(1)])
    assert canonical_digest([rec(0), seen]) != canonical_digest([rec(0), moved])


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"self_id": 1}, "own record is from 0"),
        ({"fleet_size": 0}, "fleet size"),
        ({"timeout": -1.0}, "timeout"),
        ({"settle": float("nan")}, "settle"),
        ({"backoff_min": 0.0}, "backoff"),
        ({"backoff_min": 2.0, "backoff_max": 1.0}, "backoff"),
    ],
)
def test_bad_construction(kwargs: dict[str, float], match: str) -> None:
    args: dict[str, object] = {"self_id": 0, "own_record": rec(0), "now": 0.0}
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        Agreement(**args, digest_fn=canonical_digest)  # type: ignore[arg-type]


def test_sent_rejects_unknown_publication() -> None:
    a = Agreement(0, rec(0), 0.0, digest_fn=canonical_digest)
    with pytest.raises(ValueError, match="unknown publication"):
        a.sent(["status"], 0.0)


def test_record_goes_out_once_then_only_on_request() -> None:
    a = Agreement(0, rec(0), 0.0, fleet_size=3, digest_fn=canonical_digest)
    a.member_joined(1, 0.0)
    assert "record" in a.due(0.0)
    a.sent(["record", "digest"], 0.0)
    # peer 1 is still searching (no digest yet): no record re-sends, digests back off
    for t in (1.0, 5.0, 30.0):
        assert "record" not in a.due(t)
        a.sent(a.due(t), t)
    # a newcomer gets it once more
    a.member_joined(2, 31.0)
    assert "record" in a.due(31.0)
    a.sent(["record"], 31.0)
    assert "record" not in a.due(60.0)
    # a digest that lacks our record asks for it at once
    a.on_digest(DigestMsg(sender=1, round=0, digest="1" * 64, members=(1,)), 61.0)
    assert "record" in a.due(61.0)


# ----------------------------------------------------------------- agreed parameters

P_A = params_digest({"d_e": D_E, "phi_e": PlanParams.phi_e, "route": ("axis", 3.0)})
P_B = params_digest({"d_e": D_E, "phi_e": PlanParams.phi_e, "route": ("axis", 2.0)})


def test_params_digest_is_canonical_and_sensitive() -> None:
    a = params_digest({"x": 1.0, "r": ("to", 1.0, 2.0), "s": "default", "n": None})
    b = params_digest({"n": None, "s": "default", "r": ("to", 1.0, 2.0), "x": 1.0})
    assert a == b and len(a) == 64
    assert params_digest({"x": 1.0}) != params_digest({"x": 1.0000000001})
    assert P_A != P_B


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), [1.0], {"a": 1}])
def test_params_digest_rejects_what_cannot_be_agreed(bad: object) -> None:
    with pytest.raises(ValueError):
        params_digest({"x": bad})  # type: ignore[dict-item]


def test_same_params_agree_and_digests_carry_them() -> None:
    net = Net([0, 1, 2])
    for a in net.agents.values():
        a.params = P_A
    net.run(3.0)
    assert all(a.decide(net.t).kind == "agreed" for a in net.agents.values())
    assert net.agents[0].digest_note().params == P_A


def test_an_agent_with_other_params_is_named_and_nobody_plans() -> None:
    net = Net([0, 1, 2])
    for i, a in net.agents.items():
        a.params = P_B if i == 2 else P_A
    net.run(3.0)
    ds = {i: a.decide(net.t) for i, a in net.agents.items()}
    assert all(d.kind == "failed" for d in ds.values()), ds
    for i, d in ds.items():  # every agent names robot 2, the odd one itself included
        assert "robot(s) [2] plan with different parameters" in d.reason, (i, d.reason)
        assert "robots [0, 1]: " + P_A[:12] in d.reason
        assert ("this robot among them" in d.reason) == (i == 2)


@pytest.mark.parametrize(
    "params_of, odd, ref",
    [
        ({0: "a", 1: "a", 2: "b"}, [2], [0, 1]),
        ({0: "b", 1: "a", 2: "a"}, [0], [1, 2]),
        ({3: "b", 1: "a"}, [3], [1]),  # a tie: the group with the smallest id
        ({5: "x", 2: "y", 9: "z"}, [5, 9], [2]),
        ({4: "a", 7: "a"}, [], [4, 7]),
    ],
)
def test_odd_params_known_answers(
    params_of: dict[int, str], odd: list[int], ref: list[int]
) -> None:
    assert odd_params(params_of) == (odd, ref)


def test_odd_robot_is_named_only_once_every_member_is_heard() -> None:
    # 1's digests do not reach 0 for 2 s: 0 holds only its own and 2's (a 1-1 tie) and
    # waits instead of naming a robot from half the fleet
    net = Net([0, 1, 2], drop=lambda kind, s, d, t: kind == "digest" and s == 1 and t < 2.0)
    for i, a in net.agents.items():
        a.params = P_B if i == 2 else P_A
    net.run(1.5)
    d0 = net.agents[0].decide(net.t)
    assert d0.kind == "wait" and "waiting for the parameters of [1]" in d0.reason
    net.run(4.0)
    d0 = net.agents[0].decide(net.t)
    assert d0.kind == "failed" and "robot(s) [2] plan with different parameters" in d0.reason


def test_a_member_that_left_still_counts_for_naming() -> None:
    a = Agreement(0, rec(0), 0.0, fleet_size=3, params=P_A, digest_fn=canonical_digest)
    for i in (1, 2):
        a.member_joined(i, 0.0)
    a.on_digest(DigestMsg(sender=2, round=0, digest="a" * 64, members=(2,), params=P_B), 0.1)
    a.member_left(1, 0.2)
    a.on_digest(DigestMsg(sender=1, round=0, digest="b" * 64, members=(1,), params=P_A), 0.3)
    d = a.decide(0.4)
    assert d.kind == "failed" and "robot(s) [2] plan with different parameters" in d.reason


def test_params_mismatch_names_what_is_known_at_the_timeout() -> None:
    a = Agreement(0, rec(0), 0.0, fleet_size=3, timeout=5.0, params=P_A, digest_fn=canonical_digest)
    a.member_joined(1, 0.0)
    a.on_digest(DigestMsg(sender=1, round=0, digest="a" * 64, members=(1,), params=P_B), 0.1)
    assert a.decide(1.0).kind == "wait"  # robot 2 has not even joined
    d = a.decide(6.0)
    assert d.kind == "failed" and "robot(s) [1] plan with different parameters" in d.reason


def test_a_member_out_of_reach_after_its_record_is_waited_for_until_it_returns() -> None:
    net = Net([0, 1, 2], drop=lambda kind, s, d, t: s == 2 and kind == "digest")
    net.run(1.0)  # every record held; 2's digests lost: no agreement yet
    a = net.agents[0]
    a.member_left(2, net.t)  # its session cut (grace expired), its record held
    d = a.decide(net.t)
    assert d.kind == "wait" and "[2] out of reach" in d.reason
    a.member_joined(2, net.t + 5.0)  # reconnected
    net.drop = lambda kind, s, d, t: False
    net.run(net.t + 10.0)
    assert {x.decide(net.t).kind for x in net.agents.values()} == {"agreed"}
    assert len({x.decide(net.t).digest for x in net.agents.values()}) == 1


def test_a_member_out_of_reach_that_never_returns_times_out_safely() -> None:
    net = Net([0, 1, 2], timeout=5.0, drop=lambda kind, s, d, t: s == 2 and kind == "digest")
    net.run(1.0)
    net.kill(2)
    net.run(4.0)
    assert net.agents[0].decide(net.t).kind == "wait"  # nobody agrees without 2
    net.run(7.0)
    for a in net.agents.values():
        d = a.decide(net.t)
        assert d.kind == "failed" and "2 of 3 members alive [0, 1]" in d.reason


def test_a_member_that_failed_and_left_fails_the_agreement_at_once() -> None:
    net = Net([0, 1, 2], drop=lambda kind, s, d, t: s == 2 and kind == "digest")
    net.run(1.0)
    a = net.agents[0]
    a.on_peer_phase(2, "failed")
    assert a.decide(net.t).kind == "wait"  # still a member until it leaves
    a.member_left(2, net.t)
    d = a.decide(net.t)
    assert d.kind == "failed" and "[2] left before agreement" in d.reason


def test_adopt_agrees_on_every_record_held_even_of_a_member_out_of_reach() -> None:
    net = Net([0, 1, 2], drop=lambda kind, s, d, t: kind == "digest")  # no digest arrives
    net.run(1.0)
    a = net.agents[0]
    a.member_left(2, net.t)
    assert a.decide(net.t).kind == "wait"
    d = a.adopt(net.t, "robot 1 moves on our plan")
    assert d.kind == "agreed" and d.members == (0, 1, 2) and d.reason == "robot 1 moves on our plan"
    assert d.digest == canonical_digest([rec(0), rec(1), rec(2)])
    assert d.records == (rec(0), rec(1), rec(2))
    assert a.decide(net.t + 1.0) is d and a.adopt(net.t, "again") is d  # final


def test_adopt_needs_a_record_from_every_member() -> None:
    net = Net([0, 1], drop=lambda kind, s, d, t: True)
    net.run(1.0)
    with pytest.raises(ValueError, match="a record from each of the fleet's 3 members"):
        net.agents[0].adopt(net.t, "x")
    b = Agreement(0, rec(0), 0.0, fleet_size=None, digest_fn=canonical_digest)
    with pytest.raises(ValueError, match="fleet's None members"):
        b.adopt(0.0, "x")


# ---------------------------------------------------- re-sends that scale to 50 NAOs and more


def _peer_digest(sender: int, members: tuple[int, ...], digest: str = "ab" * 32) -> DigestMsg:
    return DigestMsg(sender=sender, round=0, digest=digest, members=members, params="")


def _lone(n: int = 3) -> Agreement[NeighborRecordMsg]:
    """Agent 0 of n, backoff 1 s doubling to 8 s; its first record and digest sent at 0."""
    a = Agreement(
        0, rec(0), 0.0, fleet_size=n, backoff_min=1.0, backoff_max=8.0,
        digest_fn=canonical_digest,
    )  # fmt: skip
    for j in range(1, n):
        a.member_joined(j, 0.0)
    assert a.due(0.0) == ["record", "digest"]
    a.sent(["record", "digest"], 0.0)  # the digest timer is due next at 1.0
    return a


def test_a_differing_digest_does_not_make_us_repeat_ours() -> None:
    a = _lone()
    a.on_record(rec(1), 0.1)
    assert a.due(0.1) == []  # incomplete: our changed digest waits for the timer
    a.on_digest(_peer_digest(1, (0, 1)), 0.2)  # differs from ours, lists us: nothing to say
    assert a.due(0.5) == []
    assert a.due(1.0) == ["digest"]  # the timer


def test_a_digest_that_lacks_our_record_is_answered_once() -> None:
    a = _lone()
    a.on_digest(_peer_digest(1, (1,)), 1.2)
    assert a.due(1.2) == ["record", "digest"]  # the answer, and the digest timer (1.0)
    a.sent(["record", "digest"], 1.2)  # digest timer next at 3.2
    assert a.due(1.3) == []  # once: the next answer waits for news or the timer
    a.on_digest(_peer_digest(1, (1,), "cd" * 32), 1.4)  # its next digest still lacks us
    assert a.due(1.4) == []  # news, but answers are at least backoff_min apart ...
    assert a.due(2.2) == []  # ... and each answer doubles that (crossed in flight)
    assert "record" in a.due(3.2)


def test_hint_answers_back_off_until_a_member_joins() -> None:
    a = _lone(4)
    times = []
    for k in range(40):  # a new digest lacking us every 0.1 s
        t = 0.1 * (k + 1)
        a.on_digest(_peer_digest(1, (1,), f"{k:064x}"), t)
        if "record" in a.due(t):
            a.sent(["record"], t)
            times.append(round(t, 1))
    assert times == [1.0, 3.0]  # 1 s after the first send, then 2 s (the timer agrees)
    a.member_joined(9, 4.0)  # a newcomer: prompt again, and answers 1 s apart again
    assert "record" in a.due(4.0)
    a.sent(["record"], 4.0)
    a.on_digest(_peer_digest(1, (1,), "ef" * 32), 5.0)
    assert "record" in a.due(5.0)


def test_a_complete_set_is_announced_then_repeated_quickly() -> None:
    a = _lone()
    a.on_record(rec(1), 0.2)
    a.on_record(rec(2), 0.3)
    assert a.due(0.3) == []  # complete, but at least backoff_min after the last digest
    assert a.due(1.0) == ["digest"]
    a.sent(["digest"], 1.0)  # complete: the timer restarts at 1 s, capped at 4·1 s
    assert a.due(1.5) == []
    assert a.due(2.0) == ["digest"]
    a.sent(["digest"], 2.0)
    assert a.due(3.9) == [] and a.due(4.0) == ["digest"]
    a.sent(["digest"], 4.0)
    assert a.due(7.9) == [] and a.due(8.0) == ["digest"]  # 4 s, not 8 s: the cap


def test_a_large_fleets_complete_set_is_repaired_at_a_bounded_rate() -> None:
    """100 members (backoff 0.25 to 16 s, the agent's settings), every record held, nobody's
    digest heard: our repairs double from 0.25 s up to 100 / HEARD_PER_S = 10 s,
    not 4·0.25 s (a 100-NAO run flooded with repairs)."""
    n = 100
    a = Agreement(0, rec(0), 0.0, fleet_size=n, backoff_max=16.0, digest_fn=canonical_digest)
    for j in range(1, n):
        a.member_joined(j, 0.0)
        a.on_record(rec(j), 0.0)
    assert a.complete_cap() == pytest.approx(n / HEARD_PER_S)
    sends = []
    for k in range(1200):  # 120 s in 0.1 s steps
        t = 0.1 * k
        if "digest" in a.due(t):
            a.sent(["digest"], t)
            sends.append(round(t, 1))
    gaps = [b - a_ for a_, b in itertools.pairwise(sends)]
    assert max(gaps) == pytest.approx(10.0, abs=0.11)
    # 0, then the doubling (0.25 ... 8 s, six sends to 15.8 s), then every 10 s: 17
    assert len(sends) == 17, sends


def test_exchange_bytes_stay_linear_when_searches_end_apart() -> None:
    """Seeded, simulated medium (tools.bench agent): 30 agents whose searches end over
    30 s publish a few kB each (before re-sends on news: ~7 kB mean, ~13 kB max)."""
    import numpy as np

    from tools.bench.agent import simulate

    r = simulate(30, 0.0, np.random.default_rng(5), stagger=30.0)
    assert r["agreed"] == 1.0
    assert r["bytes_mean"] < 3500 and r["bytes_max"] < 5000
