"""The agreed record set by digest (an agent restarted after agreement gets the records back;
docs/design.md §8 "Faults"; NAO paper 4.1.2).

Once agreed, every agent serves the records it agreed on at ``nao/{id}/records``
(:func:`record_set`, :func:`answer`), so that an agent restarted after a crash can fetch
them by their digest (agent/recovery/resume.py) instead of searching again. The asker
trusts no server: ``records_of`` (agent/wire/codec.py) checks that a reply is the set
asked for, decodes, holds one record per member sorted by sender, and hashes to the
agreed digest.
"""

from __future__ import annotations

from agent.core.agreement import Decision
from agent.wire import (
    Message,
    NeighborRecordMsg,
    RecordSetReply,
    RecordSetRequest,
    encode,
)


def record_set(me: int, decision: Decision[NeighborRecordMsg]) -> RecordSetReply:
    """What this agent serves once agreed: the records of ``decision`` in wire form."""
    return RecordSetReply(
        sender=me, digest=decision.digest, records=tuple(encode(r) for r in decision.records)
    )


def answer(served: RecordSetReply | None, request: Message) -> RecordSetReply | None:
    """The reply to a record-set query: the set when it is the one asked for (or any was
    asked for: an empty digest), else none."""
    if not isinstance(request, RecordSetRequest) or served is None:
        return None
    return served if request.digest in ("", served.digest) else None
