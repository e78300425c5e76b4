"""Which run of the fleet a journal belongs to, and whether that run is still going
(a finished run's journal must not derail the next run; docs/design.md §8 "Faults"; docs/faults.md
"Crashed agents and restarted routers").

A journal (:mod:`agent.recovery.journal`) belongs to one run of the fleet. Its identity:

* **before agreement**: this robot's record round (0 before its first record) and the
  run's start, ``run_epoch`` (when this robot's first process of the run started, ms
  since the Unix epoch, kept across resumptions); the journal's last write,
  ``written_ms``, bounds the sessions that ran alongside it;
* **after agreement**: the agreed record-set digest and its members (the records hold
  every robot's measured neighbours: the sets of two runs never hash alike).

A restarted agent learns from the bus whether "its" run is still going, and resumes the
journal only then (:meth:`RunCheck.check`):

* a **final** journal (``done``, ``failed`` or ``stopped``) never: its run is over;
* **after agreement**: when another live agent serves the agreed record set (the
  record-set query by digest of :mod:`agent.phases.record_sets`, :func:`fetch_records`,
  asked again for up to :data:`SERVED_WAIT` s);
* **before agreement**: when the others agreed meanwhile on a set holding this robot's
  record exactly as journaled (:func:`agreed_by_others`), or when, within
  :data:`PEERS_WAIT` s, another robot is heard from a session that began before the
  journal's last write publishing a record or digest of the journal's round, or a
  status of a phase before agreement (:data:`EXCHANGING`). Secure buses tag every
  message with its sender's session epoch (the process start, ``agent.wire.trust``): a
  session that began after the journal's last write belongs to a later run (or to a
  peer restarted since; either way it is no evidence). Insecure buses carry no epoch:
  any session counts there.

Otherwise the journal is archived and the robot starts afresh. A wrong "ended" is safe:
the fresh robot searches again and its new record matches no agreement of the others
(their sessions are pinned once agreed); a wrong "going" is what the evidence rules out.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

from agent.body.zenoh_world import retry_no_route
from agent.net.bus import Bus, BusError, Event
from agent.phases.context import Context
from agent.phases.reporting import Phase
from agent.phases.roles import Hearing, Listening
from agent.recovery.journal import JournalState
from agent.wire import (
    KEY_RECORDS_ALL,
    DigestMsg,
    NeighborRecordMsg,
    ProtocolError,
    RecordSetReply,
    RecordSetRequest,
    StatusMsg,
    decode,
    records_of,
)

log = logging.getLogger("agent.recovery.runs")

#: s a restarted agent keeps asking the fleet for its agreed records while resuming.
FETCH_TIMEOUT = 60.0
#: s one record-set query waits for replies.
QUERY_TIMEOUT = 3.0
#: s a restarted agent asks for the agreed record set before it deems the run over.
SERVED_WAIT = 20.0
#: s a restarted agent listens for peers exchanging before it deems the run over
#: (statuses are repeated at least every 3 s, records and digests every 16 s at most).
PEERS_WAIT = 15.0
#: A peer's status in one of these phases shows a run before agreement.
EXCHANGING = (
    Phase.START,
    Phase.SEARCH,
    Phase.LOCALISE,
    Phase.EXCHANGE,
    Phase.AGREE,
    Phase.EXPLORE,
)


# --------------------------------------------------------------------------- asking the fleet


def agreed_by_others(bus: Bus, own: NeighborRecordMsg) -> tuple[str, tuple[int, ...]] | None:
    """(digest, members) of a record set the others agreed on while this agent was down
    (after its digest had matched theirs), holding its record exactly as journaled; None
    when nobody has agreed. Asks once for any agreed set (``RecordSetRequest("")``)."""

    def check(rep: RecordSetReply) -> tuple[NeighborRecordMsg, ...]:
        try:
            senders = tuple(sorted(decode(r, NeighborRecordMsg).sender for r in rep.records))
        except ProtocolError as exc:
            raise ValueError(str(exc)) from None
        recs = records_of(rep, rep.digest, senders)
        if own not in recs:
            raise ValueError(f"record set {rep.digest[:12]} lacks this robot's record")
        return recs

    def accept(rep: RecordSetReply) -> str:
        try:
            check(rep)
        except ValueError as exc:
            return str(exc)
        return ""

    try:
        rep = retry_no_route(
            lambda: bus.query(
                KEY_RECORDS_ALL, RecordSetRequest(digest=""), RecordSetReply, QUERY_TIMEOUT, accept
            ),
            QUERY_TIMEOUT,
        )
    except BusError:
        return None
    return rep.digest, tuple(r.sender for r in check(rep))


def fetch_records(
    ctx: Context,
    fleet: Hearing,
    digest: str,
    members: Sequence[int],
    timeout: float = FETCH_TIMEOUT,
) -> tuple[NeighborRecordMsg, ...]:
    """Ask every agent for the record set ``digest`` until one answers with it;
    ``ValueError`` when nobody has within ``timeout`` s."""

    def accept(rep: RecordSetReply) -> str:
        try:
            records_of(rep, digest, members)
        except ValueError as exc:
            return str(exc)
        return ""

    end = ctx.clock() + timeout
    last = "no reply"
    while ctx.clock() < end:
        try:
            rep = retry_no_route(
                lambda: ctx.bus.query(
                    KEY_RECORDS_ALL,
                    RecordSetRequest(digest=digest),
                    RecordSetReply,
                    min(QUERY_TIMEOUT, max(0.1, end - ctx.clock())),
                    accept,
                ),
                QUERY_TIMEOUT,
            )
            log.info("agreed records %s fetched from robot %d", digest[:12], rep.sender)
            return records_of(rep, digest, members)
        except BusError as exc:
            last = str(exc)
        fleet.pump(0.5)  # keep hearing the fleet while nobody answers
    raise ValueError(f"nobody served the agreed records {digest[:12]} in {timeout:g} s: {last}")


# --------------------------------------------------------------------------- the check


@dataclass(frozen=True)
class Verdict:
    """Whether a journal's run is still going, why, and what the check learnt of it."""

    going: bool
    why: str
    #: (digest, members) of the record set the run agreed on, when known.
    agreed: tuple[str, tuple[int, ...]] | None = None
    #: That set's records, fetched and checked against the digest (after agreement).
    records: tuple[NeighborRecordMsg, ...] = ()


def journal_round(st: JournalState) -> int:
    """The round of the journal's run before agreement: its record's (0 before one)."""
    return st.record.round if st.record is not None else 0


class RunCheck:
    """Asks the bus whether the run of a journal is still going (module docstring)."""

    def __init__(
        self,
        ctx: Context,
        fleet: Listening,
        served_wait: float = SERVED_WAIT,
        peers_wait: float = PEERS_WAIT,
    ) -> None:
        self.ctx = ctx
        self.fleet = fleet
        self.served_wait = served_wait
        self.peers_wait = peers_wait

    def check(self, st: JournalState) -> Verdict:
        """The verdict on the run of ``st`` (the rule of the module docstring)."""
        if st.is_final:
            return Verdict(False, f"the run ended for this robot ({st.final or st.phase})")
        if st.agreed_digest:
            return self.served(st)
        return self.exchanging(st)

    def served(self, st: JournalState) -> Verdict:
        """After agreement: going while another agent serves the agreed record set."""
        digest, members = st.agreed_digest, st.agreed_members
        try:
            recs = fetch_records(self.ctx, self.fleet, digest, members, self.served_wait)
        except ValueError as exc:
            return Verdict(False, str(exc))
        return Verdict(
            True, f"the fleet serves the agreed records {digest[:12]}", (digest, members), recs
        )

    def exchanging(self, st: JournalState) -> Verdict:
        """Before agreement: going when the others agreed on this robot's journaled
        record, or peers of the run are heard exchanging (or searching)."""
        if st.record is not None:
            found = agreed_by_others(self.ctx.bus, st.record)
            if found is not None:
                why = f"the others agreed on {found[0][:12]} with this robot's record"
                return Verdict(True, why, found)
        heard = self.listen(st)
        if heard:
            return Verdict(True, heard)
        return Verdict(
            False,
            f"no peer of round {journal_round(st)} heard exchanging within "
            f"{self.peers_wait:g} s (sessions older than the journal)",
        )

    def listen(self, st: JournalState) -> str:
        """What shows a peer of ``st``'s run exchanging, heard within the wait ("" if
        nothing): see :meth:`evidence`."""
        heard: list[str] = []

        def observe(ev: Event) -> None:
            if not heard:
                heard.append(self.evidence(st, ev))
                if not heard[0]:
                    heard.clear()

        self.fleet.observers.append(observe)
        try:
            end = self.ctx.clock() + self.peers_wait
            while not heard and self.ctx.clock() < end:
                self.fleet.wait_until(end)  # or news
        finally:
            self.fleet.observers.remove(observe)
        return heard[0] if heard else ""

    def evidence(self, st: JournalState, ev: Event) -> str:
        """Why ``ev`` shows ``st``'s run still exchanging ("" if it does not): another
        robot's record or digest of the journal's round, or its status of a phase before
        agreement, from a session that began before the journal's last write."""
        msg = ev.msg
        if not isinstance(msg, NeighborRecordMsg | DigestMsg | StatusMsg):
            return ""
        if msg.sender == self.ctx.me:
            return ""
        if ev.epoch >= 0 and st.written_ms and ev.epoch >= st.written_ms:
            return ""  # a session that began after the journal's last write
        if isinstance(msg, StatusMsg):
            if msg.phase not in EXCHANGING:
                return ""
            return f"robot {msg.sender} is in phase {msg.phase}"
        if msg.round != journal_round(st):
            return ""
        return f"robot {msg.sender} publishes its {msg.TAG} of round {msg.round}"
