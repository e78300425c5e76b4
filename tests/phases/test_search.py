"""agent/phases/search.py alone: the record it owns and its round, and the reference view
it journals, with a fake mover and a perception that sees nothing (tests/phases/fakes.py).
What the search sees on real renders: tests/body/test_runner_phases.py.
"""

from __future__ import annotations

import math

import numpy as np

from agent.config import AgentConfig
from agent.core.perception.compass import CompassResult
from agent.phases.search import Search
from agent.wire import NeighborRecordMsg
from tests.phases.fakes import FakeJournal, FakeMover, context


class Empty:
    """A perception that finds nothing, whose compass always fails."""

    def detect(self, image: np.ndarray, yaw: float) -> list[object]:
        return []

    def detect_obstacles(self, image: np.ndarray, yaw: float) -> list[object]:
        return []

    def to_fixed(self, dets: list[object], heading: float) -> tuple[np.ndarray, ...]:
        return np.zeros((0, 2)), np.zeros(0), np.zeros(0)

    def obstacles_fixed(self, dets: list[object], heading: float) -> np.ndarray:
        return np.zeros((0, 2))

    def merge(self, sightings: list[object]) -> tuple[np.ndarray, ...]:
        return np.zeros((0, 2)), np.zeros(0), np.zeros(0)

    def merge_obstacles(self, sightings: list[np.ndarray]) -> np.ndarray:
        return np.zeros((0, 2))

    def measure_turn(self, before: np.ndarray, after: np.ndarray) -> CompassResult:
        return CompassResult(False, 0.0, 0, 0, 0.0, "no features")


def search() -> tuple[Search, FakeMover, FakeJournal]:
    ctx = context(AgentConfig(robot_id=3), perception=Empty())  # type: ignore[arg-type]
    journal = FakeJournal()
    ctx.report.journal = journal
    mover = FakeMover(ctx.beliefs, image=np.full((4, 5, 3), 7, np.uint8))
    return Search(ctx, mover), mover, journal  # type: ignore[arg-type]


def test_the_record_is_of_the_current_round_and_owned_by_the_search() -> None:
    s, _, _ = search()
    assert (s.round, s.record) == (0, None)
    rec = s.localise([])
    assert s.record is rec and (rec.sender, rec.round, rec.neighbours) == (3, 0, ())
    s.begin_round(2)
    assert s.round == 2 and s.record is rec  # the old record until the next search
    assert s.localise([]).round == 2


def test_a_journaled_record_is_restored_with_its_round() -> None:
    s, _, _ = search()
    rec = NeighborRecordMsg(sender=3, round=1, neighbours=((1.0, 0.0),))
    s.restore(rec)
    assert (s.round, s.record) == (1, rec)


def test_the_sweep_journals_the_view_that_defines_the_fixed_frame_once() -> None:
    s, mover, journal = search()
    s.sweep()
    assert len(journal.references) == 1
    assert (journal.references[0] == 7).all()
    # the half turn not measured by the views: the circle is completed
    assert mover.turns == [math.pi, math.pi]
