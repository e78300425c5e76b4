"""The calibration digest in a status and a record (agent/core/perception/calibration.py):
optional, bounded like every digest, and absent from a sender that predates it."""

from __future__ import annotations

import msgpack
import pytest

from agent import wire as p

DIGEST = "ab" * 32


@pytest.mark.parametrize(
    "msg",
    [
        p.StatusMsg(sender=3, phase="search", calibration=DIGEST),
        p.NeighborRecordMsg(sender=3, round=0, neighbours=((1.0, 0.5),), calibration=DIGEST),
    ],
)
def test_the_digest_goes_over_the_wire(msg: p.Message) -> None:
    got = p.decode(p.encode(msg))
    assert got == msg and got.calibration == DIGEST  # type: ignore[attr-defined]


@pytest.mark.parametrize("tag", ["status", "record"])
def test_a_sender_that_predates_it_decodes_with_none(tag: str) -> None:
    doc = {"v": 1, "t": tag, "sender": 3}
    doc.update({"phase": "done"} if tag == "status" else {"round": 0, "neighbours": []})
    got = p.decode(msgpack.packb(doc))
    assert got.calibration == ""


@pytest.mark.parametrize("bad", ["AB" * 32, "ab" * 31, "zz" * 32, 7, "ab" * 33])
@pytest.mark.parametrize("tag", ["status", "record"])
def test_anything_but_a_digest_is_refused(tag: str, bad: object) -> None:
    doc: dict[str, object] = {"v": 1, "t": tag, "sender": 3, "calibration": bad}
    doc.update({"phase": "done"} if tag == "status" else {"round": 0, "neighbours": []})
    with pytest.raises(p.ProtocolError, match="calibration"):
        p.decode(msgpack.packb(doc))
