"""agent/recovery/journal.py: round trips, corruption and every error branch."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import msgpack
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.recovery.journal import (
    ARCHIVES_KEPT,
    MAGIC_STATE,
    MAX_STATE_BYTES,
    Journal,
    JournalError,
    JournalState,
    decode_reference,
    decode_state,
    encode_reference,
    encode_state,
)
from agent.wire import NeighborRecordMsg

D1 = "ab" * 32
D2 = "cd" * 32


def full_state() -> JournalState:
    rec = NeighborRecordMsg(
        sender=2, round=1, neighbours=((1.0, 0.5), (-0.25, 2.0)), confidences=(0.9, 0.4)
    )
    return JournalState(
        robot_id=2,
        phase="move",
        heading=1.25,
        position=(0.4, -0.2),
        compass_gain=1.01,
        record=rec,
        agreed_digest=D1,
        agreed_members=(1, 2, 3),
        plan_digest=D2,
        leg=1,
        command="walk",
        command_value=0.2,
    )


def test_save_load_round_trip_and_sequence(tmp_path: Path) -> None:
    j = Journal(tmp_path / "state", 2)
    assert j.load() is None and j.load_reference() is None
    saved = j.save(full_state())
    assert saved.seq == 1
    again = j.save(replace(full_state(), command=""))
    assert again.seq == 2
    fresh = Journal(tmp_path / "state", 2)  # a restarted process
    got = fresh.load()
    assert got == again
    assert fresh.save(JournalState(robot_id=2)).seq == 3  # continues the sequence
    assert not list((tmp_path / "state").glob("*.tmp"))  # no temporary file left


def test_reference_view_round_trip(tmp_path: Path) -> None:
    j = Journal(tmp_path, 5)
    img = np.random.default_rng(1).integers(0, 256, (48, 64, 3), dtype=np.uint8)
    j.save_reference(img)
    out = j.load_reference()
    assert out is not None and out.dtype == np.uint8 and np.array_equal(out, img)
    j.clear()
    assert j.load() is None and j.load_reference() is None


@settings(max_examples=60, deadline=None)
@given(
    phase=st.sampled_from(["start", "search", "agree", "wait", "move", "hold", "done"]),
    heading=st.floats(-math.pi, math.pi),
    x=st.floats(-999, 999),
    y=st.floats(-999, 999),
    cmd=st.sampled_from(["", "turn", "walk"]),
    value=st.floats(-3, 3),
    members=st.lists(st.integers(0, 65535), max_size=20, unique=True),
)
def test_codec_round_trips(
    phase: str, heading: float, x: float, y: float, cmd: str, value: float, members: list[int]
) -> None:
    s = JournalState(
        robot_id=7,
        phase=phase,
        heading=heading,
        position=(x, y),
        command=cmd,
        command_value=value,
        agreed_digest=D1 if members else "",
        agreed_members=tuple(sorted(members)),
    )
    assert decode_state(encode_state(s)) == s


@settings(max_examples=200, deadline=None)
@given(data=st.binary(max_size=400))
def test_garbage_raises_journal_error_only(data: bytes) -> None:
    with pytest.raises(JournalError):
        decode_state(data)
    with pytest.raises(JournalError):
        decode_reference(data)


def test_every_flipped_byte_is_detected() -> None:
    data = encode_state(full_state())
    for k in range(len(data)):
        bad = bytearray(data)
        bad[k] ^= 0x40
        with pytest.raises(JournalError):
            decode_state(bytes(bad))


def _framed(body: object) -> bytes:
    import hashlib

    raw = msgpack.packb(body, use_bin_type=True)
    return MAGIC_STATE + len(raw).to_bytes(4, "big") + hashlib.sha256(raw).digest() + raw


def _body(**over: object) -> dict[str, object]:
    s = full_state()
    body = msgpack.unpackb(encode_state(s)[len(MAGIC_STATE) + 36 :], raw=False)
    body.update(over)
    return dict(body)


@pytest.mark.parametrize(
    ("data", "match"),
    [
        (b"NAOJRNL1", "truncated"),
        (b"X" * 60, "bad magic"),
        (MAGIC_STATE + (MAX_STATE_BYTES + 1).to_bytes(4, "big") + b"\0" * 40, "at most"),
        (MAGIC_STATE + (10).to_bytes(4, "big") + b"\0" * 32 + b"abc", "header says"),
        (MAGIC_STATE + (3).to_bytes(4, "big") + b"\0" * 32 + b"abc", "checksum"),
        (_framed([1, 2]), "not a map"),
        (_framed({**_body(), "v": 1}), "version"),
        (_framed({**_body(), "v": True}), "version"),
        (_framed({**_body(), "more": 1}), "differ"),
        (_framed({**_body(), "record": "text"}), "record is not bytes"),
        (_framed({**_body(), "record": b"\x80"}), "record"),
        (_framed({**_body(), "position": 3}), "must be lists"),
        (_framed({**_body(), "phase": "fly"}), "is not a phase"),
        (_framed({**_body(), "phase": [1]}), "unhashable|not a phase"),
        (_framed({**_body(), "heading": math.inf}), "heading"),
        (_framed({**_body(), "heading": "n"}), "expected a number"),
        (_framed({**_body(), "position": [1.0]}), "position"),
        (_framed({**_body(), "position": [1.0, 2000.0]}), "position"),
        (_framed({**_body(), "compass_gain": 3.0}), "compass_gain"),
        (_framed({**_body(), "robot_id": 3}), "record: not this robot"),
        (_framed({**_body(), "robot_id": -1}), "robot_id"),
        (_framed({**_body(), "agreed_digest": "XY"}), "agreed_digest"),
        (_framed({**_body(), "plan_digest": 5}), "plan_digest"),
        (_framed({**_body(), "agreed_members": [1, -2]}), "agreed member"),
        (_framed({**_body(), "agreed_members": []}), "go together"),
        (_framed({**_body(), "leg": 1001}), "leg"),
        (_framed({**_body(), "command": "jump"}), "command"),
        (_framed({**_body(), "command_value": 1e9}), "command_value"),
        (_framed({**_body(), "seq": True}), "seq"),
    ],
)
def test_each_error_branch(data: bytes, match: str) -> None:
    with pytest.raises(JournalError, match=match):
        decode_state(data)


def test_agreed_members_must_be_a_tuple() -> None:
    with pytest.raises(JournalError, match="agreed_members"):
        JournalState(robot_id=1, agreed_digest=D1, agreed_members=[1])  # type: ignore[arg-type]


def test_position_must_be_a_pair() -> None:
    with pytest.raises(JournalError, match="position"):
        JournalState(robot_id=1, position=[0.0, 0.0])  # type: ignore[arg-type]


def test_another_robots_journal_is_refused(tmp_path: Path) -> None:
    Journal(tmp_path, 2).save(full_state())
    (tmp_path / "robot-3.journal").write_bytes((tmp_path / "robot-2.journal").read_bytes())
    with pytest.raises(JournalError, match="journal of robot 2, this is robot 3"):
        Journal(tmp_path, 3).load()


def test_oversized_and_unreadable_files_are_refused(tmp_path: Path) -> None:
    j = Journal(tmp_path, 1)
    j.state_path.write_bytes(b"\0" * (MAX_STATE_BYTES + 100))
    with pytest.raises(JournalError, match="larger than"):
        j.load()
    j.state_path.unlink()
    j.state_path.mkdir()  # a folder where the file should be
    with pytest.raises(JournalError, match="cannot read"):
        j.load()


def test_corrupt_reference_views(tmp_path: Path) -> None:
    img = np.zeros((4, 5, 3), np.uint8)
    data = encode_reference(img)
    with pytest.raises(JournalError, match="checksum"):
        decode_reference(data[:-1] + b"\x01")
    body = (4).to_bytes(2, "big") + (5).to_bytes(2, "big") + b"\0" * 10
    import hashlib

    from agent.recovery.journal import MAGIC_REFERENCE

    short = MAGIC_REFERENCE + len(body).to_bytes(4, "big") + hashlib.sha256(body).digest() + body
    with pytest.raises(JournalError, match="pixel bytes"):
        decode_reference(short)
    tiny = b"ab"
    no_size = MAGIC_REFERENCE + (2).to_bytes(4, "big") + hashlib.sha256(tiny).digest() + tiny
    with pytest.raises(JournalError, match="no size"):
        decode_reference(no_size)


@pytest.mark.parametrize(
    "img",
    [np.zeros((4, 5), np.uint8), np.zeros((4, 5, 3), np.float32), np.zeros((2000, 5, 3), np.uint8)],
)
def test_bad_reference_images_are_not_written(img: np.ndarray) -> None:
    with pytest.raises(JournalError):
        encode_reference(img)


def test_bad_robot_id_for_a_journal(tmp_path: Path) -> None:
    with pytest.raises(JournalError, match="robot_id"):
        Journal(tmp_path, -1)


# ------------------------------------------------ journals bound to their run


def test_run_identity_request_id_and_final_round_trip(tmp_path: Path) -> None:
    j = Journal(tmp_path, 2, wall=lambda: 1_700_000_000.25)
    st = replace(full_state(), request_id=2**53 - 1, run_epoch=1_699_999_000_000, final="")
    saved = j.save(st)
    assert saved.written_ms == 1_700_000_000_250  # set by the write, not the caller
    got = Journal(tmp_path, 2).load()
    assert got == saved and got.request_id == 2**53 - 1 and not got.is_final
    for final in ("done", "failed", "stopped"):
        ended = replace(st, command="", request_id=0, final=final)
        assert decode_state(encode_state(ended)).is_final


@pytest.mark.parametrize(
    ("phase", "final", "is_final"),
    [("move", "", False), ("done", "", True), ("failed", "", True), ("hold", "stopped", True)],
)
def test_which_journals_are_final(phase: str, final: str, is_final: bool) -> None:
    assert JournalState(robot_id=1, phase=phase, final=final).is_final is is_final


@pytest.mark.parametrize(
    ("over", "match"),
    [
        ({"request_id": -1}, "request_id"),
        ({"request_id": 2**53}, "request_id"),
        ({"command": "", "request_id": 5}, "request_id without a command"),
        ({"run_epoch": -5}, "run_epoch"),
        ({"written_ms": 1.5}, "written_ms"),
        ({"final": "crashed"}, "final"),
        ({"final": [1]}, "unhashable|final"),
    ],
)
def test_issue_20_error_branches(over: dict[str, object], match: str) -> None:
    with pytest.raises(JournalError, match=match):
        decode_state(_framed({**_body(), **over}))


def test_archive_renames_with_a_timestamp_and_keeps_a_few(tmp_path: Path) -> None:
    t = [1_700_000_000.0]
    j = Journal(tmp_path, 4, wall=lambda: t[0])
    assert j.archive() == []  # nothing to archive
    names = []
    for k in range(ARCHIVES_KEPT + 2):
        j.save(JournalState(robot_id=4, phase="search", run_epoch=k))
        j.save_reference(np.zeros((2, 3, 3), np.uint8))
        moved = j.archive()
        assert [p.name.split(".")[:2] for p in moved] == [
            ["robot-4", "journal"],
            ["robot-4", "reference"],
        ]
        assert not j.state_path.exists() and not j.reference_path.exists()
        names.append(moved[0].name)
        t[0] += 0.5 if k % 2 else 0.0  # the first two in one millisecond
    assert names[0] == "robot-4.journal.20231114T221320.000Z"
    assert names[1] == "robot-4.journal.20231114T221320.000Z-1"
    kept = j.archives()
    assert [p.name for p in kept] == sorted(names, reverse=True)[:ARCHIVES_KEPT]
    assert len(j.archives(j.reference_path)) == ARCHIVES_KEPT
    newest = decode_state(kept[0].read_bytes())
    assert newest.run_epoch == ARCHIVES_KEPT + 1  # the newest kept, the oldest dropped
    assert Journal(tmp_path, 4).load() is None  # the next start is a fresh run


def test_the_phase_is_journaled_as_the_same_string_as_before_the_enum() -> None:
    """Journals stay compatible: a phase is written as its string (the bytes a journal of
    plain strings holds) and read back as the :class:`Phase`."""
    import hashlib

    from agent.phases.reporting import Phase

    st = JournalState(robot_id=3, phase=Phase.MOVE, leg=2, seq=4)
    assert st == JournalState(robot_id=3, phase="move", leg=2, seq=4)
    assert JournalState(robot_id=3, phase="move").phase is Phase.MOVE
    body = {
        "v": 2, "robot_id": 3, "phase": "move", "heading": math.pi / 2,
        "position": [0.0, 0.0], "compass_gain": 1.0, "record": None, "agreed_digest": "",
        "agreed_members": [], "plan_digest": "", "leg": 2, "command": "",
        "command_value": 0.0, "request_id": 0, "run_epoch": 0, "written_ms": 0, "final": "",
        "seq": 4,
    }  # fmt: skip
    raw = msgpack.packb(body, use_bin_type=True)
    plain = MAGIC_STATE + len(raw).to_bytes(4, "big") + hashlib.sha256(raw).digest() + raw
    assert encode_state(st) == plain
    back = decode_state(plain)
    assert back == st and back.phase is Phase.MOVE and back.is_final is False
    assert JournalState(robot_id=3, phase="done").is_final  # a final phase, by its string
