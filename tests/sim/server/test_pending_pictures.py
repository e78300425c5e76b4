"""One picture per robot and a fair bound (:mod:`sim.server.pending_pictures`)."""

from __future__ import annotations

import pytest

from sim.server.pending_pictures import MIN_CAPACITY, Admission, PendingPictures


def test_the_capacity_is_at_least_the_fleet() -> None:
    assert PendingPictures(3).capacity == MIN_CAPACITY
    assert PendingPictures(100).capacity == 100  # 100 NAOs: none refused for room


def test_a_new_robot_is_admitted_and_its_picture_found_again() -> None:
    p: PendingPictures[str] = PendingPictures(2)
    assert p.request("q1", 1, 0.5) == (Admission.NEW, None)
    p.add(7, "q1", 1, 0.5, 12.0)
    assert len(p) == 1
    done = p.done(7)
    assert done is not None and (done.query, done.robot_id, done.yaw, done.t_sim) == (
        "q1", 1, 0.5, 12.0,
    )  # fmt: skip
    assert p.done(7) is None and len(p) == 0
    assert p.request("q2", 1, 0.5) == (Admission.NEW, None)  # free again


def test_a_repeat_at_the_same_yaw_takes_over_the_picture() -> None:
    p: PendingPictures[str] = PendingPictures(2)
    p.add(1, "old", 4, 0.25, 3.0)
    assert p.request("new", 4, 0.25) == (Admission.REBOUND, "old")
    done = p.done(1)
    assert done is not None and done.query == "new" and done.t_sim == 3.0  # old poses
    assert len(p) == 0


def test_another_yaw_while_drawing_is_busy_and_queues_nothing() -> None:
    p: PendingPictures[str] = PendingPictures(2)
    p.add(1, "old", 4, 0.25, 3.0)
    assert p.request("other", 4, -0.25) == (Admission.BUSY, None)
    assert len(p) == 1 and p.done(1) is not None


def test_a_full_queue_refuses_a_robot_without_a_picture() -> None:
    p: PendingPictures[str] = PendingPictures(0)
    for k in range(MIN_CAPACITY):
        p.add(k, f"q{k}", 1000 + k, 0.0, 0.0)
    assert p.request("late", 5, 0.0) == (Admission.BUSY, None)
    assert p.request("again", 1000, 0.0) == (Admission.REBOUND, "q0")  # repeats still served


def test_drain_forgets_everything() -> None:
    p: PendingPictures[str] = PendingPictures(2)
    p.add(1, "a", 1, 0.0, 0.0)
    p.add(2, "b", 2, 0.0, 0.0)
    assert [x.query for x in p.drain()] == ["a", "b"] and len(p) == 0
    assert p.request("c", 1, 0.0) == (Admission.NEW, None)


def test_errors() -> None:
    with pytest.raises(ValueError, match="robots must be >= 0"):
        PendingPictures(-1)
    p: PendingPictures[str] = PendingPictures(2)
    p.add(1, "a", 1, 0.0, 0.0)
    with pytest.raises(ValueError, match="already pending"):
        p.add(1, "b", 2, 0.0, 0.0)  # the job id again
    with pytest.raises(ValueError, match="already pending"):
        p.add(2, "b", 1, 0.0, 0.0)  # the robot again
