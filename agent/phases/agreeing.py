"""Exchange and agreement: one round of records until the fleet agrees (NAO paper 4.1.2;
docs/design.md §1 step 4, the project's addition: the papers assume lossless WiFi).

EXCHANGE publish this robot's record and collect every member's;
AGREE    move on only once every live member published the same record-set digest
         (agent/core/agreement.py: re-sends, back-off, members joining and leaving).

Agreement is asymmetric on a lossy link: a member that already acts on the
plan of exactly the records held here has agreed on them, and this robot adopts that
agreement (:meth:`Agreeing.adopt_plan`), once it has held every record for
:data:`ADOPT_AFTER` seconds without agreeing.
"""

from __future__ import annotations

import logging

from agent.core.agreed_params import params_digest
from agent.core.agreement import Agreement, Decision
from agent.phases.context import Context
from agent.phases.reporting import Phase
from agent.phases.roles import Fleet
from agent.phases.waves import plan_pumping
from agent.wire import NeighborRecordMsg, canonical_digest

log = logging.getLogger("agent.phases.agreeing")

#: Seconds of holding every member's record before a member's plan is checked for
#: adoption (it costs a whole plan, ~7 CPU s at 50 NAOs, during which nothing is pumped;
#: on a sound link the digests agree well before, also at 50 NAOs).
ADOPT_AFTER = 2.0


class Agreeing:
    """One agreement round over the fleet's records (module docstring)."""

    def __init__(self, ctx: Context, fleet: Fleet) -> None:
        self.ctx = ctx
        self.fleet = fleet
        # (records held, digest of their plan) for adopting a member's plan (adopt_plan)
        self.candidate: tuple[tuple[NeighborRecordMsg, ...], str] | None = None

    def agree(self, record: NeighborRecordMsg) -> Decision[NeighborRecordMsg]:
        """Publish ``record`` and exchange until the agreement decides (agreed or not)."""
        ctx, cfg = self.ctx, self.ctx.cfg
        agr = Agreement(
            ctx.me,
            record,
            ctx.clock(),
            fleet_size=cfg.fleet_size,
            timeout=cfg.timeout,
            settle=cfg.settle,
            backoff_max=cfg.backoff_max,
            digest_fn=canonical_digest,
            params=params_digest(cfg.agreed_params()),
        )
        self.fleet.open_round(agr)
        ctx.report.status(Phase.EXCHANGE, 0.0, "publishing record")
        log.info(
            "exchange: record of round %d, %d neighbour(s)", record.round, len(record.neighbours)
        )
        complete_at: float | None = None  # when a record from every member was first held
        self.fleet.pump()
        while True:
            now = ctx.clock()
            d = agr.decide(now)
            if complete_at is None and not agr.missing_records():
                complete_at = now
            if d.kind == "wait" and complete_at is not None and now - complete_at >= ADOPT_AFTER:
                d = self.adopt_plan(agr) or d
            if d.kind != "wait":
                since = "" if complete_at is None else f" {now - complete_at:.1f} s after"
                log.info(
                    "%s: %d member(s),%s every record held; %s",
                    d.kind, len(agr.live), since or " not", d.reason,
                )  # fmt: skip
                return d
            n = max(1, len(agr.live))
            held = len(agr.held_members())
            agreeing = n - len(agr.disagreeing())
            phase = Phase.EXCHANGE if agr.missing_records() else Phase.AGREE
            ctx.report.status(phase, (held + agreeing) / (2 * n), d.reason)
            # asleep until news, our next status, or the adoption check is due (the
            # agreement's own re-sends and timeout are the membership's deadlines)
            until = ctx.report.due()
            if complete_at is not None and now < complete_at + ADOPT_AFTER:
                until = min(until, complete_at + ADOPT_AFTER)
            self.fleet.wait_until(until)

    def adopt_plan(self, agr: Agreement[NeighborRecordMsg]) -> Decision[NeighborRecordMsg] | None:
        """Agreed, when a member already acts on the plan of exactly our records (a lossy link).

        Agreement is asymmetric: a member agrees once it holds every matching digest, and
        ours may reach it while its own never reaches us (a session cut until it exits).
        A member whose status carries a plan digest has agreed; when it plans with our
        parameters (its digest's ``params``) and that plan digest is the digest of the
        plan we compute from the records we hold (a record from every fleet member), it
        planned from the same inputs: we adopt (:meth:`Agreement.adopt`). The candidate
        plan is computed once per record set.
        """
        ctx, peers = self.ctx, self.fleet.peers
        if ctx.cfg.fleet_size is None or len(agr.records) != ctx.cfg.fleet_size:
            return None
        claims = {
            i: peers[i].plan_digest
            for i in sorted(agr.records)
            if i != ctx.me
            and i in peers
            and peers[i].plan_digest
            and agr.params_of.get(i) == agr.params
        }
        if not claims:
            return None
        recs = tuple(agr.records[i] for i in sorted(agr.records))
        if self.candidate is None or self.candidate[0] != recs:
            try:
                digest = str(plan_pumping(ctx, self.fleet, recs).digest)
            except ValueError:
                digest = ""
            self.candidate = (recs, digest)
        if tuple(agr.records[i] for i in sorted(agr.records)) != recs:
            return None  # the records changed while we planned (we pump meanwhile)
        digest = self.candidate[1]
        same = [i for i, d in claims.items() if d == digest]
        if not digest or not same:
            return None
        why = f"robot(s) {same} act on the plan of the records held here (plan {digest[:12]})"
        log.info("agreed by adoption: %s", why)
        return agr.adopt(ctx.clock(), why)
