"""agent/phases/resume.py and the runner's journal hooks, without the world (issue #9).

The runner of tests/test_runner.py (robot 3, an unconnected zenoh session): what is
journaled, what a corrupt journal does, and where each journaled phase resumes.
"""

from __future__ import annotations

import logging
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from agent.phases import resume
from agent.phases.context import NORTH, AgentFailure
from agent.phases.journal import Journal, JournalState
from agent.phases.runner import Runner
from agent.wire import NeighborRecordMsg
from tests.test_runner import perception, records, runner  # noqa: F401  (fixtures)


def test_the_runner_journals_the_command_before_sending_it(runner: Runner, tmp_path: Path) -> None:  # noqa: F811
    runner.ctx.journal = Journal(tmp_path, 3)
    runner.ctx.beliefs.heading, runner.ctx.beliefs.position = 1.0, np.array([0.5, -0.25])
    runner.journaling.save("walk", 0.2)
    st = Journal(tmp_path, 3).load()
    assert st is not None and (st.command, st.command_value) == ("walk", 0.2)
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
    assert resume.load(Journal(tmp_path / "empty", 3)) is None


@pytest.mark.parametrize("phase", ["failed", "march", "explore"])
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
        resume.fetch_records(
            runner.ctx, runner.membership, st.agreed_digest, st.agreed_members, timeout=0.5
        )
