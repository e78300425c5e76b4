"""agent/phases/search.py alone: the record it owns and its round, the reference view it
journals and the times its record carries (each sighting's image, the body's stances),
with a fake mover and a perception that sees nothing or one robot (tests/phases/fakes.py).
What the search sees on real renders: tests/body/test_runner_phases.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from agent.adapters import PerceptionAdapter
from agent.body.base import Frame
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
        return np.zeros((0, 2)), np.zeros(0), np.zeros(0), np.zeros(0, np.int64)

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


class ClockedMover(FakeMover):
    """A fake mover with a clock: a picture takes 0.5 s, a turn 3 s, and a turn ends with
    a head-yaw-0 picture as the real one's compass control does."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self.t = 10.0

    def look(self, yaw: float = 0.0) -> Frame:
        self.t += 0.5
        return Frame(self.image, yaw, self.t)

    def rotate(self, angle: float, gains: object = None, label: str = "") -> float:
        self.t += 3.0
        out = super().rotate(angle, gains, label)
        self.last_frame = self.look(0.0)
        return out


class SeesOne(Empty):
    """Sees one robot 1 m ahead in the image taken at head yaw ``yaw``, with a
    confidence that grows with the image's index (so the last such image is the best)."""

    def __init__(self, yaw: float) -> None:
        self.yaw, self.n = yaw, 0

    def detect(self, image: np.ndarray, yaw: float) -> list[object]:
        self.n += 1
        return [self.n] if abs(yaw - self.yaw) < 1e-9 else []

    def to_fixed(self, dets: list[object], heading: float) -> tuple[np.ndarray, ...]:
        k = len(dets)
        conf = np.array([0.5 + 0.01 * float(d) for d in dets])  # type: ignore[arg-type]
        return np.tile([[1.0, 0.0]], (k, 1)), conf, np.full(k, 0.3)

    merge = staticmethod(PerceptionAdapter.merge)  # type: ignore[assignment]


def test_the_record_carries_the_stances_and_when_each_sighting_was_seen() -> None:
    cfg = AgentConfig(robot_id=3)
    k = 2  # the robot is seen in the third picture of each sweep
    ctx = context(cfg, perception=SeesOne(cfg.search_yaws[k]))  # type: ignore[arg-type]
    ctx.report.journal = FakeJournal()
    mover = ClockedMover(ctx.beliefs, image=np.full((4, 5, 3), 7, np.uint8))
    s = Search(ctx, mover)  # type: ignore[arg-type]
    rec = s.localise(s.sweep())
    n = len(ctx.cfg.search_yaws)
    # sweep 0: n pictures from 10.5, the yaw-0 reference; the turn; its closing picture;
    # sweep 1; the reference; the circle completed (the fake compass fails); its picture
    first, before_turn = 10.5, 10.0 + 0.5 * (n + 1)
    after_turn = before_turn + 3.5
    before_circle = after_turn + 0.5 * (n + 1)
    after_circle = before_circle + 3.5
    want = [
        (first, before_turn, 0.0),
        (after_turn, before_circle, math.pi),
        (after_circle, after_circle, 0.0),
    ]
    got, exp = np.array(rec.stances), np.array(want)
    np.testing.assert_allclose(got[:, :2], exp[:, :2], atol=1e-12)
    np.testing.assert_allclose(np.cos(got[:, 2] - exp[:, 2]), 1.0, atol=1e-12)  # ±π alike
    # the one neighbour: its best sighting is the later one, in sweep 1
    assert len(rec.neighbours) == 1
    assert rec.seen_at == pytest.approx((after_turn + 0.5 * (k + 1),))


def test_a_record_of_sightings_given_without_their_sweep_carries_no_times() -> None:
    s, _, _ = search()
    rec = s.localise([(np.array([[1.0, 0.0]]), np.array([0.9]), np.array([0.1]))])
    assert rec.seen_at == () and rec.stances == ()


def test_a_restarted_search_says_the_body_was_set_down_and_nothing_since() -> None:
    """After a crash (agent/recovery/resume.py) the record's stances begin with the
    instant the robot was set down, at the start heading in the new fixed frame, and then
    the new search's: a mask of it taken before the new search falls between stances (its
    body stood where the crash left it) and is set aside, not read at the first heading."""
    from agent.core.formation.frame.records import heading_at

    cfg = AgentConfig(robot_id=3)
    ctx = context(cfg, perception=SeesOne(cfg.search_yaws[2]))  # type: ignore[arg-type]
    ctx.report.journal = FakeJournal()
    mover = ClockedMover(ctx.beliefs, image=np.full((4, 5, 3), 7, np.uint8))
    s = Search(ctx, mover)  # type: ignore[arg-type]
    s.restarted(0.3 + 2 * math.pi)
    rec = s.localise(s.sweep())
    assert rec.stances[0] == pytest.approx((0.0, 0.0, 0.3))
    first = rec.stances[1]
    assert first[0] == pytest.approx(10.5)
    stances = np.array(rec.stances)
    assert math.isnan(heading_at(stances, 5.0))  # the crash: nobody knows
    assert heading_at(stances, first[0]) == pytest.approx(first[2])
