"""Camera requests waiting for render workers: one picture per robot, a fair bound
(docs/design.md §3, the world's camera service, for fleets of fifty NAOs and beyond).

A robot waits for one picture at a time. The world keeps at most one picture in the
works per robot and never refuses a robot of its own for want of room:

* a robot with no picture pending is admitted while fewer than ``capacity`` are pending;
  the capacity is at least the number of the world's robots, so only a flood from
  outside them is refused;
* a robot that asks again at the same yaw while its picture is being drawn (its
  attempt timed out and it repeated the query) gets that picture: the newest query is
  answered, the older one is told it was superseded;
* at another yaw, it is told the world is busy (its earlier picture is still being
  drawn) and asks again later; no second job is queued for it.

Why: with one global bound of 64 and no per-robot rule, 100 NAOs searching at once
kept the queue full. A robot whose attempt timed out asked again while its first
picture still waited, so a few robots held two places each, and a refused robot had
to land its retry in the moment a place came free. Robot 50 was refused 52 times in
200 s, stopped on "world busy", and the whole fleet then stopped on "member 50 left
before agreement".
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from typing import Generic, TypeVar

#: Pictures in the works at most, whatever the fleet's size (the capacity is at least
#: the number of robots of the world).
MIN_CAPACITY = 64

Q = TypeVar("Q")


class Admission(Enum):
    """What :meth:`PendingPictures.request` decided."""

    NEW = "new"  # draw a picture for it: the caller submits a job and calls add()
    REBOUND = "rebound"  # its picture already being drawn answers this query
    BUSY = "busy"  # refused: nothing drawn, the robot may ask again


@dataclass(frozen=True)
class Pending(Generic[Q]):
    """One picture in the works: the query to answer, and what the picture shows."""

    query: Q
    robot_id: int
    yaw: float
    t_sim: float  # world time of the poses the picture is drawn from


class PendingPictures(Generic[Q]):
    """The pending pictures by job id, at most one per robot (module docstring)."""

    def __init__(self, robots: int) -> None:
        if robots < 0:
            raise ValueError(f"robots must be >= 0, got {robots}")
        self.capacity = max(MIN_CAPACITY, robots)
        self._jobs: dict[int, Pending[Q]] = {}
        self._job_of: dict[int, int] = {}  # robot id -> its job id

    def __len__(self) -> int:
        return len(self._jobs)

    def request(self, query: Q, robot_id: int, yaw: float) -> tuple[Admission, Q | None]:
        """Decide on a camera request. With ``REBOUND`` the second item is the older
        query the picture no longer answers (the caller tells it it was superseded)."""
        job = self._job_of.get(robot_id)
        if job is None:
            if len(self._jobs) >= self.capacity:
                return Admission.BUSY, None
            return Admission.NEW, None
        old = self._jobs[job]
        if old.yaw != yaw:
            return Admission.BUSY, None
        self._jobs[job] = Pending(query, robot_id, yaw, old.t_sim)
        return Admission.REBOUND, old.query

    def add(self, job_id: int, query: Q, robot_id: int, yaw: float, t_sim: float) -> None:
        """A job submitted after ``NEW``."""
        if job_id in self._jobs or robot_id in self._job_of:
            raise ValueError(f"job {job_id} or robot {robot_id} already pending")
        self._jobs[job_id] = Pending(query, robot_id, yaw, t_sim)
        self._job_of[robot_id] = job_id

    def done(self, job_id: int) -> Pending[Q] | None:
        """The pending picture of a finished job (None: not pending)."""
        pending = self._jobs.pop(job_id, None)
        if pending is not None:
            del self._job_of[pending.robot_id]
        return pending

    def drain(self) -> list[Pending[Q]]:
        """Every pending picture, forgotten (the world shuts down)."""
        out = list(self._jobs.values())
        self._jobs.clear()
        self._job_of.clear()
        return out
