"""agent/phases/reporting.py alone: the phases as an Enum with the wire's strings, what a
status carries, the journal written at every phase change, the timeline.

The pace of the statuses (on change, heartbeats) is tested in tests/test_waiting.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from agent.config import AgentConfig
from agent.core.formation.shape.verdict import PairCheck
from agent.phases.reporting import NoJournal, Phase, Reporter, Timeline
from agent.wire import MAX_SHIFT, MAX_WALKED, PHASES, StatusMsg, encode, key_status
from tests.phases.fakes import Clock, FakeBody, FakeBus, FakeJournal


def reporter(clock: Clock | None = None) -> tuple[Reporter, FakeBus]:
    clock = clock or Clock()
    bus = FakeBus(clock)
    return Reporter(bus, FakeBody(3), AgentConfig(robot_id=3, fleet_size=3), clock), bus  # type: ignore[arg-type]


def test_the_phases_are_the_wires_strings_in_order() -> None:
    assert tuple(p.value for p in Phase) == PHASES
    for p in Phase:
        assert p == p.value and str(p) == p.value and f"{p}" == p.value
        assert Phase(p.value) is p
    with pytest.raises(ValueError):
        Phase("walking")


def test_a_status_is_the_same_bytes_as_with_the_phase_as_a_string() -> None:
    """Statuses stay compatible: the Enum never reaches the wire."""
    report, bus = reporter()
    report.status(Phase.MOVE, 0.5, "leg 1/2", force=True)
    (key, msg) = bus.published[-1]
    assert key == key_status(3) and type(msg.phase) is str and msg.phase == "move"
    plain = StatusMsg(sender=3, phase="move", progress=0.5, detail="leg 1/2", t_sim=0.0)
    assert encode(msg) == encode(plain)


def test_the_phase_starts_at_start_and_follows_the_statuses() -> None:
    report, _ = reporter()
    assert report.phase is Phase.START
    report.status(Phase.SEARCH)
    assert report.phase is Phase.SEARCH


def test_every_phase_change_is_journaled_and_marked_once() -> None:
    report, _ = reporter()
    journal = FakeJournal(report)
    report.journal = journal
    report.status(Phase.SEARCH, 0.1)
    report.status(Phase.SEARCH, 0.2, "more")  # the same phase: no journal
    report.status(Phase.LOCALISE)
    # written with the new phase already entered, without a command
    assert journal.saved == [("", 0.0, 0, "search"), ("", 0.0, 0, "localise")]
    assert [m[0] for m in report.timeline.marks] == ["search", "localise"]


def test_no_journal_by_default() -> None:
    report, _ = reporter()
    assert isinstance(report.journal, NoJournal)
    report.status(Phase.SEARCH)  # writes nothing, raises nothing
    report.journal.reference(np.zeros((2, 2, 3), np.uint8))


def test_a_status_carries_each_figure_its_owner_shows() -> None:
    report, bus = reporter()
    check = PairCheck(child=3, parent=1, distance=0.8, angle=0.5, r_d=0.02, r_phi=-0.05)
    report.show_plan("ab" * 32, 2)
    report.show_check(check)
    report.show_blocked_by(4)
    report.show_walked(1.25)
    report.show_shift((0.1, -0.2))
    report.status(Phase.HOLD, force=True)
    msg = bus.statuses()[-1]
    assert (msg.plan_digest, msg.wave, msg.blocked_by) == ("ab" * 32, 2, 4)
    assert (msg.check_parent, msg.r_d, msg.r_phi) == (1, 0.02, -0.05)
    assert (msg.walked, msg.shift_x, msg.shift_y) == (1.25, 0.1, -0.2)
    assert report.figures.check is check and report.figures.blocked_by == 4


def test_figures_beyond_the_wires_bounds_are_clamped() -> None:
    report, bus = reporter()
    big = PairCheck(child=3, parent=1, distance=0.8, angle=0.5, r_d=1e6, r_phi=-1e6)
    report.show_check(big)
    report.show_walked(-1.0)
    report.status(Phase.HOLD, 2.0, "x" * 900, error="e" * 900, force=True)
    report.show_walked(math.inf)
    report.show_shift((1e9, -1e9))
    report.status(Phase.HOLD, -1.0, force=True)
    first, second = bus.statuses()[-2:]
    assert (first.r_d, first.r_phi, first.walked, first.progress) == (100.0, -100.0, 0.0, 1.0)
    assert len(first.detail) == len(first.error) == 500
    assert second.walked == MAX_WALKED and (second.shift_x, second.shift_y) == (
        MAX_SHIFT,
        -MAX_SHIFT,
    )
    assert second.progress == 0.0


def test_the_status_carries_the_bytes_published_and_the_sim_time() -> None:
    report, bus = reporter()
    report.status(Phase.SEARCH, force=True)
    before = bus.stats.total_published
    report.status(Phase.SEARCH, 0.5, force=True)
    assert bus.statuses()[-1].bytes_sent == before > 0


def test_the_timeline_reports_wall_and_cpu_seconds_per_phase() -> None:
    tl = Timeline()
    assert tl.costs() == ""
    tl.mark(Phase.SEARCH, 0.0)
    tl.mark(Phase.WAIT, 1.0)
    parts = tl.costs().split(", ")
    assert [p.split(" ")[0] for p in parts] == ["set-up", "search", "wait"]
    assert parts[0].startswith("set-up -/")
    wall, cpu = (float(v) for v in parts[1].split(" ")[1].split("/"))
    assert wall >= 0.0 and cpu >= 0.0
