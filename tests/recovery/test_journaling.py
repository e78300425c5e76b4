"""agent/recovery/journaling.py alone: what is journaled before each command and at each
phase change, the final record, the reference view, a failing disk, and the journal
while resuming; against a fake fleet, course and search (tests/phases/fakes.py), on a
real journal in a temporary folder.
"""

from __future__ import annotations

import dataclasses
import logging
import shutil
from pathlib import Path

import numpy as np
import pytest

from agent.adapters import FormationAdapter
from agent.config import AgentConfig
from agent.core.agreement import Agreement
from agent.core.formation.params import PlanParams
from agent.phases.context import Context
from agent.phases.reporting import Phase
from agent.phases.waves import Itinerary
from agent.recovery.journal import Journal, JournalState
from agent.recovery.journaling import Journaling
from agent.wire import canonical_digest
from tests.phases.fakes import Clock, FakeFleet, FakeSurveyor, context, records


@dataclasses.dataclass
class Rig:
    journaling: Journaling
    ctx: Context
    fleet: FakeFleet
    course: Itinerary
    survey: FakeSurveyor


def rig(folder: Path) -> Rig:
    clock = Clock()
    ctx = context(AgentConfig(robot_id=3, fleet_size=3), FormationAdapter(), clock=clock)
    fleet, course, survey = FakeFleet(clock), Itinerary(), FakeSurveyor(3)
    journaling = Journaling(Journal(folder, 3), ctx, fleet, course, survey)  # type: ignore[arg-type]
    ctx.report.journal = journaling
    return Rig(journaling, ctx, fleet, course, survey)


def test_the_command_is_journaled_with_the_beliefs_before_it_is_sent(tmp_path: Path) -> None:
    r = rig(tmp_path)
    r.ctx.beliefs.heading, r.ctx.beliefs.position = 1.0, np.array([0.5, -0.25])
    r.journaling.join_run(1_700_000_000_000)
    r.journaling.save("walk", 0.2, 41)
    st = Journal(tmp_path, 3).load()
    assert st is not None and (st.command, st.command_value, st.request_id) == ("walk", 0.2, 41)
    assert st.run_epoch == 1_700_000_000_000 and st.written_ms > 0 and st.final == ""
    assert st.heading == 1.0 and st.position == (0.5, -0.25) and st.record is None
    r.ctx.report.status(Phase.SEARCH, 0.1)  # a phase change is journaled, without a command
    st = Journal(tmp_path, 3).load()
    assert st is not None and st.phase is Phase.SEARCH and st.command == ""


def test_the_record_the_agreement_and_the_plan_are_journaled(tmp_path: Path) -> None:
    r = rig(tmp_path)
    r.survey.restore(records()[2])
    r.journaling.save()
    st = Journal(tmp_path, 3).load()
    assert st is not None and st.record == records()[2] and st.agreed_digest == ""
    agr = Agreement.restored(3, records(), 0.0, params="ab" * 32, digest_fn=canonical_digest)
    r.fleet.agreement = agr  # agreed: its record and digest
    plan = FormationAdapter().plan(records(), PlanParams())
    r.course.follow(plan)
    r.course.at_leg(2)
    r.journaling.save()
    st = Journal(tmp_path, 3).load()
    assert st is not None and st.record == records()[2]
    assert (st.agreed_digest, st.agreed_members) == (canonical_digest(records()), (1, 2, 3))
    assert (st.plan_digest, st.leg) == (plan.digest, 2)


def test_the_run_ends_with_a_final_record(tmp_path: Path) -> None:
    r = rig(tmp_path)
    r.journaling.finish("failed")
    st = Journal(tmp_path, 3).load()
    assert st is not None and st.final == "failed" and st.is_final
    r.journaling.finish("done")
    st = Journal(tmp_path, 3).load()
    assert st is not None and st.final == "done"


def test_a_failing_disk_gives_the_journal_up_never_the_agent(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    r = rig(tmp_path / "state")
    shutil.rmtree(tmp_path / "state")
    with caplog.at_level(logging.ERROR):
        r.journaling.save("turn", 0.1)
    assert r.journaling.journal is None and "journal write failed" in caplog.text
    r.journaling.save("turn", 0.1)  # given up: nothing more is tried
    r.journaling.reference(np.zeros((4, 5, 3), np.uint8))
    r.journaling.finish("done")


def test_the_reference_view_is_kept_and_a_bad_one_only_logged(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    r = rig(tmp_path)
    image = np.full((4, 5, 3), 9, np.uint8)
    r.journaling.reference(image)
    assert (Journal(tmp_path, 3).load_reference() == image).all()
    with caplog.at_level(logging.ERROR):
        r.journaling.reference(np.zeros((4, 5), np.uint8))  # not an image: refused
    assert "reference view not journaled" in caplog.text
    assert r.journaling.journal is not None  # the journal goes on


def test_while_resuming_only_the_motions_are_journaled_over_the_journaled_state(
    tmp_path: Path,
) -> None:
    r = rig(tmp_path)
    st = JournalState(robot_id=3, phase="move", record=records()[2], leg=1, run_epoch=7)
    with r.journaling.resuming(st) as motions:
        r.ctx.report.status(Phase.PLAN, force=True)  # a phase change: nothing written
        assert Journal(tmp_path, 3).load() is None
        r.ctx.beliefs.heading = 0.5
        r.journaling.save("turn", 0.25, 77)  # a motion: written over the journaled state
        written = Journal(tmp_path, 3).load()
        assert written is not None
        assert (written.phase, written.record, written.leg, written.run_epoch) == (
            "move",
            records()[2],
            1,
            7,
        )
        assert (written.heading, written.command, written.request_id) == (0.5, "turn", 77)
        motions.save()  # answered: nothing in flight
        written = Journal(tmp_path, 3).load()
        assert written is not None and written.command == "" and written.request_id == 0
        r.journaling.reference(np.zeros((4, 5, 3), np.uint8))  # not while resuming
        assert Journal(tmp_path, 3).load_reference() is None
    r.ctx.report.status(Phase.WAIT)  # resumed: the journal follows the phases again
    written = Journal(tmp_path, 3).load()
    assert written is not None and written.phase == "wait"
