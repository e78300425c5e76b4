"""agent/recovery/resume.py, agent/recovery/runs.py and the runner's journal hooks, without
the world (crashed agents and stale journals).

The runner of tests/phases/test_runner.py (robot 3, an unconnected zenoh session): what is
journaled, what a corrupt journal does, where each journaled phase resumes, and which
journals are resumed at all: only those of a run still going, as the bus shows it (the
fleet's answers are faked on the session: its ``query``, and events put in its queue).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from agent.body.base import MotionResult
from agent.core.control import wrap_pi
from agent.net.bus import Event, QueryTimeout
from agent.phases.context import NORTH, AgentFailure
from agent.phases.runner import Runner
from agent.recovery import resume, runs
from agent.recovery.journal import Journal, JournalState
from agent.wire import (
    DigestMsg,
    Message,
    NeighborRecordMsg,
    RecordSetReply,
    RecordSetRequest,
    StatusMsg,
    canonical_digest,
    encode,
    key_digest,
    key_record,
    key_status,
)
from tests.phases.test_runner import perception, records, runner  # noqa: F401  (fixtures)


def test_the_runner_journals_the_command_before_sending_it(runner: Runner, tmp_path: Path) -> None:  # noqa: F811
    runner.ctx.journal = Journal(tmp_path, 3)
    runner.ctx.beliefs.heading, runner.ctx.beliefs.position = 1.0, np.array([0.5, -0.25])
    runner.ctx.run_epoch = 1_700_000_000_000
    runner.journaling.save("walk", 0.2, 41)
    st = Journal(tmp_path, 3).load()
    assert st is not None and (st.command, st.command_value, st.request_id) == ("walk", 0.2, 41)
    assert st.run_epoch == 1_700_000_000_000 and st.written_ms > 0 and st.final == ""
    assert st.heading == 1.0 and st.position == (0.5, -0.25) and st.record is None
    runner.ctx.status("search", 0.1)  # a phase change is journaled, without a command
    st = Journal(tmp_path, 3).load()
    assert st is not None and st.phase == "search" and st.command == ""


def test_a_failing_disk_gives_the_journal_up_never_the_agent(
    runner: Runner,  # noqa: F811
    tmp_path: Path,
    caplog: pytest.LogCaptureFixture,
) -> None:
    runner.ctx.journal = Journal(tmp_path / "state", 3)
    shutil.rmtree(tmp_path / "state")
    with caplog.at_level(logging.ERROR):
        runner.journaling.save("turn", 0.1)
    assert runner.ctx.journal is None and "journal write failed" in caplog.text


def test_a_corrupt_journal_is_reported_and_ignored(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    j = Journal(tmp_path, 3)
    j.state_path.write_bytes(b"NAOJRNL1 garbage")
    with caplog.at_level(logging.ERROR):
        assert resume.load(j) is None
    assert "unusable, starting afresh" in caplog.text
    assert not j.state_path.exists() and len(j.archives()) == 1  # kept aside, not resumed
    assert resume.load(Journal(tmp_path / "empty", 3)) is None


@pytest.mark.parametrize("phase", ["failed", "done", "march", "explore"])
def test_a_failed_marching_or_exploring_robot_is_not_resumed(runner: Runner, phase: str) -> None:  # noqa: F811
    with pytest.raises(AgentFailure, match=f"phase {phase} at the crash"):
        runner.resumption.resume(JournalState(robot_id=3, phase=phase))


def test_before_the_record_it_searches_again_facing_north(runner: Runner) -> None:  # noqa: F811
    st = JournalState(robot_id=3, phase="search", heading=NORTH)
    assert runner.resumption.resume(st) == ("search", None)
    assert runner.ctx.beliefs.heading == NORTH


def test_with_a_record_it_rejoins_the_exchange(runner: Runner, tmp_path: Path) -> None:  # noqa: F811
    rec = NeighborRecordMsg(sender=3, round=2, neighbours=((1.0, 0.0),))
    runner.ctx.journal = Journal(tmp_path, 3)
    st = JournalState(
        robot_id=3, phase="exchange", heading=1.4, compass_gain=1.02, record=rec, seq=5
    )
    # nobody answers for an agreed set (no fleet): the exchange again, with the record
    assert runner.resumption.resume(st) == ("agree", rec)
    assert runner.ctx.own_record == rec and runner.ctx.record_round == 2
    assert runner.ctx.beliefs.compass_gain == 1.02 and runner.ctx.beliefs.heading == 1.4
    assert runner.ctx.journal is not None  # journaling goes on after the resumption


def test_the_command_in_flight_counts_as_executed(runner: Runner) -> None:  # noqa: F811
    rec = records()[2]
    st = JournalState(
        robot_id=3, phase="exchange", heading=NORTH, record=rec, command="walk", command_value=0.2
    )
    runner.resumption.resume(st)
    assert np.allclose(runner.ctx.beliefs.position, [0.0, 0.2])
    st = JournalState(
        robot_id=3, phase="exchange", heading=1.0, record=rec, command="turn", command_value=0.25
    )
    runner.resumption.resume(st)
    assert math.isclose(runner.ctx.beliefs.heading, 1.25)


def test_after_agreement_without_a_fleet_it_stops_safely(runner: Runner) -> None:  # noqa: F811
    st = JournalState(
        robot_id=3,
        phase="move",
        record=records()[2],
        agreed_digest="ab" * 32,
        agreed_members=(1, 2, 3),
    )
    with pytest.raises(ValueError, match="nobody served the agreed records"):
        runs.fetch_records(
            runner.ctx, runner.membership, st.agreed_digest, st.agreed_members, timeout=0.5
        )


# --------------------------------------------------------------------------- the command in flight


def test_a_command_in_flight_with_a_request_id_is_asked_again_with_it(
    runner: Runner,  # noqa: F811
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    sent: list[tuple[str, float, int]] = []

    def walk(distance: float, request_id: int = 0) -> MotionResult:
        sent.append(("walk", distance, request_id))
        return MotionResult("done", 5.0)

    def turn(angle: float, request_id: int = 0) -> MotionResult:
        sent.append(("turn", angle, request_id))
        return MotionResult("done", 6.0)

    monkeypatch.setattr(runner.ctx.body, "walk", walk)
    monkeypatch.setattr(runner.ctx.body, "turn", turn)
    rec = records()[2]
    st = JournalState(
        robot_id=3, phase="exchange", heading=NORTH, record=rec, command="walk",
        command_value=0.2, request_id=9001,
    )  # fmt: skip
    runner.resumption.resume(st, runs.Verdict(True, "peers exchanging"))
    assert sent == [("walk", 0.2, 9001)]  # once, with the journaled id
    assert np.allclose(runner.ctx.beliefs.position, [0.0, 0.2])  # the belief follows once
    st = JournalState(
        robot_id=3, phase="exchange", heading=1.0, record=rec, command="turn",
        command_value=0.25, request_id=9002,
    )  # fmt: skip
    runner.resumption.resume(st, runs.Verdict(True, "peers exchanging"))
    assert sent[-1] == ("turn", 0.25, 9002) and math.isclose(runner.ctx.beliefs.heading, 1.25)


def test_a_contact_answered_to_the_walk_in_flight_stops_safely(
    runner: Runner,  # noqa: F811
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(
        runner.ctx.body, "walk", lambda d, request_id=0: MotionResult("contact", 5.0, "robot 1")
    )
    st = JournalState(
        robot_id=3, phase="move", heading=NORTH, record=records()[2], command="walk",
        command_value=0.2, request_id=7,
    )  # fmt: skip
    with pytest.raises(AgentFailure, match="contact while walking"):
        runner.resumption.resume(st, runs.Verdict(True, "served"))


def test_each_turn_is_journaled_with_the_request_id_it_is_sent_with(
    runner: Runner,  # noqa: F811
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    runner.ctx.journal = Journal(tmp_path, 3)
    sent: list[tuple[float, int]] = []

    def turn(angle: float, request_id: int = 0) -> MotionResult:
        st = Journal(tmp_path, 3).load()  # written before the body is asked
        assert st is not None and (st.command, st.request_id) == ("turn", request_id)
        sent.append((angle, request_id))
        return MotionResult("done", 1.0)

    monkeypatch.setattr(runner.ctx.body, "new_request_id", lambda: 4242)
    monkeypatch.setattr(runner.ctx.body, "turn", turn)
    runner.motion.turn(0.1)
    assert sent == [(0.1, 4242)]


# --------------------------------------------------------------------------- is the run going?

WRITTEN_S = 1_000.0  # the crashed process's last write (wall clock, s)
RESTART_S = 2_000.0  # the restarted process


def crashed(tmp_path: Path, st: JournalState) -> Journal:
    """``st`` journaled by the crashed process; the restarted process's journal."""
    Journal(tmp_path, 3, wall=lambda: WRITTEN_S).save(st)
    return Journal(tmp_path, 3, wall=lambda: RESTART_S)


def nobody_answers(
    key: str, msg: Message, expect: type, timeout: float = 0.0, accept: object = None
) -> Message:
    raise QueryTimeout(f"{key}: no reply within {timeout:g} s")


def serving(reply: RecordSetReply) -> object:
    """A fleet where robot ``reply.sender`` serves ``reply`` (record_sets.answer's rule)."""

    def query(
        key: str, msg: Message, expect: type, timeout: float = 0.0, accept: object = None
    ) -> Message:
        assert isinstance(msg, RecordSetRequest)
        if msg.digest not in ("", reply.digest):
            raise QueryTimeout("no reply")
        assert callable(accept) and accept(reply) == ""
        return reply

    return query


def served_set(sender: int = 1) -> RecordSetReply:
    recs = records()
    return RecordSetReply(
        sender=sender, digest=canonical_digest(recs), records=tuple(encode(r) for r in recs)
    )


def agreed(phase: str = "wait") -> JournalState:
    recs = records()
    return JournalState(
        robot_id=3, phase=phase, record=recs[2], agreed_digest=canonical_digest(recs),
        agreed_members=(1, 2, 3), run_epoch=123_456,
    )  # fmt: skip


@pytest.mark.parametrize(
    "st",
    [
        JournalState(robot_id=3, phase="done", run_epoch=5),  # a crash while lingering
        JournalState(robot_id=3, phase="failed"),
        JournalState(robot_id=3, phase="hold", final="done"),
        JournalState(robot_id=3, phase="search", final="stopped"),
    ],
)
def test_a_final_journal_is_archived_and_never_resumed(
    runner: Runner,  # noqa: F811
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    st: JournalState,
) -> None:
    j = crashed(tmp_path, st)
    Journal(tmp_path, 3).save_reference(np.zeros((4, 5, 3), np.uint8))
    runner.ctx.journal = j
    # the fleet still serving that run changes nothing: its state is final
    monkeypatch.setattr(runner.ctx.bus, "query", serving(served_set()))
    assert runner.resumption.start() == ("search", None)
    assert not j.state_path.exists() and not j.reference_path.exists()
    assert len(j.archives()) == 1 and len(j.archives(j.reference_path)) == 1
    assert runner.ctx.run_epoch == j.opened_ms == int(RESTART_S * 1000)  # a new run


def test_an_agreed_journal_nobody_serves_is_archived_and_the_robot_starts_afresh(
    runner: Runner,  # noqa: F811
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    caplog: pytest.LogCaptureFixture,
) -> None:
    j = crashed(tmp_path, agreed("move"))
    runner.ctx.journal = j
    runner.resumption.runs.served_wait = 0.3
    monkeypatch.setattr(runner.ctx.bus, "query", nobody_answers)
    with caplog.at_level(logging.INFO):
        assert runner.resumption.start() == ("search", None)
    assert "nobody served the agreed records" in caplog.text and "archived" in caplog.text
    assert not j.state_path.exists() and len(j.archives()) == 1
    assert runner.membership.agreement is None


def test_an_agreed_journal_the_fleet_serves_is_resumed(
    runner: Runner,  # noqa: F811
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    j = crashed(tmp_path, agreed("wait"))
    runner.ctx.journal = j
    monkeypatch.setattr(runner.ctx.bus, "query", serving(served_set()))
    assert runner.resumption.start() == ("wait", records()[2])
    agr = runner.membership.agreement
    assert agr is not None and agr.agreed and agr.digest()[1] == canonical_digest(records())
    assert runner.ctx.run_epoch == 123_456  # the run goes on under its identity
    assert j.state_path.exists() and j.archives() == []


def test_an_agreed_journal_served_with_another_set_is_not_resumed(
    runner: Runner,  # noqa: F811
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    other = (*records()[:2], NeighborRecordMsg(sender=3, round=0, neighbours=((2.0, 2.0),)))
    reply = RecordSetReply(
        sender=1, digest=canonical_digest(other), records=tuple(encode(r) for r in other)
    )
    j = crashed(tmp_path, agreed("move"))
    runner.ctx.journal = j
    runner.resumption.runs.served_wait = 0.3
    monkeypatch.setattr(runner.ctx.bus, "query", serving(reply))  # a later run's set
    assert runner.resumption.start() == ("search", None)
    assert len(j.archives()) == 1


def exchanging_journal() -> JournalState:
    return JournalState(robot_id=3, phase="exchange", heading=1.4, record=records()[2])


OLD = int(WRITTEN_S * 1000) - 60_000  # a session that began before the journal's last write
NEW = int(WRITTEN_S * 1000) + 60_000  # one that began after it: a later run


def put(runner: Runner, key: str, msg: Message, epoch: int) -> None:  # noqa: F811
    runner.ctx.bus._put(Event("msg", key, msg, epoch=epoch))


@pytest.mark.parametrize(
    ("key", "msg", "epoch"),
    [
        (key_record(1), records()[0], OLD),
        (key_status(2), StatusMsg(sender=2, phase="agree"), OLD),
        (key_status(1), StatusMsg(sender=1, phase="search"), -1),  # insecure: no epochs
        (key_digest(2), DigestMsg(sender=2, round=0, digest="ab" * 32, members=(1, 2, 3)), OLD),
    ],
)
def test_a_journal_before_agreement_is_resumed_while_peers_exchange(
    runner: Runner,  # noqa: F811
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    key: str,
    msg: Message,
    epoch: int,
) -> None:
    j = crashed(tmp_path, exchanging_journal())
    runner.ctx.journal = j
    runner.membership.start()
    runner.resumption.runs.peers_wait = 5.0
    monkeypatch.setattr(runner.ctx.bus, "query", nobody_answers)  # nobody agreed yet
    put(runner, key, msg, epoch)
    assert runner.resumption.start() == ("agree", records()[2])
    assert j.state_path.exists() and j.archives() == []
    assert runner.ctx.beliefs.heading == 1.4


@pytest.mark.parametrize(
    ("key", "msg", "epoch"),
    [
        (None, None, 0),  # nobody heard
        (key_record(1), records()[0], NEW),  # a session of a later run
        (key_status(2), StatusMsg(sender=2, phase="search"), NEW),
        (key_status(2), StatusMsg(sender=2, phase="move"), OLD),  # not exchanging
        (key_record(1), NeighborRecordMsg(sender=1, round=1, neighbours=()), OLD),  # round 1
        (key_record(3), records()[2], OLD),  # this robot's own earlier session
    ],
)
def test_a_journal_before_agreement_without_peers_exchanging_is_archived(
    runner: Runner,  # noqa: F811
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    key: str | None,
    msg: Message | None,
    epoch: int,
) -> None:
    j = crashed(tmp_path, exchanging_journal())
    runner.ctx.journal = j
    runner.membership.start()
    runner.resumption.runs.peers_wait = 0.5
    monkeypatch.setattr(runner.ctx.bus, "query", nobody_answers)
    if key is not None and msg is not None:
        put(runner, key, msg, epoch)
    assert runner.resumption.start() == ("search", None)
    assert not j.state_path.exists() and len(j.archives()) == 1
    assert runner.ctx.beliefs.heading == NORTH and runner.ctx.own_record is None


def test_a_journal_before_agreement_whose_record_the_others_agreed_on_is_resumed(
    runner: Runner,  # noqa: F811
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    j = crashed(tmp_path, exchanging_journal())
    runner.ctx.journal = j
    runner.resumption.runs.peers_wait = 0.3
    monkeypatch.setattr(runner.ctx.bus, "query", serving(served_set(sender=2)))
    assert runner.resumption.start() == ("wait", records()[2])  # adopted, then planned
    assert runner.membership.agreement is not None and j.archives() == []


def test_a_search_journal_is_resumed_while_peers_search(
    runner: Runner,  # noqa: F811
    tmp_path: Path,
) -> None:
    j = crashed(tmp_path, JournalState(robot_id=3, phase="search", heading=NORTH))
    runner.ctx.journal = j
    runner.membership.start()
    runner.resumption.runs.peers_wait = 5.0
    put(runner, key_status(1), StatusMsg(sender=1, phase="search"), OLD)
    assert runner.resumption.start() == ("search", None)
    assert j.state_path.exists() and j.archives() == []


def test_the_runner_ends_with_a_final_record(runner: Runner, tmp_path: Path) -> None:  # noqa: F811
    runner.ctx.journal = Journal(tmp_path, 3)
    assert runner.fail("a test") == 1
    st = Journal(tmp_path, 3).load()
    assert st is not None and st.final == "failed" and st.is_final
    runner.journaling.finish("done")
    st = Journal(tmp_path, 3).load()
    assert st is not None and st.final == "done"


def test_resumed_at_hold_it_faces_the_pyramid_axis_and_checks_against_it(
    runner: Runner,  # noqa: F811
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A robot resumed at hold skips the move, which set the pyramid axis; the hold's own
    check judged the pair against north instead (eval_faults kill-agent@hold: "formation
    off: r_φ +285 %" on pairs within tolerance), facing north after the re-measurement."""
    goals, axis = runner.ctx.formation.goals(runner.ctx.plan, 3)
    final = wrap_pi(axis + 1.2)  # a robot of a fleet turned away from north
    monkeypatch.setattr(runner.ctx.formation, "goals", lambda plan, me: (goals, final))
    turned: list[float] = []

    def rotate(angle: float, gains: object = None, detail: str = "") -> None:
        turned.append(angle)
        runner.ctx.beliefs.heading = wrap_pi(runner.ctx.beliefs.heading + angle)

    def remeasure(journal: object) -> None:  # turned to θ = 0, the view did not match
        rotate(wrap_pi(NORTH - runner.ctx.beliefs.heading))

    monkeypatch.setattr(runner.motion, "rotate", rotate)
    monkeypatch.setattr(runner.resumption, "remeasure_heading", remeasure)
    monkeypatch.setattr(runner.ctx.bus, "query", serving(served_set()))
    st = dataclasses.replace(agreed("hold"), heading=final, position=(0.1, 0.3))
    assert runner.ctx.final_heading == NORTH  # as a fresh process starts
    stage, _ = runner.resumption.resume(st, runs.Verdict(True, "served"))
    assert stage == "hold"
    assert runner.ctx.final_heading == pytest.approx(final)
    assert turned == [pytest.approx(wrap_pi(NORTH - final)), pytest.approx(wrap_pi(final - NORTH))]
    assert runner.ctx.beliefs.heading == pytest.approx(final)  # facing the axis again


class Crash(Exception):
    """The agent killed (SIGKILL) while its command is on its way."""


def test_a_second_crash_during_the_resumption_forgets_no_turn(
    runner: Runner,  # noqa: F811
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """eval_chaos seed 22: an agent killed four times in its search. The third process
    answered the turn in flight and turned back towards θ = 0 to re-measure its heading;
    killed during that turn, the fourth resumed from the journal of the first crash and
    believed itself 88° from where it faced (the compass then disagreed by 30°: kept the
    estimate, and the robot missed its parent at the end). The resumption's own turns are
    journaled now, with their request ids; the journaled phase and record stand."""
    from agent.body.base import Frame

    heading, v = math.radians(163.2), 0.262
    first = JournalState(
        robot_id=3, phase="search", heading=heading, command="turn", command_value=v,
        request_id=900, run_epoch=77,
    )  # fmt: skip
    Journal(tmp_path, 3).save(first)
    Journal(tmp_path, 3).save_reference(np.zeros((4, 5, 3), np.uint8))
    runner.ctx.journal = Journal(tmp_path, 3)
    frame = Frame(np.zeros((4, 5, 3), np.uint8), 0.0, 0.0)
    monkeypatch.setattr(runner.motion, "look", lambda yaw=0.0: frame)
    sent: list[tuple[float, int]] = []

    def turn(angle: float, request_id: int = 0) -> MotionResult:
        sent.append((angle, request_id))
        if request_id == 900:
            return MotionResult("done", 6.3)  # the world's first answer, from its cache
        raise Crash  # the re-measurement's first turn: the agent dies with it on its way

    monkeypatch.setattr(runner.ctx.body, "turn", turn)
    monkeypatch.setattr(runner.ctx.body, "new_request_id", lambda: 901)
    with pytest.raises(Crash):
        runner.resumption.resume(first, runs.Verdict(True, "peers search"))
    assert sent[0] == (v, 900) and sent[1][1] == 901
    st = Journal(tmp_path, 3).load()
    assert st is not None
    assert (st.command, st.request_id) == ("turn", 901)  # the turn on its way, with its id
    assert st.command_value == pytest.approx(sent[1][0])
    assert st.heading == pytest.approx(wrap_pi(heading + v))  # the turn in flight done once
    assert (st.phase, st.record, st.run_epoch) == ("search", None, 77)  # as journaled
    assert runner.ctx.journal is not None and runner.ctx.journal_hook == runner.journaling.save
