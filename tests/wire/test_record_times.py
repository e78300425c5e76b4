"""A record's times (agent/wire/messages.py ``NeighborRecordMsg``: ``seen_at`` and
``stances``, docs/design.md §9 "Masks seen mid-turn"): they go over the wire, a sender
that predates them decodes with none, and anything malformed is refused."""

from __future__ import annotations

import msgpack
import pytest

from agent import wire as p
from agent.wire.fields import MAX_STANCES

STANCES = ((1.0, 4.0, 0.0), (7.0, 9.0, 3.14))


def _doc(**extra: object) -> dict[str, object]:
    doc: dict[str, object] = {"v": 1, "t": "record", "sender": 3, "round": 0}
    doc["neighbours"] = [[1.0, 0.5], [0.2, -1.0]]
    doc.update(extra)
    return doc


def test_times_go_over_the_wire() -> None:
    msg = p.NeighborRecordMsg(
        sender=3, round=0, neighbours=((1.0, 0.5), (0.2, -1.0)), seen_at=(2.0, 8.5),
        stances=STANCES, clock_error=0.05,
    )  # fmt: skip
    got = p.decode(p.encode(msg))
    assert got == msg


def test_a_sender_that_predates_them_decodes_with_none() -> None:
    got = p.decode(msgpack.packb(_doc()))
    assert got.seen_at == () and got.stances == ()  # type: ignore[attr-defined]
    assert got.clock_error == 0.0  # type: ignore[attr-defined]


@pytest.mark.parametrize(
    "extra, match",
    [
        ({"seen_at": [1.0]}, "seen_at: 1 values for 2"),
        ({"seen_at": [1.0, -2.0]}, "seen_at"),
        ({"seen_at": [1.0, float("nan")]}, "not finite"),
        ({"stances": [[1.0, 4.0]]}, "stance"),
        ({"stances": [[4.0, 1.0, 0.0]]}, "out of time order"),
        ({"stances": [[1.0, 4.0, 0.0], [3.0, 5.0, 0.0]]}, "out of time order"),
        ({"stances": [[1.0, 4.0, 11.0]]}, "stance heading"),
        ({"stances": [[1.0, 1.0, 0.0]] * (MAX_STANCES + 1)}, "at most"),
        ({"clock_error": -0.1}, "clock_error"),
        ({"clock_error": 11.0}, "clock_error"),
    ],
)
def test_malformed_times_are_refused(extra: dict[str, object], match: str) -> None:
    with pytest.raises(p.ProtocolError, match=match):
        p.decode(msgpack.packb(_doc(**extra)))
