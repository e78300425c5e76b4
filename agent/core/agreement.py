"""Exchange and agreement of neighbour records (NAO paper 4.1.2, docs/design.md §1 steps 3–4).

The paper exchanges each robot's record ``{i, N_i, (x_ij, y_ij)}`` once over WiFi and
assumes nothing is lost. Here every agent re-publishes until the fleet provably holds
the same record set, and moves only then:

* **Membership** is the set of live agents (liveliness tokens, fed in by the caller);
  with ``fleet_size`` it must reach exactly that size, without it the set must stay
  unchanged for ``settle`` seconds.
* Each agent publishes its **record** and a **digest** of the records it holds
  (``DigestMsg.members`` = the ids whose records are covered, so a digest doubles as an
  acknowledgement of whose records the sender holds).
* **Agreed** when the agent holds a record from every member, the members are exactly
  the live set, and every member's latest digest equals its own (same digest, same
  members). Then all of them hold bit-identical inputs and compute the same plan.
* **Failed** (a safe stop, never a move on an unshared plan) when a member whose
  record we do not hold (or that reported ``failed``) leaves before agreement, the live
  set exceeds ``fleet_size``,
  or ``timeout`` seconds pass without news; the reason names who is missing. A member that leaves after
  its record arrived is out of reach, not gone (at 50 % loss a session stays
  cut for longer than any sensible grace): the agreement waits for it to come back
  (:meth:`Agreement.member_joined`) until ``timeout``, and nobody moves meanwhile,
  since agreement needs every member's matching digest.

**The timeout counts from the fleet's last news** (at 100 NAOs searches end far apart), not from
this agent's start: news is a record that changes the set held or a member's digest that changes.
In a fleet of 100 the searches end over ~15 minutes; an agent that searched early
would otherwise give up while the fleet is still converging (and, having stopped, end
everyone's agreement: "member left before agreement"). Each member's record and
digest can change only finitely often in a round (its held set only grows), so the
agreement still ends: agreed, or failed after ``timeout`` seconds in which nothing
moved.

**Patience follows the fleet** (docs/design.md §1 steps 1–4: every robot searches,
then exchanges; the agreement waits for every live member). A member that is alive and
still searching is news too: its status of a searching phase (:data:`SEARCHING_PHASES`,
progress or heartbeat, :meth:`Agreement.on_peer_phase` with the time) counts as news
while we hold no record of it for this round, so the agreement never gives up on a
member whose statuses show it still searching (at 100 NAOs, 23 robots still searching
at 780 s found the 77 others gone: "no news for 120 s"). It gives up only on members
that are truly silent (no record, digest or searching status for ``timeout`` s) or
gone (token lost and silent for the membership grace, below). A searcher ends its
search by itself (a record, or ``failed``), so the agreement still ends.

Re-publishing (what :meth:`Agreement.due` returns; its bytes stay O(N) at 50 NAOs):
prompt sends answer news (the record when it was never sent, a member joined, or a
member's new digest lacks it; the digest when it changed and the set held is complete, and once more on agreement);
a backoff timer (``backoff_min`` doubling to ``backoff_max``; after the set is complete
at most 4·``backoff_min``, or one repair per ``live / HEARD_PER_S`` seconds in a
larger fleet, so that what every member hears stays bounded) repairs losses while some
member's digest is missing or differs, after agreement until every member has reported
a post-agreement phase, and after a failure on parameters (as long as the caller
pumps). Pure: the caller passes the time and does the I/O.

Per-sender state is kept only for fleet members (hardened against hostile senders): a record, digest
or phase from a sender that is not a live member is ignored and counted in ``ignored``, so a
stranger cycling through 65 536 ids cannot grow it. Nothing is lost for a real member
whose record outran its liveliness token: our digest does not list it, which makes it
re-send its record (see the re-publishing rules above).

**Agreed parameters.** Equal records are not enough: every agent must also plan with
the same d_e, φ_e, radius, orientation and strategy, and march the same route. Each agent
hashes its own settings (:func:`agent.core.agreed_params.params_digest`) and sends that digest in every
``DigestMsg`` (``params``); a member whose parameters digest differs from ours counts as
disagreeing, and the agreement fails (an agent started with other settings is never
outvoted, and nobody plans or marches differently). To name the odd robot alike on every
agent, the failure waits until the parameters digest of every member is known (the
fleet complete when ``fleet_size`` is given; members that left count with their last
digest), or until ``timeout``; then the robots outside the largest group of equal
digests are named (:func:`agent.core.agreed_params.odd_params`; a tie goes to the group holding the smallest id).

**Membership grace.** On a lossy radio a live member's liveliness token can
vanish for a while (its zenoh lease expires, its client reconnects and declares the
token again). :class:`agent.core.grace.Grace` turns token changes and the member's own publications into
membership: a vanished token counts as gone only after ``grace`` seconds in which
nothing (record, digest or status) was heard from that member; a token that comes back,
or any publication, ends the count. The caller feeds :meth:`Agreement.member_left` only
with what :meth:`agent.core.grace.Grace.expired` returns.

Tie-breaks: a record with a higher ``round`` replaces an older one; for the same round
the latest received wins (re-publications are identical). Digests are over the
records sorted by sender id.

**Adopting** (a lossy radio, :meth:`Agreement.adopt`): agreement is asymmetric (two
generals); a member may agree and move while its matching digest never reaches us (its
session cut until it exits). The runner then lets us agree too when such a member,
with our parameters digest, reports the plan digest of exactly the records we hold:
it planned from the same inputs, so moving on that plan is moving on a shared plan.

**Rounds** (re-search, NAO paper 4.1.3 rule 2, :mod:`agent.core.formation.frame.research`): an
agreement belongs to the round of its own record (``round``). Records and digests of an
older round are stale and ignored (counted in ``stale``); a record or digest of a newer
round from a member proves that member agreed on ours and moved on, so it acknowledges
our digest (no more re-publication for it) and is left to the next round's agreement.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Generic

from agent.core.agreed_params import odd_params
from agent.core.agreement_terms import (
    Decision,
    DigestFn,
    DigestLike,
    DigestNote,
    R,
    RecordLike,
)
from agent.core.backoff import Backoff

__all__ = ["HEARD_PER_S", "Agreement", "Decision", "DigestLike", "DigestNote", "RecordLike"]

#: Publications of one kind (repairs of complete sets; progress statuses) a member hears
#: per second from the fleet, at most (docs/agent.md: repairs every 1 s flooded 100 NAOs).
HEARD_PER_S = 10.0

#: Phases an agent reports only after it has agreed (acknowledges our digest).
POST_AGREE_PHASES = frozenset({"plan", "wait", "move", "hold", "march", "done"})
#: Phases of a member still making its record (joined, searching, localising, walking to
#: search again): its statuses are news while its record is missing (module doc).
SEARCHING_PHASES = frozenset({"start", "search", "localise", "explore"})


class Agreement(Generic[R]):
    """The agreement state machine of one agent (see the module docstring)."""

    def __init__(
        self,
        self_id: int,
        own_record: R,
        now: float,
        fleet_size: int | None = None,
        timeout: float = 60.0,
        settle: float = 2.0,
        backoff_min: float = 0.25,
        backoff_max: float = 4.0,
        *,
        digest_fn: DigestFn[R],
        params: str = "",
    ) -> None:
        if own_record.sender != self_id:
            raise ValueError(f"own record is from {own_record.sender}, this agent is {self_id}")
        if fleet_size is not None and fleet_size < 1:
            raise ValueError(f"fleet size must be >= 1, got {fleet_size}")
        for name, v in (("timeout", timeout), ("settle", settle), ("now", now)):
            if not math.isfinite(v) or (name != "now" and v < 0.0):
                raise ValueError(f"{name} must be finite and >= 0, got {v}")
        if not (0.0 < backoff_min <= backoff_max and math.isfinite(backoff_max)):
            raise ValueError(
                f"need 0 < backoff_min <= backoff_max, got {backoff_min}, {backoff_max}"
            )
        self.self_id = self_id
        self.fleet_size = fleet_size
        self.timeout = timeout
        self.settle = settle
        self.started = now
        self.last_news = now  # the timeout counts from here (module doc)
        self.digest_fn = digest_fn
        self.params = params  # our agreed-parameters digest (params_digest)
        self.params_of: dict[int, str] = {}  # member (live or left) -> its params digest
        self.live: set[int] = {self_id}
        self.left: set[int] = set()
        self.stopped: set[int] = set()  # members that reported ``failed``
        self.records: dict[int, R] = {self_id: own_record}
        self.digests: dict[int, DigestLike] = {}
        self.peer_agreed: set[int] = set()
        self.rejected: list[str] = []
        self.ignored = 0  # records, digests and phases from non-members, not kept
        self.round = own_record.round  # the (re-)search round this agreement is about
        self.stale = 0  # records and digests of an older round, not kept
        self.membership_changed = now
        self._record_tx = Backoff(backoff_min, backoff_max)
        self._record_pending = True  # publish at least once (again after a newcomer)
        self._record_hint = False  # a member's new digest lacks our record: send once
        #: answers to such hints are at least this far apart, doubling with each answer
        #: (digests sent before our record reached their senders keep arriving after it)
        self._hint_gap = backoff_min
        self._digest_at: dict[int, float] = {}  # member -> when its latest digest arrived
        self._digest_tx = Backoff(backoff_min, backoff_max)
        self._digest_dirty = True  # our digest changed since we last published it
        self._min_gap = backoff_min  # prompt sends are at least this far apart
        self._backoff_max = backoff_max
        self._last_sent = {"record": -math.inf, "digest": -math.inf}
        self._final: Decision[R] | None = None
        self._params_failed = False  # failed on parameters: the digest is still answered
        self._digest_cache: tuple[tuple[int, ...], str] | None = None

    @classmethod
    def restored(
        cls,
        self_id: int,
        records: Sequence[R],
        now: float,
        *,
        digest_fn: DigestFn[R],
        params: str = "",
        backoff_max: float = 4.0,
    ) -> Agreement[R]:
        """The agreement of an agent restarted after it had agreed (a crash): the agreed
        ``records`` (its own among them), every member live, the decision ``agreed``.

        It re-publishes its digest until every member reports a post-agreement phase
        (see :meth:`due`), which tells the others that its new session holds the same
        set. Raises ``ValueError`` when ``records`` lack this agent's or repeat a sender.
        """
        by_id = {r.sender: r for r in records}
        if len(by_id) != len(records):
            raise ValueError("the agreed records repeat a sender")
        if self_id not in by_id:
            raise ValueError(f"the agreed records hold none of robot {self_id}")
        agr = cls(
            self_id, by_id[self_id], now, digest_fn=digest_fn, params=params,
            backoff_max=backoff_max,
        )  # fmt: skip
        agr.live = set(by_id)
        agr.records = dict(by_id)
        agr._final = agr._agreed("restored: ")
        return agr

    # ----------------------------------------------------------------- inputs

    def member_joined(self, robot_id: int, now: float) -> None:
        if robot_id in self.live:
            return
        self.live.add(robot_id)
        self.left.discard(robot_id)
        self.membership_changed = now
        # A newcomer has seen none of our earlier publications (no history).
        self._record_pending = True
        self._digest_dirty = True
        self._hint_gap = self._min_gap
        self._record_tx.reset(now)
        self._digest_tx.reset(now)

    def member_left(self, robot_id: int, now: float) -> None:
        if robot_id == self.self_id or robot_id not in self.live:
            return
        self.live.discard(robot_id)
        self.left.add(robot_id)
        self.membership_changed = now

    def on_record(self, msg: R, now: float) -> bool:
        """Take a record; True when it changed the set held."""
        if msg.sender == self.self_id:
            return False  # our own echo (or an impostor): ours is authoritative
        if msg.sender not in self.live:
            self.ignored += 1
            return False
        if not self._this_round(msg.sender, msg.round):
            return False
        old = self.records.get(msg.sender)
        if old is not None and (old.round > msg.round or old == msg):
            return False
        self.records[msg.sender] = msg
        self.last_news = now
        self._digest_cache = None
        self._digest_dirty = True
        return True

    def on_digest(self, msg: DigestLike, now: float) -> None:
        if msg.sender == self.self_id:
            return
        if msg.sender in self.left:  # its parameters still help to name the odd robot
            self.params_of[msg.sender] = msg.params
            return
        if msg.sender not in self.live:
            self.ignored += 1
            return
        if not self._this_round(msg.sender, msg.round):
            return
        old = self.digests.get(msg.sender)
        self.digests[msg.sender] = msg
        self._digest_at[msg.sender] = now
        self.params_of[msg.sender] = msg.params
        news = old is None or (old.digest, old.members) != (msg.digest, msg.members)
        if news:
            self.last_news = now
        if news and self.self_id not in msg.members:
            self._record_hint = True  # it lacks our record: answer once
        # A digest that differs from ours needs records, not our digest: no re-send.
        # (Before agreement had to scale, it reset our digest timer, which at 50 robots made every
        # agent publish its digest several times per record that arrived.)

    def _this_round(self, sender: int, round_: int) -> bool:
        """Whether a member's record or digest of ``round_`` belongs to this agreement;
        a newer round acknowledges our digest (see Rounds in the module doc)."""
        if round_ < self.round:
            self.stale += 1
            return False
        if round_ > self.round:
            if self.agreed:
                self.peer_agreed.add(sender)
            return False
        return True

    def on_peer_phase(self, robot_id: int, phase: str, now: float | None = None) -> None:
        """A member's status: a post-agreement phase acknowledges our digest; heard at
        ``now``, a searching phase of a member whose record we lack is news (patience,
        module doc; without ``now``, e.g. a phase remembered from before, it is not)."""
        if robot_id not in self.live:
            self.ignored += 1
        elif phase in POST_AGREE_PHASES:
            self.peer_agreed.add(robot_id)
        elif phase == "failed":
            self.stopped.add(robot_id)  # when it leaves, it will not return
        elif now is not None and phase in SEARCHING_PHASES and robot_id not in self.records:
            self.last_news = max(self.last_news, now)

    # ----------------------------------------------------------------- state

    def held_members(self) -> tuple[int, ...]:
        """Ids of the live members whose records we hold, sorted."""
        return tuple(sorted(i for i in self.records if i in self.live))

    def digest(self) -> tuple[tuple[int, ...], str]:
        """(members covered, digest) of the live members' records we hold."""
        members = self.held_members()
        if self._digest_cache is None or self._digest_cache[0] != members:
            recs = [self.records[i] for i in members]
            self._digest_cache = (members, self.digest_fn(recs))
        return self._digest_cache

    def digest_note(self) -> DigestNote:
        """Our digest, of this agreement's round, to publish."""
        members, digest = self.digest()
        return DigestNote(
            sender=self.self_id, round=self.round, digest=digest, members=members,
            params=self.params,
        )  # fmt: skip

    def missing_records(self) -> list[int]:
        return sorted(i for i in self.live if i not in self.records)

    def disagreeing(self) -> list[int]:
        """Live members whose latest digest is absent or differs from ours."""
        members, digest = self.digest()
        out = []
        for i in sorted(self.live - {self.self_id}):
            d = self.digests.get(i)
            if d is None or d.digest != digest or d.members != members or d.params != self.params:
                out.append(i)
        return out

    def decide(self, now: float) -> Decision[R]:
        """Wait, agreed or failed. Agreed and failed are final."""
        if self._final is not None:
            return self._final
        params_wait = self._params_decision(now)
        if params_wait is not None:
            return params_wait
        gone = sorted(i for i in self.left if i not in self.records or i in self.stopped)
        if gone:
            return self._fail(
                f"member(s) {gone} left before agreement; not moving on a plan they may not share"
            )
        n = len(self.live)
        if self.fleet_size is not None and n > self.fleet_size:
            return self._fail(
                f"{n} members alive {sorted(self.live)}, more than the fleet size {self.fleet_size}"
            )
        missing = self.missing_records()
        disagree = self.disagreeing()
        size_ok = n == self.fleet_size if self.fleet_size is not None else n >= 1
        settled = self.fleet_size is not None or now - self.membership_changed >= self.settle
        if size_ok and settled and not missing and not disagree:
            self._final = self._agreed()
            self._digest_dirty = True  # tell the others once more, promptly
            return self._final
        if self.timed_out(now):
            parts = [
                f"no agreement: no news for {self.timeout:g} s "
                f"({now - self.started:.0f} s after the exchange began)"
            ]
            if self.fleet_size is not None and n != self.fleet_size:
                parts.append(f"{n} of {self.fleet_size} members alive {sorted(self.live)}")
            if missing:
                parts.append(f"no record from {missing}")
            if disagree:
                parts.append(f"digest differs or missing from {disagree}")
            return self._fail("; ".join(parts))
        return Decision("wait", self._wait_reason(missing, disagree))

    def adopt(self, now: float, why: str) -> Decision[R]:
        """Agreed on the records held, without every member's matching digest: the caller
        saw a member act on the plan of exactly these records (``agent.phases.runner``; on a lossy
        radio that member's digest may never reach us). Needs a record from every member of a
        fleet of known size (members out of reach included); final like :meth:`decide`.
        """
        if self._final is not None:
            return self._final
        members = tuple(sorted(self.records))
        if self.fleet_size is None or len(members) != self.fleet_size:
            raise ValueError(
                f"adopting needs a record from each of the fleet's {self.fleet_size} members, "
                f"holding {list(members)}"
            )
        recs = tuple(self.records[i] for i in members)
        self._final = Decision("agreed", why, self.digest_fn(recs), members, recs)
        self._digest_dirty = True
        return self._final

    def _params_decision(self, now: float) -> Decision[R] | None:
        """None while every known parameters digest equals ours; else ``failed``, naming
        the odd robots (:func:`odd_params`) once every member's digest is known or at the
        timeout, and ``wait`` until then."""
        known = {i: p for i, p in self.params_of.items() if i in self.live or i in self.left}
        if all(p == self.params for p in known.values()):
            return None
        known[self.self_id] = self.params
        unknown = sorted(i for i in self.live if i not in known)
        complete = self.fleet_size is None or len(self.live | self.left) >= self.fleet_size
        timed_out = self.timed_out(now)
        odd, ref = odd_params(known)
        if (unknown or not complete) and not timed_out:
            return Decision(
                "wait",
                f"planning parameters differ (robots {odd} from {ref} so far); "
                f"waiting for the parameters of {unknown or 'the whole fleet'} to name who",
            )
        names = ", ".join(f"{i}: {known[i][:12] or '(none)'}" for i in odd)
        self._params_failed = True
        mine = " (this robot among them)" if self.self_id in odd else ""
        return self._fail(
            f"robot(s) {odd} plan with different parameters{mine}: params digest {names}; "
            f"robots {ref}: {known[ref[0]][:12] or '(none)'}"
            + (f"; parameters unknown for {unknown}" if unknown else "")
            + "; nobody plans or marches"
        )

    def timed_out(self, now: float) -> bool:
        """Whether ``timeout`` seconds passed since the fleet's last news (module doc)."""
        return now - self.last_news > self.timeout

    def _wait_reason(self, missing: list[int], disagree: list[int]) -> str:
        if self.left:
            return f"member(s) {sorted(self.left)} out of reach; waiting for them to return"
        if self.fleet_size is not None and len(self.live) < self.fleet_size:
            return f"{len(self.live)} of {self.fleet_size} members"
        if missing:
            return f"waiting for records from {missing}"
        if disagree:
            return f"waiting for matching digests from {disagree}"
        return "waiting for membership to settle"

    def _agreed(self, prefix: str = "") -> Decision[R]:
        """The ``agreed`` decision on the records held now."""
        members, digest = self.digest()
        return Decision(
            "agreed",
            f"{prefix}{len(members)} members agree on digest {digest[:12]}",
            digest,
            members,
            tuple(self.records[i] for i in members),
        )

    def _fail(self, reason: str) -> Decision[R]:
        self._final = Decision("failed", reason)
        return self._final

    @property
    def agreed(self) -> bool:
        return self._final is not None and self._final.kind == "agreed"

    # ----------------------------------------------------------------- output

    def due(self, now: float) -> list[str]:
        """What to (re-)publish now: a subset of ``["record", "digest"]`` in that order.

        Prompt sends answer news, at most one per ``backoff_min``: the record when it was
        never sent, a member joined, or a member's new digest lacks it (those answers
        ``backoff_min`` apart, then twice that after each one, up to ``backoff_max``,
        until a member joins: at 50 NAOs on 2 cores digests that crossed our record in
        flight had each agent send it 5–6 times); the digest when it
        changed and we hold a record of every live member (a digest of an incomplete set
        cannot be agreed on; others learn what we lack from the slow re-sends), and once
        more when we agree. A backoff timer (``backoff_min`` doubling to ``backoff_max``,
        reset by a newcomer and when our set becomes complete, then capped at
        :meth:`complete_cap`) re-sends while something is still unacknowledged, so
        that lost publications are repaired: bytes per agent grow with the fleet size and
        the time spent waiting, not with their product (also at 50 NAOs). The caller publishes
        and then calls :meth:`sent` with the same list.
        """
        out: list[str] = []
        if self._final is not None and self._final.kind == "failed":
            # after a parameters failure our digest (our parameters) still goes out, so
            # that members that have not heard it yet name the same odd robot
            if self._params_failed and (self._prompt("digest", now) or self._digest_tx.due(now)):
                out.append("digest")
            return out
        others = self.live - {self.self_id}
        if self.agreed:
            if (others - self.peer_agreed) and (
                self._prompt("digest", now) or self._digest_tx.due(now)
            ):
                out.append("digest")
            return out
        # Re-send the record only to answer a digest that lacks it: a peer still
        # searching publishes its digest when it starts exchanging, which re-arms us.
        # ... and only a digest that arrived after our last send: an older one is no news
        # (a member whose set is incomplete publishes its digest only on its slow timer)
        unacked = self._unacked(others)
        hinted = self._record_hint and now - self._last_sent["record"] >= self._hint_gap
        if (
            (self._record_pending and self._spaced("record", now))
            or hinted
            or ((unacked or not others) and self._record_tx.due(now))
        ):
            out.append("record")
        complete = not self.missing_records()
        # a complete set is what the others wait for: repaired at most complete_cap() apart
        self._digest_tx.hi = self.complete_cap() if complete else self._backoff_max
        if complete and self._prompt("digest", now):
            self._digest_tx.reset(now)
            out.append("digest")
        elif (self.disagreeing() or not others) and self._digest_tx.due(now):
            out.append("digest")
        return out

    def _unacked(self, others: set[int]) -> list[int]:
        """Members whose digest lacks our record and arrived after our last send."""
        return [
            i
            for i in others
            if i in self.digests
            and self.self_id not in self._members_of(i)
            and self._digest_at.get(i, -math.inf) > self._last_sent["record"]
        ]

    def next_wake(self, now: float) -> float:
        """The first time after ``now`` at which, with nothing heard, :meth:`due` or
        :meth:`decide` may answer differently (``math.inf``: never): a prompt send's
        spacing, a re-send timer, the timeout, the settling of membership. Called right
        after :meth:`due` was acted on, so a waiting caller sleeps until then or until
        something arrives (agent/phases/membership.py)."""
        last = self._last_sent
        out: list[float] = []
        others = self.live - {self.self_id}
        if self._final is not None:
            waiting = self._params_failed if self._final.kind == "failed" else self.agreed
            if waiting and (self._final.kind == "failed" or others - self.peer_agreed):
                if self._digest_dirty:
                    out.append(last["digest"] + self._min_gap)
                out.append(self._digest_tx.next_at)
        else:
            out.append(self.last_news + self.timeout + 1e-3)  # timed_out is strict
            if self.fleet_size is None:
                out.append(self.membership_changed + self.settle)
            if self._record_pending:
                out.append(last["record"] + self._min_gap)
            if self._record_hint:
                out.append(last["record"] + self._hint_gap)
            if self._unacked(others) or not others:
                out.append(self._record_tx.next_at)
            complete = not self.missing_records()
            if complete and self._digest_dirty:
                out.append(last["digest"] + self._min_gap)
            if self.disagreeing() or not others:
                out.append(self._digest_tx.next_at)
        return min((t for t in out if t > now), default=math.inf)

    def complete_cap(self) -> float:
        """Longest gap (s) between repairs of our complete set: 4·``backoff_min``, or
        ``live / HEARD_PER_S`` in a larger fleet, at most ``backoff_max``."""
        spread = len(self.live) / HEARD_PER_S
        return min(self._backoff_max, max(4.0 * self._min_gap, spread))

    def _spaced(self, what: str, now: float) -> bool:
        return now - self._last_sent[what] >= self._min_gap

    def _prompt(self, what: str, now: float) -> bool:
        return self._digest_dirty and self._spaced(what, now)

    def sent(self, what: Iterable[str], now: float) -> None:
        for w in what:
            if w == "record":
                if self._record_hint and not self._record_pending:
                    self._hint_gap = min(self._backoff_max, 2.0 * self._hint_gap)
                self._record_pending = False
                self._record_hint = False
                self._record_tx.fired(now)
            elif w == "digest":
                self._digest_dirty = False
                self._digest_tx.fired(now)
            else:
                raise ValueError(f"unknown publication {w!r}")
            self._last_sent[w] = now

    def _members_of(self, robot_id: int) -> tuple[int, ...]:
        d = self.digests.get(robot_id)
        return () if d is None else d.members
