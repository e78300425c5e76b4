"""Membership: what this agent hears of the fleet, and says back (docs/design.md §8 "Faults";
NAO paper 4.1.2, the exchange of records).

The papers assume lossless WiFi and robots that never leave. Here the fleet is whoever
holds an alive token (``nao/alive/{id}``), and one :class:`Membership` per agent keeps
what it knows of each member (:class:`Peer`):

* **Tokens and grace.** A token that appears makes a member; a vanished token is a
  departure only once the member has also been silent for the membership grace
  (:class:`agent.core.grace.Grace`): on a lossy link sessions are cut and restored.
* **Key ownership and sessions.** A record, digest or status counts only from the robot
  its key names, and only from that robot's current session (:meth:`current_session`):
  after agreement, from the session whose record was agreed, or a new one that shows the
  agreed digest (a member resumed after a crash).
* **Early records.** Records and digests heard before this agent's own agreement round
  (or of a later round) are kept per sender, newest round first, and handed to the
  agreement when it opens (:meth:`open_round`).
* **Pump.** Every wait of every phase pumps: handle what arrived, expire members, and
  (re-)publish what the agreements say is due (agent/core/agreement.py); agreements of
  earlier re-search rounds are retired but acknowledged until every member moved on.
* **Waiting costs nothing** (docs/design.md §1, every phase waits on the fleet):
  :meth:`Membership.wait_until` sleeps on the bus's queue until something arrives or the
  next deadline: the caller's (its phase's timeout, its next status), or this
  membership's own (an agreement's next re-send, timeout or settling,
  :meth:`agent.core.agreement.Agreement.next_wake`; a vanished member's grace,
  :meth:`agent.core.grace.Grace.next_expiry`). No polls: an agent waiting for a quiet
  fleet wakes for the fleet's statuses and its own heartbeat, a few times a minute
  (``python -m tools.bench idle``).

It also serves the agreed record set (agent/phases/record_sets.py), and hands every
record, digest and status it accepts to its :attr:`Membership.observers` (the check of
agent/recovery/runs.py: is a journal's run still going?).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Collection
from dataclasses import asdict, dataclass
from typing import TypeVar

from agent.core.agreement import Agreement
from agent.core.formation.plan import Plan
from agent.core.formation.waves.jam import stop_reason
from agent.core.grace import Grace
from agent.net.bus import Event
from agent.phases.context import Context
from agent.phases.record_sets import answer
from agent.phases.reporting import Phase
from agent.wire import (
    KEY_ALIVE_ALL,
    KEY_DIGEST_ALL,
    KEY_RECORD_ALL,
    KEY_RESHAPE,
    KEY_STATUS_ALL,
    DigestMsg,
    NeighborRecordMsg,
    RecordSetReply,
    ReshapeMsg,
    StatusMsg,
    id_from_key,
    key_alive,
    key_digest,
    key_record,
    key_records,
)

log = logging.getLogger("agent.phases.membership")

#: phases of a member that has arrived
ARRIVED = (Phase.HOLD, Phase.MARCH, Phase.DONE, Phase.FAILED)
#: The longest sleep of :meth:`Membership.wait_until` (s). What a wait looks at changes
#: only when something arrives (the bus's queue wakes the sleeper) or at a deadline the
#: wait names (its phase's, its next status, an agreement's, a grace's), so no poll is
#: needed: every waiting phase names its next status (agent/phases/reporting.py, at most a
#: heartbeat away), and this bound only caps a sleep whose caller names no deadline.
MAX_WAIT = 60.0
#: Plans an agent keeps the operator's newest reshape command for (each command names the
#: plan it reshapes): a bound on what a flood of commands can make it hold.
COMMANDS_KEPT = 8
#: The sleep when the next deadline has already passed (s): its owner acts on it after
#: this wait; this keeps a deadline nobody acts on from spinning the loop.
MIN_WAIT = 0.01

_Round = TypeVar("_Round", NeighborRecordMsg, DigestMsg)


def _keep_newest(store: dict[int, _Round], msg: _Round) -> None:
    """Keep ``msg`` for its sender unless a message of a newer round is held."""
    old = store.get(msg.sender)
    if old is None or old.round <= msg.round:
        store[msg.sender] = msg


@dataclass
class Peer:
    """What this agent knows of one member: its token, and its last status."""

    alive: bool = False
    phase: str = ""  # of its last status (a Phase value; "": none heard yet)
    detail: str = ""
    wave: int = -1
    plan_digest: str = ""
    seen_alive: bool = False
    error: str = ""  # the reason of a ``failed`` status
    blocked_by: int = -1  # the member it is blocked by (a dense fleet's jam); -1: none
    # how far it has walked along its path of plan ``plan_digest`` (finer
    # waits): the largest value heard for that plan (the robot only walks on)
    walked: float = 0.0
    # how far it has stepped since it arrived (m, common frame of ``plan_digest``)
    shift: tuple[float, float] = (0.0, 0.0)


def on_plan(peer: Peer, phases: Collection[str], digest: str) -> bool:
    """Whether ``peer`` is in one of ``phases`` of the plan ``digest`` ("": of any plan).
    A failed member counts whatever its plan; one that shows no digest yet counts too.
    After a reshape the fleet's statuses name two plans for a while: a member ``done``
    on the plan it held has not yet started the new one (agent/phases/transitions/reshaping.py)."""
    if peer.phase not in phases:
        return False
    return not digest or peer.phase == Phase.FAILED or peer.plan_digest in ("", digest)


class Membership:
    """The fleet as heard by one agent; see the module docstring."""

    def __init__(self, ctx: Context) -> None:
        self.ctx = ctx
        self.peers: dict[int, Peer] = {}
        self.grace = Grace(ctx.cfg.member_grace)  # a vanished token is gone only after it
        self.early_records: dict[int, NeighborRecordMsg] = {}
        self.early_digests: dict[int, DigestMsg] = {}
        self.epochs: dict[int, int] = {}  # newest session (epoch) heard per sender
        self.agreed_epochs: dict[int, int] = {}  # the sessions the agreement was made with
        self.agreed_plan = ""  # the digest of the plan of that agreement ("" before one)
        self.agreement: Agreement[NeighborRecordMsg] | None = None
        self.retired: list[Agreement[NeighborRecordMsg]] = []  # agreed earlier rounds
        self.served: RecordSetReply | None = None  # the agreed record set we serve
        # called with each record, digest or status accepted (its key owned by its
        # sender, from the sender's current session), before it is handled
        self.observers: list[Callable[[Event], None]] = []
        #: the operator's newest reshape command per plan it reshapes (its ``base``;
        #: the bus let through only the operator's signature on its key), at most
        #: :data:`COMMANDS_KEPT`; agent/phases/transitions/reshaping.py acts on the held plan's
        self.commands: dict[str, ReshapeMsg] = {}

    def start(self) -> None:
        """Subscribe to the fleet (what others publish: our own records, digests and
        statuses are never delivered back, :meth:`agent.net.bus.Bus.subscribe`), declare
        our token, serve the agreed record set."""
        bus, me = self.ctx.bus, self.ctx.me
        for key in (KEY_RECORD_ALL, KEY_DIGEST_ALL, KEY_STATUS_ALL, KEY_RESHAPE):
            bus.subscribe(key, remote_only=True)  # our own come back only to be dropped
        bus.watch_alive(KEY_ALIVE_ALL)
        bus.declare_alive(key_alive(me))
        bus.serve(key_records(me), lambda req: answer(self.served, req))

    def peer(self, rid: int) -> Peer:
        """What we know of ``rid`` (a blank :class:`Peer` if nothing)."""
        return self.peers.get(rid, Peer())

    def pump(self, timeout: float = 0.0) -> None:
        """Handle what arrived (waiting up to ``timeout`` s for the first event); expire
        members; (re-)publish what the agreements say is due."""
        bus = self.ctx.bus
        for ev in bus.drain(timeout):
            try:
                self.handle(ev)
            except Exception as exc:  # one bad event is counted and skipped, never fatal
                bus.guard.reject(f"event on {ev.key}", exc)
        self.expire()
        self.publish_due()

    def publish_due(self) -> None:
        """(Re-)publish what the agreements say is due now."""
        bus, me = self.ctx.bus, self.ctx.me
        for agr in self.agreements():
            now = self.ctx.clock()
            due = agr.due(now)
            for what in due:
                if what == "record":
                    bus.publish(key_record(me), agr.records[me], "record")
                else:
                    bus.publish(key_digest(me), DigestMsg(**asdict(agr.digest_note())), "digest")
            agr.sent(due, now)

    def next_wake(self, now: float) -> float:
        """This membership's next deadline after ``now`` (``math.inf``: none): an
        agreement's (:meth:`~agent.core.agreement.Agreement.next_wake`) or a vanished
        member's grace (module docstring)."""
        times = [a.next_wake(now) for a in self.agreements()]
        return min([self.grace.next_expiry(), *times])

    def wait_until(self, deadline: float) -> None:
        """Sleep until something arrives, ``deadline`` (the caller's, on ``ctx.clock``)
        or this membership's own next deadline, whichever is first (no poll: at most
        :data:`MAX_WAIT` when none is named); then pump (module docstring). What is due now is published
        before the sleep."""
        self.expire()
        self.publish_due()
        now = self.ctx.clock()
        until = min(deadline, self.next_wake(now))
        self.pump(MIN_WAIT if until <= now else min(MAX_WAIT, until - now))

    def agreements(self) -> list[Agreement[NeighborRecordMsg]]:
        """The current agreement and the agreed ones of earlier re-search rounds (their
        digests are re-published until every member has moved on)."""
        return [*self.retired, *([self.agreement] if self.agreement is not None else [])]

    def handle(self, ev: Event) -> None:
        """One bus event: a token, or a record, digest or status of a member."""
        now = self.ctx.clock()
        me = self.ctx.me
        agr = self.agreement
        if ev.kind in ("alive", "gone"):
            peer = self.peers.setdefault(ev.robot_id, Peer())
            back = not peer.alive or ev.robot_id in self.grace.pending()
            self.grace.token(ev.robot_id, ev.kind == "alive", now)
            if ev.kind == "alive":  # a vanished token counts as gone in expire
                if ev.robot_id != me and back:  # new, or back after its links were cut: it
                    self.ctx.report.say_again()  # may have missed our (slow) status
                peer.alive = peer.seen_alive = True
                if agr is not None and ev.robot_id != me:
                    agr.member_joined(ev.robot_id, now)
            return
        msg = ev.msg
        if isinstance(msg, ReshapeMsg) and ev.key == KEY_RESHAPE:
            self.take_command(msg)
            return
        if not isinstance(msg, NeighborRecordMsg | DigestMsg | StatusMsg):
            return
        try:
            key_id = id_from_key(ev.key)
        except ValueError:
            key_id = None
        if key_id != msg.sender:
            log.warning(
                "dropped %s on %s: sender %s does not own the key", msg.TAG, ev.key, msg.sender
            )
            return
        if not self.current_session(ev, msg.sender):
            return
        for observe in self.observers:
            observe(ev)
        self.grace.heard(msg.sender, now)  # a member's publication is a heartbeat
        if isinstance(msg, NeighborRecordMsg | DigestMsg):
            for a in self.agreements():
                if isinstance(msg, NeighborRecordMsg):
                    a.on_record(msg, now)
                else:
                    a.on_digest(msg, now)
            # kept for the next round: before our agreement, or newer than its round
            early = agr is None or msg.round > agr.round
            if early and msg.sender != me and self.member(msg.sender):
                if isinstance(msg, NeighborRecordMsg):
                    _keep_newest(self.early_records, msg)
                else:
                    _keep_newest(self.early_digests, msg)
        elif isinstance(msg, StatusMsg):
            member = self.peers.get(msg.sender)
            if msg.sender == me or member is None or not member.seen_alive:
                return  # per-sender state only for members (their token came first)
            same_plan = msg.plan_digest == member.plan_digest
            member.walked = max(member.walked, msg.walked) if same_plan else msg.walked
            member.phase, member.wave, member.plan_digest = msg.phase, msg.wave, msg.plan_digest
            member.detail = msg.detail
            member.error, member.blocked_by = msg.error, msg.blocked_by
            member.shift = (msg.shift_x, msg.shift_y)
            for a in self.agreements():
                a.on_peer_phase(msg.sender, msg.phase, now)  # a searcher's: news

    def take_command(self, msg: ReshapeMsg) -> None:
        """Keep the operator's command ``msg`` if it is the newest for its plan (a retry
        repeats its number); it waits there until this robot holds that plan
        (agent/phases/transitions/reshaping.py; meanwhile it is deferred, and said so)."""
        old = self.commands.get(msg.base)
        if old is not None and old.command >= msg.command:
            return
        self.commands.pop(msg.base, None)
        self.commands[msg.base] = msg
        while len(self.commands) > COMMANDS_KEPT:  # the oldest plan's goes first
            del self.commands[next(iter(self.commands))]
        report = self.ctx.report
        if report.phase != Phase.DONE:
            log.info("reshape command %d deferred: robot in %s", msg.command, report.phase)
            text = f"reshape {msg.command} to {msg.name} deferred until the fleet holds"
            report.status(report.phase, 0.0, text, force=True)

    def expire(self) -> None:
        """Members whose token vanished and who stayed silent for the grace period are gone."""
        now = self.ctx.clock()
        for rid in self.grace.expired(now):
            peer = self.peers.get(rid)
            if peer is None or not peer.alive:
                continue
            peer.alive = False
            log.warning("robot %d is gone (token lost, silent for %g s)", rid, self.grace.grace)
            if self.agreement is not None and rid != self.ctx.me:
                self.agreement.member_left(rid, now)

    def proves_agreement(self, msg: object) -> bool:
        """Whether ``msg`` shows the record-set digest (or plan digest) we agreed on."""
        agr = self.agreement
        if agr is None or not agr.agreed:
            return False
        if isinstance(msg, DigestMsg):
            members, digest = agr.digest()
            return msg.digest == digest and msg.members == members and msg.params == agr.params
        plan_digest = self.agreed_plan
        return isinstance(msg, StatusMsg) and bool(plan_digest) and msg.plan_digest == plan_digest

    def member(self, rid: int) -> bool:
        peer = self.peers.get(rid)
        return peer is not None and peer.alive

    def current_session(self, ev: Event, sender: int) -> bool:
        """Whether ``ev`` comes from the member's current session (docs/design.md §8).

        Secure buses tag each message with its signer's epoch (the sending process's
        start). A message from an older session of a member than one already heard is
        stale (a replay, or a process since replaced); once the fleet has agreed, only
        the session whose record was agreed counts. Insecure buses carry no epoch.
        """
        if ev.epoch < 0:
            return True
        pinned = self.agreed_epochs.get(sender)
        if pinned is not None:
            if ev.epoch > pinned and self.proves_agreement(ev.msg):
                # a member restarted after agreeing: its new session counts
                log.info("robot %d resumed in a new session with the agreed digest", sender)
                self.agreed_epochs[sender] = self.epochs[sender] = ev.epoch
            return ev.epoch == self.agreed_epochs[sender]
        if ev.epoch < self.epochs.get(sender, -1):
            return False
        self.epochs[sender] = ev.epoch
        return True

    # ------------------------------------------------------------ agreement rounds

    def open_round(self, agr: Agreement[NeighborRecordMsg]) -> None:
        """Make ``agr`` the current agreement, handed all that was heard before it: the
        members, their early records and digests, who left, every member's phase."""
        now = self.ctx.clock()
        me = self.ctx.me
        for rid, peer in sorted(self.peers.items()):
            if rid != me and peer.seen_alive:
                agr.member_joined(rid, now)
        for msg in self.early_records.values():
            agr.on_record(msg, now)
        for dmsg in self.early_digests.values():
            agr.on_digest(dmsg, now)
        for rid, peer in sorted(self.peers.items()):
            if rid != me and peer.seen_alive and not peer.alive:
                # it was a member and left while we searched: a departure too (with its
                # record held, one it may return from, agent.core.agreement)
                agr.member_left(rid, now)
        self.early_records = {i: m for i, m in self.early_records.items() if m.round > agr.round}
        self.early_digests = {i: m for i, m in self.early_digests.items() if m.round > agr.round}
        for rid, peer in self.peers.items():
            agr.on_peer_phase(rid, peer.phase)
        self.agreement = agr

    def retire(self) -> None:
        """The current agreement is done with (a re-search round follows); its digest is
        still acknowledged until every member has moved on."""
        if self.agreement is not None:
            self.retired.append(self.agreement)
        self.agreement = None

    def pin_sessions(self, members: set[int], plan_digest: str) -> None:
        """From the plan on (its digest ``plan_digest``), only the sessions the agreement
        was made with count, or a new one of a member that shows the agreed digest."""
        self.agreed_epochs = {r: e for r, e in self.epochs.items() if r in members}
        self.agreed_plan = plan_digest

    def fleet_stop(self, plan: Plan | None) -> str:
        """Why this robot must stop because a member of ``plan`` (None: no plan yet)
        failed ("" if none): the one reason of agent/core/formation/waves/jam.py rule 4,
        so that no agent reports a formation with a hole as held. Robots the plan left
        out (they stop by design) and members that only left do not count."""
        if plan is None:
            return ""
        counted = set(self.ctx.formation.members(plan)) - set(plan.excluded) - {self.ctx.me}
        return stop_reason(
            {
                i: p.error
                for i, p in sorted(self.peers.items())
                if i in counted and p.phase == Phase.FAILED
            }
        )

    def arrived(self, among: Collection[int] | None = None, digest: str = "") -> bool:
        """Whether every live member of the agreement (or of ``among``) has arrived
        (:data:`ARRIVED`); with ``digest``, on that plan (a member still holding the
        plan before a reshape has not started the new one: it may walk yet)."""
        if among is None:
            among = self.agreement.held_members() if self.agreement else ()
        for i in among:
            peer = self.peer(i)
            if i != self.ctx.me and peer.alive and not on_plan(peer, ARRIVED, digest):
                return False
        return True
