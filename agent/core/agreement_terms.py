"""What the agreement (agent/core/agreement.py; NAO paper 4.1.2, docs/design.md §1 step 4)
reads and says: the record and digest it reads of a member, the digest note it
publishes, and its decision.

Structural types, so that the pure core names the wire's messages (``agent.wire``)
without importing them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Generic, Protocol, TypeVar


class RecordLike(Protocol):
    """What the agreement reads of a neighbour record (``agent.wire.NeighborRecordMsg``)."""

    @property
    def sender(self) -> int: ...
    @property
    def round(self) -> int: ...


class DigestLike(Protocol):
    """What the agreement reads of a member's digest (``agent.wire.DigestMsg``)."""

    @property
    def sender(self) -> int: ...
    @property
    def round(self) -> int: ...
    @property
    def digest(self) -> str: ...
    @property
    def members(self) -> tuple[int, ...]: ...
    @property
    def params(self) -> str: ...


@dataclass(frozen=True)
class DigestNote:
    """This agent's digest, to publish (the wire form is ``agent.wire.DigestMsg``, whose
    fields these are)."""

    sender: int
    round: int
    digest: str
    members: tuple[int, ...]
    params: str


R = TypeVar("R", bound=RecordLike)
#: The digest of a record set: the caller's, over the records' wire form sorted by sender
#: (``agent.wire.canonical_digest``), so that equal digests mean bit-identical inputs.
DigestFn = Callable[[Sequence[R]], str]


@dataclass(frozen=True)
class Decision(Generic[R]):
    """The state of the agreement: ``wait``, ``agreed`` or ``failed`` (with ``reason``)."""

    kind: str
    reason: str = ""
    digest: str = ""
    members: tuple[int, ...] = ()
    records: tuple[R, ...] = ()
