"""agent/recovery/resume.py and agent/recovery/runs.py alone (crashed agents and stale
journals): what a corrupt journal does, where each journaled phase resumes, and which
journals are resumed at all: only those of a run still going, as the fleet shows it.

Robot 3 of the three robots of ``records()``, its :class:`~agent.phases.roles.Crew` of
fakes (tests/phases/fakes.py): the fleet's answers to queries are the bus's ``answer``,
what the fleet says meanwhile is handed to the run check's observer; the planner plans
on the real formation core; the journal is real, in a temporary folder.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from pathlib import Path

import numpy as np
import pytest

from agent.adapters import FormationAdapter
from agent.body.base import Frame, MotionResult
from agent.config import AgentConfig
from agent.core.control import wrap_pi
from agent.net.bus import Event, QueryTimeout
from agent.phases.context import NORTH, AgentFailure, Context
from agent.phases.motion import Motion
from agent.phases.reporting import Phase
from agent.phases.roles import Crew
from agent.phases.waves import Itinerary
from agent.recovery import resume, runs
from agent.recovery.journal import Journal, JournalState
from agent.recovery.journaling import Journaling
from agent.recovery.resume import Resumption
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
from tests.phases.fakes import (
    Clock,
    FakeBody,
    FakeBus,
    FakeFleet,
    FakeMover,
    FakePlanner,
    FakeSurveyor,
    context,
    records,
)


@dataclasses.dataclass
class Rig:
    resumption: Resumption
    journaling: Journaling
    ctx: Context
    bus: FakeBus
    body: FakeBody
    fleet: FakeFleet
    mover: FakeMover | Motion
    planner: FakePlanner
    course: Itinerary
    survey: FakeSurveyor


def rig(journal: Journal, real_motion: bool = False, perception: object = None) -> Rig:
    """Robot 3 resuming from ``journal`` (the reporter journals through it, as in the
    runner); ``real_motion``: its turns by :class:`~agent.phases.motion.Motion`."""
    clock = Clock()
    cfg = AgentConfig(robot_id=3, fleet_size=3)
    ctx = context(cfg, FormationAdapter(), perception, clock)  # type: ignore[arg-type]
    assert isinstance(ctx.bus, FakeBus) and isinstance(ctx.body, FakeBody)
    fleet, course, survey = FakeFleet(clock), Itinerary(), FakeSurveyor(3)
    mover = Motion(ctx, fleet) if real_motion else FakeMover(ctx.beliefs)  # type: ignore[arg-type]
    planner = FakePlanner(ctx, course)
    crew = Crew(ctx, fleet, mover, planner, course, survey)  # type: ignore[arg-type]
    journaling = Journaling(journal, ctx, fleet, course, survey)  # type: ignore[arg-type]
    ctx.report.journal = journaling
    resumption = Resumption(journaling, crew)
    resumption.runs.served_wait = resumption.runs.peers_wait = 5.0
    return Rig(
        resumption, journaling, ctx, ctx.bus, ctx.body, fleet, mover, planner, course, survey
    )


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
def test_a_failed_marching_or_exploring_robot_is_not_resumed(tmp_path: Path, phase: str) -> None:
    r = rig(Journal(tmp_path, 3))
    with pytest.raises(AgentFailure, match=f"phase {phase} at the crash"):
        r.resumption.resume(JournalState(robot_id=3, phase=phase))
    with pytest.raises(AgentFailure, match=r"phase hold \(stopped\) at the crash"):
        r.resumption.resume(JournalState(robot_id=3, phase="hold", final="stopped"))


def test_before_the_record_it_searches_again_facing_north(tmp_path: Path) -> None:
    r = rig(Journal(tmp_path, 3))
    st = JournalState(robot_id=3, phase="search", heading=NORTH)
    assert r.resumption.resume(st) == (Phase.SEARCH, None)
    assert r.ctx.beliefs.heading == NORTH and r.survey.record is None
    assert r.survey.start_heading == 0.0  # the new frame is the old one: it did not turn


def test_a_search_resumed_turned_tells_the_search_its_start_heading(tmp_path: Path) -> None:
    """Crashed 0.4 rad past north with no reference view to re-measure against: the new
    search's frame is defined where it stands, so the start heading in it is −0.4 rad,
    and the search is told so (its stances say nothing of the body since)."""
    r = rig(Journal(tmp_path, 3))
    st = JournalState(robot_id=3, phase="search", heading=NORTH + 0.4)
    assert r.resumption.resume(st) == (Phase.SEARCH, None)
    assert r.ctx.beliefs.heading == NORTH
    assert r.survey.start_heading == pytest.approx(-0.4)


def test_with_a_record_it_rejoins_the_exchange(tmp_path: Path) -> None:
    r = rig(Journal(tmp_path, 3))
    rec = NeighborRecordMsg(sender=3, round=2, neighbours=((1.0, 0.0),))
    st = JournalState(
        robot_id=3, phase="exchange", heading=1.4, compass_gain=1.02, record=rec, seq=5
    )
    # nobody answers for an agreed set (no fleet): the exchange again, with the record
    assert r.resumption.resume(st) == (Phase.AGREE, rec)
    assert r.survey.record == rec and r.survey.round == 2
    assert r.ctx.beliefs.compass_gain == 1.02 and r.ctx.beliefs.heading == 1.4
    assert r.journaling.journal is not None  # journaling goes on after the resumption
    assert r.planner.decisions == []


def test_the_command_in_flight_counts_as_executed(tmp_path: Path) -> None:
    r = rig(Journal(tmp_path, 3))
    rec = records()[2]
    st = JournalState(
        robot_id=3, phase="exchange", heading=NORTH, record=rec, command="walk", command_value=0.2
    )
    r.resumption.resume(st)
    assert np.allclose(r.ctx.beliefs.position, [0.0, 0.2])
    st = JournalState(
        robot_id=3, phase="exchange", heading=1.0, record=rec, command="turn", command_value=0.25
    )
    r.resumption.resume(st)
    assert math.isclose(r.ctx.beliefs.heading, 1.25)
    st = JournalState(
        robot_id=3, phase="exchange", heading=NORTH, record=rec, command="side", command_value=0.1
    )
    r.resumption.resume(st)
    assert np.allclose(r.ctx.beliefs.position, [-0.1, 0.0])  # to the left of north
    assert r.body.sent == []  # without request ids the body is not asked


def test_after_agreement_without_a_fleet_it_stops_safely(tmp_path: Path) -> None:
    r = rig(Journal(tmp_path, 3))
    st = agreed("move")
    with pytest.raises(ValueError, match="nobody served the agreed records"):
        runs.fetch_records(r.ctx, r.fleet, st.agreed_digest, st.agreed_members, timeout=0.5)
    assert r.fleet.pumps >= 1  # the fleet was heard meanwhile


# --------------------------------------------------------------------------- the command in flight


def test_a_command_in_flight_with_a_request_id_is_asked_again_with_it(tmp_path: Path) -> None:
    r = rig(Journal(tmp_path, 3))
    rec = records()[2]
    st = JournalState(
        robot_id=3, phase="exchange", heading=NORTH, record=rec, command="walk",
        command_value=0.2, request_id=9001,
    )  # fmt: skip
    r.resumption.resume(st, runs.Verdict(True, "peers exchanging"))
    assert r.body.sent == [("walk", 0.2, 9001)]  # once, with the journaled id
    assert np.allclose(r.ctx.beliefs.position, [0.0, 0.2])  # the belief follows once
    st = JournalState(
        robot_id=3, phase="exchange", heading=1.0, record=rec, command="turn",
        command_value=0.25, request_id=9002,
    )  # fmt: skip
    r.resumption.resume(st, runs.Verdict(True, "peers exchanging"))
    assert r.body.sent[-1] == ("turn", 0.25, 9002) and math.isclose(r.ctx.beliefs.heading, 1.25)
    # answered: journaled with nothing in flight, over the journaled state
    written = Journal(tmp_path, 3).load()
    assert written is not None and (written.command, written.request_id) == ("", 0)
    assert written.phase == "exchange" and written.heading == pytest.approx(1.25)


def test_a_contact_answered_to_the_walk_in_flight_stops_safely(tmp_path: Path) -> None:
    r = rig(Journal(tmp_path, 3))
    r.body.walk = lambda d, request_id=0: MotionResult("contact", 5.0, "robot 1")  # type: ignore[method-assign]
    st = JournalState(
        robot_id=3, phase="move", heading=NORTH, record=records()[2], command="walk",
        command_value=0.2, request_id=7,
    )  # fmt: skip
    with pytest.raises(AgentFailure, match="contact while walking"):
        r.resumption.resume(st, runs.Verdict(True, "served"))


def test_a_contact_answered_to_the_turn_in_flight_is_only_logged(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    r = rig(Journal(tmp_path, 3))
    r.body.turn = lambda a, request_id=0: MotionResult("contact", 5.0, "robot 1")  # type: ignore[method-assign]
    st = JournalState(
        robot_id=3, phase="exchange", heading=NORTH, record=records()[2], command="turn",
        command_value=0.1, request_id=8,
    )  # fmt: skip
    with caplog.at_level(logging.WARNING):
        assert r.resumption.resume(st, runs.Verdict(True, "peers"))[0] == Phase.AGREE
    assert "contact while turning" in caplog.text


# --------------------------------------------------------------------------- is the run going?

WRITTEN_S = 1_000.0  # the crashed process's last write (wall clock, s)
RESTART_S = 2_000.0  # the restarted process


def crashed(tmp_path: Path, st: JournalState) -> Journal:
    """``st`` journaled by the crashed process; the restarted process's journal."""
    Journal(tmp_path, 3, wall=lambda: WRITTEN_S).save(st)
    return Journal(tmp_path, 3, wall=lambda: RESTART_S)


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
def test_a_final_journal_is_archived_and_never_resumed(tmp_path: Path, st: JournalState) -> None:
    j = crashed(tmp_path, st)
    Journal(tmp_path, 3).save_reference(np.zeros((4, 5, 3), np.uint8))
    r = rig(j)
    # the fleet still serving that run changes nothing: its state is final
    r.bus.answer = serving(served_set())  # type: ignore[assignment]
    assert r.resumption.start() == (Phase.SEARCH, None)
    assert not j.state_path.exists() and not j.reference_path.exists()
    assert len(j.archives()) == 1 and len(j.archives(j.reference_path)) == 1
    assert r.journaling.run_epoch == j.opened_ms == int(RESTART_S * 1000)  # a new run


def test_without_a_journal_it_starts_afresh(tmp_path: Path) -> None:
    r = rig(Journal(tmp_path, 3))
    assert r.resumption.start() == (Phase.SEARCH, None)  # an empty slot
    assert r.journaling.run_epoch == r.journaling.journal.opened_ms  # type: ignore[union-attr]
    r.journaling.journal = None  # given up (a failing disk)
    assert r.resumption.start() == (Phase.SEARCH, None)


def test_an_agreed_journal_nobody_serves_is_archived_and_the_robot_starts_afresh(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    j = crashed(tmp_path, agreed("move"))
    r = rig(j)
    r.resumption.runs.served_wait = 0.3
    with caplog.at_level(logging.INFO):
        assert r.resumption.start() == (Phase.SEARCH, None)
    assert "nobody served the agreed records" in caplog.text and "archived" in caplog.text
    assert not j.state_path.exists() and len(j.archives()) == 1
    assert r.fleet.agreement is None


def test_an_agreed_journal_the_fleet_serves_is_resumed(tmp_path: Path) -> None:
    j = crashed(tmp_path, agreed("wait"))
    r = rig(j)
    r.bus.answer = serving(served_set())  # type: ignore[assignment]
    assert r.resumption.start() == (Phase.WAIT, records()[2])
    agr = r.fleet.agreement
    assert agr is not None and agr.agreed and agr.digest()[1] == canonical_digest(records())
    assert [d.records for d in r.planner.decisions] == [records()]  # planned again
    assert r.journaling.run_epoch == 123_456  # the run goes on under its identity
    assert j.state_path.exists() and j.archives() == []
    said = r.bus.statuses()[0]
    assert (said.phase, said.detail) == ("plan", "resumed: fetching the agreed records")


def test_a_recomputed_plan_that_differs_from_the_journal_stops_the_robot(tmp_path: Path) -> None:
    j = crashed(tmp_path, dataclasses.replace(agreed("move"), plan_digest="cd" * 32))
    r = rig(j)
    r.bus.answer = serving(served_set())  # type: ignore[assignment]
    with pytest.raises(AgentFailure, match=r"recomputed plan \w+ differs from the journaled cdcd"):
        r.resumption.start()


def test_resumed_mid_move_it_goes_on_from_the_journaled_leg(tmp_path: Path) -> None:
    st = dataclasses.replace(agreed("move"), leg=2, heading=NORTH)
    r = rig(crashed(tmp_path, st))
    r.bus.answer = serving(served_set())  # type: ignore[assignment]
    assert r.resumption.start() == (Phase.MOVE, records()[2])
    assert r.course.leg == 2
    _, axis = FormationAdapter().goals(r.course.plan, 3)
    assert r.course.final_heading == pytest.approx(axis)
    assert r.mover.turns == []  # type: ignore[union-attr]  # it had not moved: no re-measuring


def test_an_agreed_journal_served_with_another_set_is_not_resumed(tmp_path: Path) -> None:
    other = (*records()[:2], NeighborRecordMsg(sender=3, round=0, neighbours=((2.0, 2.0),)))
    reply = RecordSetReply(
        sender=1, digest=canonical_digest(other), records=tuple(encode(r) for r in other)
    )
    j = crashed(tmp_path, agreed("move"))
    r = rig(j)
    r.resumption.runs.served_wait = 0.3
    r.bus.answer = serving(reply)  # type: ignore[assignment]  # a later run's set
    assert r.resumption.start() == (Phase.SEARCH, None)
    assert len(j.archives()) == 1


def exchanging_journal() -> JournalState:
    return JournalState(robot_id=3, phase="exchange", heading=1.4, record=records()[2])


OLD = int(WRITTEN_S * 1000) - 60_000  # a session that began before the journal's last write
NEW = int(WRITTEN_S * 1000) + 60_000  # one that began after it: a later run


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
    tmp_path: Path, key: str, msg: Message, epoch: int
) -> None:
    j = crashed(tmp_path, exchanging_journal())
    r = rig(j)
    r.fleet.heard.append(Event("msg", key, msg, epoch=epoch))  # nobody agreed yet
    assert r.resumption.start() == (Phase.AGREE, records()[2])
    assert j.state_path.exists() and j.archives() == []
    assert r.ctx.beliefs.heading == 1.4
    assert r.fleet.observers == []  # the run check stopped listening


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
    tmp_path: Path, key: str | None, msg: Message | None, epoch: int
) -> None:
    j = crashed(tmp_path, exchanging_journal())
    r = rig(j)
    r.resumption.runs.peers_wait = 0.5
    if key is not None and msg is not None:
        r.fleet.heard.append(Event("msg", key, msg, epoch=epoch))
    assert r.resumption.start() == (Phase.SEARCH, None)
    assert not j.state_path.exists() and len(j.archives()) == 1
    assert r.ctx.beliefs.heading == NORTH and r.survey.record is None


def test_a_journal_before_agreement_whose_record_the_others_agreed_on_is_resumed(
    tmp_path: Path,
) -> None:
    j = crashed(tmp_path, exchanging_journal())
    r = rig(j)
    r.resumption.runs.peers_wait = 0.3
    r.bus.answer = serving(served_set(sender=2))  # type: ignore[assignment]
    assert r.resumption.start() == (Phase.WAIT, records()[2])  # adopted, then planned
    assert r.fleet.agreement is not None and j.archives() == []


def test_a_search_journal_is_resumed_while_peers_search(tmp_path: Path) -> None:
    j = crashed(tmp_path, JournalState(robot_id=3, phase="search", heading=NORTH))
    r = rig(j)
    r.fleet.heard.append(
        Event("msg", key_status(1), StatusMsg(sender=1, phase="search"), epoch=OLD)
    )
    assert r.resumption.start() == (Phase.SEARCH, None)
    assert j.state_path.exists() and j.archives() == []


def test_resumed_at_hold_it_faces_the_pyramid_axis_and_checks_against_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A robot resumed at hold skips the move, which set the pyramid axis; the hold's own
    check judged the pair against north instead (eval_faults kill-agent@hold: "formation
    off: r_φ +285 %" on pairs within tolerance), facing north after the re-measurement."""
    r = rig(Journal(tmp_path, 3))
    mover = r.mover
    assert isinstance(mover, FakeMover)
    plan = FormationAdapter().plan(records(), r.ctx.cfg.plan_params())
    goals, axis = r.ctx.formation.goals(plan, 3)
    final = wrap_pi(axis + 1.2)  # a robot of a fleet turned away from north
    monkeypatch.setattr(r.ctx.formation, "goals", lambda plan, me: (goals, final))

    def remeasure(journal: object, sigma: float) -> None:  # turned to θ = 0, no match
        mover.rotate(wrap_pi(NORTH - r.ctx.beliefs.heading))

    monkeypatch.setattr(r.resumption, "remeasure_heading", remeasure)
    r.bus.answer = serving(served_set())  # type: ignore[assignment]
    st = dataclasses.replace(agreed("hold"), heading=final, position=(0.1, 0.3))
    assert r.course.final_heading == NORTH  # as a fresh process starts
    stage, _ = r.resumption.resume(st, runs.Verdict(True, "served"))
    assert stage == Phase.HOLD
    assert r.course.final_heading == pytest.approx(final)
    assert mover.turns == [
        pytest.approx(wrap_pi(NORTH - final)),
        pytest.approx(wrap_pi(final - NORTH)),
    ]
    assert r.ctx.beliefs.heading == pytest.approx(final)  # facing the axis again


class Compass:
    """A perception whose compass reads one turn."""

    def __init__(self, dtheta: float) -> None:
        from agent.core.perception.compass import CompassResult

        self.reading = CompassResult(True, dtheta, 40, 30, 0.75, "")

    def measure_turn(self, before: np.ndarray, after: np.ndarray) -> object:
        return self.reading


def test_the_heading_is_remeasured_against_the_reference_view(tmp_path: Path) -> None:
    """Turned back to θ = 0 by the estimate, the compass between the reference view and
    the image now gives the heading, weighed by the errors: in place (at the frame's origin)
    the compass's 3° is taken whole; a reading off by 34° is beyond the gate."""
    j = Journal(tmp_path, 3)
    j.save_reference(np.zeros((4, 5, 3), np.uint8))
    sigma = math.radians(2.0)
    for dtheta, want in ((math.radians(3.0), NORTH + math.radians(3.0)), (0.6, NORTH)):
        r = rig(j, perception=Compass(dtheta))
        r.ctx.beliefs.heading = NORTH + 0.3
        r.resumption.remeasure_heading(j, sigma)
        assert r.mover.turns == [pytest.approx(-0.3)]  # type: ignore[union-attr]
        assert r.ctx.beliefs.heading == pytest.approx(want, abs=math.radians(0.05))


def test_away_from_the_reference_view_the_compass_barely_moves_the_estimate(
    tmp_path: Path,
) -> None:
    """eval_faults kill-agent@hold seed 1: resumed at its slot 0.9 m from where its reference
    view was taken, a robot read its heading 13.6° off a sound estimate (parallax, ~14° per
    metre) and took it, a silent wrong done at |r_φ| 32 %. A metre away the compass's σ is
    14°: the estimate (σ 2°) moves by 2 % of the innovation."""
    j = Journal(tmp_path, 3)
    j.save_reference(np.zeros((4, 5, 3), np.uint8))
    r = rig(j, perception=Compass(math.radians(13.6)))
    r.ctx.beliefs.position = np.array([-0.692, -0.275])
    r.resumption.remeasure_heading(j, math.radians(2.0))
    off = math.degrees(wrap_pi(r.ctx.beliefs.heading - NORTH))
    assert 0.1 < off < 0.5


class Crash(Exception):
    """The agent killed (SIGKILL) while its command is on its way."""


def test_a_second_crash_during_the_resumption_forgets_no_turn(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """eval_chaos seed 22: an agent killed four times in its search. The third process
    answered the turn in flight and turned back towards θ = 0 to re-measure its heading;
    killed during that turn, the fourth resumed from the journal of the first crash and
    believed itself 88° from where it faced (the compass then disagreed by 30°: kept the
    estimate, and the robot missed its parent at the end). The resumption's own turns are
    journaled now, with their request ids; the journaled phase and record stand."""
    heading, v = math.radians(163.2), 0.262
    first = JournalState(
        robot_id=3, phase="search", heading=heading, command="turn", command_value=v,
        request_id=900, run_epoch=77,
    )  # fmt: skip
    Journal(tmp_path, 3).save(first)
    Journal(tmp_path, 3).save_reference(np.zeros((4, 5, 3), np.uint8))
    r = rig(Journal(tmp_path, 3), real_motion=True)
    frame = Frame(np.zeros((4, 5, 3), np.uint8), 0.0, 0.0)
    monkeypatch.setattr(r.mover, "look", lambda yaw=0.0: frame)
    sent: list[tuple[float, int]] = []

    def turn(angle: float, request_id: int = 0) -> MotionResult:
        sent.append((angle, request_id))
        if request_id == 900:
            return MotionResult("done", 6.3)  # the world's first answer, from its cache
        raise Crash  # the re-measurement's first turn: the agent dies with it on its way

    monkeypatch.setattr(r.body, "turn", turn)
    monkeypatch.setattr(r.body, "new_request_id", lambda: 901)
    with pytest.raises(Crash):
        r.resumption.resume(first, runs.Verdict(True, "peers search"))
    assert sent[0] == (v, 900) and sent[1][1] == 901
    st = Journal(tmp_path, 3).load()
    assert st is not None
    assert (st.command, st.request_id) == ("turn", 901)  # the turn on its way, with its id
    assert st.command_value == pytest.approx(sent[1][0])
    assert st.heading == pytest.approx(wrap_pi(heading + v))  # the turn in flight done once
    assert (st.phase, st.record, st.run_epoch) == ("search", None, 77)  # as journaled
    # the resumption is over: the journal follows the phases again
    assert r.journaling.journal is not None
    r.ctx.report.status(Phase.SEARCH, force=True)
    st = Journal(tmp_path, 3).load()
    assert st is not None and st.command == "" and st.phase == "search"
